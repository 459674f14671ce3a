"""Aggregated views of a recording: block means for the drift analysis, a fine grid for spectra.

Block means shrink white noise by sqrt(samples per block), so effects far below the per-sample
noise become visible, and they keep the generalised least squares of the finder at about a
thousand observations whatever the sample rate. Everything here reads only ``time_s``,
``temp_c`` and ``accel_mg`` (``Recording.without_truth()`` is applied by the caller).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.signal import savgol_filter

from trainer.data.recording import Recording
from trainer.diagnose.branches import longest_hold_after_ramp_s
from trainer.errors import UserError

DEFAULT_MAX_BLOCKS = 600  # dense GLS: Cholesky cost ~ N^3, a few ms at 600
FINE_STEP_S = 0.5  # fine grid for periodograms: periods down to the catalogue's 5 s stay resolved
RATE_WINDOW_S = 60.0  # Savitzky-Golay window for dT/dt: below the package time constants of interest
MIN_BLOCKS = 60
# Blocks mostly held out by a cross-validation fold (``Recording.held_out``) get no weight in the GLS (Gls
# ``held_out``), and the white noise is measured on the other rows, so the fit is the fit to the
# training rows alone.


def block_means(x: np.ndarray, m: int, nb: int) -> np.ndarray:
    """Means of ``nb`` consecutive blocks of ``m`` samples (the tail beyond ``nb * m`` is dropped)."""
    return np.asarray(x[: nb * m], dtype=np.float64).reshape(nb, m).mean(axis=1)


def detect_lattice(temp_c: np.ndarray) -> float | None:
    """The LSB (degC) when the thermometer column lies on a lattice of equal steps, else None.

    A quantised thermometer takes few distinct values, all integer multiples of the LSB apart;
    a continuous one (the usual float reading) takes nearly as many values as there are samples.
    """
    values = np.unique(np.asarray(temp_c, dtype=np.float64))
    if values.size < 3 or values.size > temp_c.size // 3:  # a float reading is nearly all distinct
        return None
    steps = np.diff(values)
    lsb = float(np.min(steps))
    span = float(values[-1] - values[0])
    if not (lsb > 1e-4 and span / lsb < 1e6):
        return None
    multiples = (values - values[0]) / lsb
    if np.max(np.abs(multiples - np.round(multiples))) > 1e-3:
        return None
    return float(lsb)


def dequantize(
    t: np.ndarray, temp_c: np.ndarray, lsb: float
) -> tuple[np.ndarray, np.ndarray, list[tuple[float, float]]]:
    """Knots ``(t, T)`` of the smooth temperature behind a staircase thermometer column, and plateaus.

    The reading changes level when the true temperature crosses a half-LSB threshold, so each
    crossing (a burst of noise-dithered flips between two levels, taken at its median time) pins
    the true temperature to the threshold at that time. A shape-preserving (PCHIP) curve through
    these knots follows ramps and the slowing approach to a hold. Where no crossing happens for
    long (holds, the start and the end) the temperature is only known within one LSB, so those
    plateaus are returned as ``(t0, t1)`` intervals for the model to give each an unknown offset
    (the bias slope times that temperature error).
    """
    temp_c = np.asarray(temp_c, dtype=np.float64)
    level = np.round(temp_c / lsb).astype(np.int64)
    change = np.flatnonzero(level[1:] != level[:-1]) + 1
    t_end = float(t[-1])
    if change.size == 0:
        mid = float(level[0] * lsb)
        return np.array([t[0], t_end]), np.array([mid, mid]), [(float(t[0]), t_end + 1.0)]
    # Seconds per level on the fastest ramp: noise-dithered flips around one threshold come in
    # bursts far shorter than that, a longer pause is a new crossing.
    step = max(1, round(10.0 / max(float(t[1] - t[0]), 1e-9)))
    coarse_t, coarse_T = t[::step], temp_c[::step]
    fastest = (
        float(np.percentile(np.abs(rate_c_per_min(coarse_t, coarse_T)), 95)) / 60.0
        if coarse_t.size >= 7
        else 0.0
    )
    typical = lsb / fastest if fastest > 0 else t_end - float(t[0])
    knots_t: list[float] = []
    knots_v: list[float] = []
    pair_prev: tuple[int, int] = (0, 0)
    burst: list[float] = []
    for idx in change.tolist():
        a, b = int(level[idx - 1]), int(level[idx])
        pair = (min(a, b), max(a, b))
        when = 0.5 * (t[idx - 1] + t[idx])
        if burst and (pair != pair_prev or when - burst[-1] > 0.3 * typical):
            knots_t.append(float(np.median(burst)))
            knots_v.append(0.5 * (pair_prev[0] + pair_prev[1]) * lsb)
            burst = []
        burst.append(when)
        pair_prev = pair
    knots_t.append(float(np.median(burst)))
    knots_v.append(0.5 * (pair_prev[0] + pair_prev[1]) * lsb)
    # Runs of crossings of the same threshold (hovering in a hold): keep the first and the last.
    kt: list[float] = []
    kv: list[float] = []
    for i, (tk, vk) in enumerate(zip(knots_t, knots_v, strict=True)):
        same_prev = i > 0 and knots_v[i - 1] == vk
        same_next = i + 1 < len(knots_v) and knots_v[i + 1] == vk
        if not (same_prev and same_next):
            kt.append(tk)
            kv.append(vk)
    # Gaps between crossings grow geometrically on the approach to a hold (PCHIP follows that);
    # only a gap much longer than that is a hold whose level is unknown within the LSB. There the
    # last crossing's value is held (the approach from it is exact) until shortly before the next
    # crossing, and the model gives the plateau an unknown offset.
    long_gap = max(10.0 * typical, 0.05 * (t_end - float(t[0])))
    plateaus: list[tuple[float, float]] = []
    points: list[tuple[float, float]] = []
    if kt[0] - t[0] > long_gap:
        points += [(float(t[0]), float(level[0] * lsb)), (kt[0] - 2.0 * typical, float(level[0] * lsb))]
        plateaus.append((float(t[0]), kt[0] - typical))
    else:
        points.append((float(t[0]), float(level[0] * lsb)))
    for i in range(len(kt)):
        if i > 0 and kt[i] - kt[i - 1] > long_gap:
            points.append((kt[i] - 2.0 * typical, kv[i - 1]))
            plateaus.append((kt[i - 1] + typical, kt[i] - typical))
        points.append((kt[i], kv[i]))
    if t_end - kt[-1] > long_gap:
        plateaus.append((kt[-1] + typical, t_end + 1.0))
    if t_end > kt[-1]:
        points.append((t_end, kv[-1]))
    out_t: list[float] = []
    out_v: list[float] = []
    for tp, vp in points:
        if not out_t or tp > out_t[-1]:
            out_t.append(tp)
            out_v.append(vp)
    return np.asarray(out_t), np.asarray(out_v), plateaus


def rate_c_per_min(t: np.ndarray, temp: np.ndarray) -> np.ndarray:
    """Smoothed ``dT/dt`` in degC/min: Savitzky-Golay (quadratic) derivative over ~60 s."""
    n = temp.size
    dt = float(t[1] - t[0]) if n > 1 else 1.0
    window = max(5, round(RATE_WINDOW_S / dt) | 1)
    window = min(window, n - 1 if (n - 1) % 2 == 1 else n - 2)
    if window < 5:
        return np.gradient(temp, t) * 60.0
    return savgol_filter(temp, window, 2, deriv=1, delta=dt, mode="interp") * 60.0


@dataclass
class BlockData:
    """Block means of one recording plus what the fitters need around them.

    ``accel`` has the known true input (from the user's simulation) removed. ``temp`` is the
    block mean of the thermometer column; :meth:`temperature` returns it or its de-quantised
    version. ``t`` are block centres on the recording's time axis.
    """

    source: str
    fs: float
    samples_per_block: int
    t: np.ndarray
    accel: np.ndarray
    temp: np.ndarray
    duration_s: float
    lattice_lsb_c: float | None
    temp_smooth: np.ndarray | None
    white_n_mg_rt_s: float
    fine_t: np.ndarray
    fine_accel: np.ndarray
    fine_step_s: float
    full_t: np.ndarray = field(repr=False)
    full_accel: np.ndarray = field(repr=False)
    known_input_block: np.ndarray | None = None
    plateaus: list[tuple[float, float]] = field(default_factory=list)  # quantised holds, see dequantize
    held_out: np.ndarray | None = (
        None  # blocks without weight (``Recording.held_out``), None: every block counts
    )

    @property
    def n(self) -> int:
        return self.t.size

    @property
    def block_s(self) -> float:
        return self.samples_per_block / self.fs

    @property
    def starts(self) -> np.ndarray:
        """Time of each block's first sample (the centre is the mean of its sample times)."""
        return self.t - 0.5 * (self.block_s - 1.0 / self.fs)

    def temperature(self, dequantized: bool) -> np.ndarray:
        if dequantized and self.temp_smooth is not None:
            return self.temp_smooth
        return self.temp

    @cached_property
    def _rates(self) -> dict[bool, np.ndarray]:
        return {q: rate_c_per_min(self.t, self.temperature(q)) for q in (False, True)}

    def rate(self, dequantized: bool) -> np.ndarray:
        return self._rates[dequantized]

    @cached_property
    def hold_after_ramp_s(self) -> float:
        """The longest hold after a ramp (s): where a filtered term's decay shows (temp_rate's
        search range for a filter, ``trainer.physics.catalogue.temp_rate.freed_max_s``)."""
        return longest_hold_after_ramp_s(self.rate(True), self.block_s)

    def subset(self, stop: int) -> BlockData:
        """The first ``stop`` blocks (the held-out check fits on a leading part of the run)."""
        keep_full = np.searchsorted(self.full_t, self.t[stop - 1] + 0.5 * self.block_s)
        keep_fine = np.searchsorted(self.fine_t, self.t[stop - 1] + 0.5 * self.block_s)
        return BlockData(
            source=self.source,
            fs=self.fs,
            samples_per_block=self.samples_per_block,
            t=self.t[:stop],
            accel=self.accel[:stop],
            temp=self.temp[:stop],
            duration_s=float(self.t[stop - 1] + 0.5 * self.block_s - (self.t[0] - 0.5 * self.block_s)),
            lattice_lsb_c=self.lattice_lsb_c,
            temp_smooth=None if self.temp_smooth is None else self.temp_smooth[:stop],
            white_n_mg_rt_s=self.white_n_mg_rt_s,
            fine_t=self.fine_t[:keep_fine],
            fine_accel=self.fine_accel[:keep_fine],
            fine_step_s=self.fine_step_s,
            full_t=self.full_t[:keep_full],
            full_accel=self.full_accel[:keep_full],
            known_input_block=None if self.known_input_block is None else self.known_input_block[:stop],
            plateaus=[p for p in self.plateaus if p[0] < self.t[stop - 1]],
        )


def white_noise_density(accel: np.ndarray, fs: float) -> float:
    """White-noise density ``n`` (mg s^1/2) from robust first differences at the full rate."""
    diffs = np.diff(np.asarray(accel, dtype=np.float64))
    if diffs.size < 2:
        return 0.0
    mad = float(np.median(np.abs(diffs - np.median(diffs))))
    return 1.4826 * mad / math.sqrt(2.0) / math.sqrt(fs)


def build_blocks(
    rec: Recording, *, known_input: np.ndarray | None = None, max_blocks: int = DEFAULT_MAX_BLOCKS
) -> BlockData:
    """Aggregate ``rec`` (already stripped of ``true_*`` columns) into :class:`BlockData`."""
    if any(name.startswith("true_") for name in rec.columns):
        raise ValueError("diagnosis must not see ground truth: pass rec.without_truth()")
    t = np.asarray(rec.time_s, dtype=np.float64)
    n = t.size
    if n < MIN_BLOCKS * 2:
        raise UserError(f"{rec.source}: {n} rows is too short to diagnose (need at least {MIN_BLOCKS * 2})")
    fs = float(rec.sample_rate_hz)
    accel = np.asarray(rec.accel_mg, dtype=np.float64)
    if known_input is not None:
        accel = accel - known_input
    temp = np.asarray(rec.temp_c, dtype=np.float64)
    m = max(1, n // max_blocks)
    nb = n // m
    t0 = float(t[0])
    tb = block_means(t, m, nb) - t0
    lsb = detect_lattice(temp)
    smooth_block = None
    plateaus: list[tuple[float, float]] = []
    if lsb is not None:
        kt, kv, plateaus = dequantize(t - t0, temp, lsb)
        smooth_block = (
            PchipInterpolator(kt, kv, extrapolate=True)(tb) if kt.size > 2 else np.interp(tb, kt, kv)
        )
    mf = max(1, round(FINE_STEP_S * fs))
    nf = n // mf
    held = None
    measured = accel
    rows_held = rec.held_out()
    if rows_held is not None:
        held = block_means(rows_held.astype(np.float64), m, nb) > 0.5
        measured = accel[~rows_held]
    return BlockData(
        source=rec.source,
        fs=fs,
        samples_per_block=m,
        t=tb,
        accel=block_means(accel, m, nb),
        temp=block_means(temp, m, nb),
        duration_s=nb * m / fs,
        lattice_lsb_c=lsb,
        temp_smooth=smooth_block,
        white_n_mg_rt_s=white_noise_density(measured, fs),
        fine_t=block_means(t, mf, nf) - t0,
        fine_accel=block_means(accel, mf, nf),
        fine_step_s=mf / fs,
        full_t=t - t0,
        full_accel=accel,
        known_input_block=None if known_input is None else block_means(known_input, m, nb),
        plateaus=plateaus,
        held_out=held if held is not None and held.any() else None,
    )
