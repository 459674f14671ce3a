"""Allan-deviation scoring of accelerometer outputs (IEEE Std 952 terms, the paper's Table 1).

The Allan deviation itself comes from :func:`allantools.oadev` (overlapping estimator, the input
treated as a rate-like quantity, ``data_type="freq"``). This module adds what allantools does not
do: a tau grid suited to multi-hour recordings, honest error bars, the reading of the five IEEE
952 noise coefficients off the curve, the paper's improvement table and the Figure-13 plot.
Conventions (which tau each coefficient is read at) follow ``shared/specs/physics-catalogue.md``;
the algorithm is documented in ``docs/allan.md``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Literal

import allantools
import numpy as np
from scipy.optimize import nnls

from trainer.data.channels import DEFAULT_UNIT, ONE_AXIS_CHANNEL, Signal
from trainer.scoring.markdown import markdown_table

__all__ = [
    "BIAS_INSTABILITY_FACTOR",
    "AllanCurve",
    "AllanTable",
    "NoiseCoefficients",
    "TermFit",
    "allan_deviation",
    "allan_table",
    "default_taus",
    "improvement_percent",
    "local_slopes",
    "noise_coefficients",
    "plot_allan",
]

#: sigma_min = 0.664 B for a flicker floor; sqrt(2 ln 2 / pi) = 0.66428 (IEEE Std 952, Annex C).
BIAS_INSTABILITY_FACTOR: float = math.sqrt(2.0 * math.log(2.0) / math.pi)

#: Default grid density and reach: ~10 log-spaced taus per decade, longest tau N / (10 rate), so
#: even the last point averages over >= 10 independent clusters (about 24 % relative error).
DEFAULT_POINTS_PER_DECADE: int = 10
DEFAULT_MIN_CLUSTERS: int = 10

TausSpec = None | Literal["octave", "decade"] | int | Sequence[float] | np.ndarray
Fallback = Literal["envelope", "closest"]


# --------------------------------------------------------------------------------------------
# Allan deviation
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class AllanCurve:
    """An overlapping Allan deviation curve; arrays are read-only so the dataclass is truly frozen.

    ``adev_err`` is the 1-sigma error of ``adev`` from the IEEE 952 cluster formula
    ``adev / sqrt(2 (N/m - 1))`` (N samples, m samples per cluster), not allantools'
    ``adev / sqrt(n_pairs)``, which treats the correlated overlapping pairs as independent and is
    far too optimistic at long tau. ``n_pairs`` is allantools' count of second differences.
    """

    taus_s: np.ndarray
    adev: np.ndarray
    adev_err: np.ndarray
    n_pairs: np.ndarray

    def __post_init__(self) -> None:
        for name in ("taus_s", "adev", "adev_err", "n_pairs"):
            dtype = np.int64 if name == "n_pairs" else np.float64
            values = np.array(getattr(self, name), dtype=dtype)  # private copy, then lock it
            values.setflags(write=False)
            object.__setattr__(self, name, values)
        sizes = {len(self.taus_s), len(self.adev), len(self.adev_err), len(self.n_pairs)}
        if len(sizes) != 1:
            raise ValueError("AllanCurve arrays must have equal lengths")

    def __len__(self) -> int:
        return len(self.taus_s)


def default_taus(
    n_samples: int,
    rate_hz: float,
    taus: TausSpec = None,
    max_tau_s: float | None = None,
) -> np.ndarray:
    """Averaging times (s) on the integer-sample grid, capped so the longest tau stays estimable.

    ``None`` means ``DEFAULT_POINTS_PER_DECADE`` log-spaced points per decade; an int is the
    points per decade; "octave" is m = 1, 2, 4, ...; "decade" is m = 1, 2, 4, 10, 20, 40, ...
    (allantools' definitions). All start at one sample and stop at ``max_tau_s`` (default
    N / (10 rate)). Rounding to whole samples merges duplicates at short tau.
    """
    if max_tau_s is None:
        max_m = n_samples // DEFAULT_MIN_CLUSTERS
    else:
        max_m = math.floor(max_tau_s * rate_hz + 1e-9)
    max_m = min(max_m, (n_samples - 1) // 2)  # oadev needs 2m < N+1 for >= 2 second differences
    if max_m < 1:
        raise ValueError(
            f"{n_samples} samples at {rate_hz} Hz leave no averaging time up to the cap "
            f"(max_tau_s={max_tau_s})"
        )
    if taus is None:
        taus = DEFAULT_POINTS_PER_DECADE
    if isinstance(taus, bool):
        raise ValueError("taus must be None, 'octave', 'decade', an int or an array, not a bool")
    if isinstance(taus, str):
        if taus == "octave":
            m = 2.0 ** np.arange(0, math.floor(math.log2(max_m)) + 1)
        elif taus == "decade":
            decades = 10.0 ** np.arange(0, math.floor(math.log10(max_m)) + 1)
            m = np.sort(np.concatenate([decades, 2 * decades, 4 * decades]))
        else:
            raise ValueError(f"unknown taus keyword {taus!r}; use 'octave', 'decade', an int or an array")
    elif isinstance(taus, int | np.integer):
        if taus < 1:
            raise ValueError(f"points per decade must be >= 1, got {taus}")
        n_points = max(2, math.ceil(taus * math.log10(max_m)) + 1)
        m = np.logspace(0.0, math.log10(max_m), n_points)
    else:
        requested = np.asarray(taus, dtype=float).ravel()
        if requested.size == 0 or not np.all(np.isfinite(requested)) or np.any(requested <= 0):
            raise ValueError("explicit taus must be a non-empty array of positive, finite seconds")
        m = requested * rate_hz
    m = np.unique(np.round(m))
    m = m[(m >= 1) & (m <= max_m)]
    if m.size == 0:
        raise ValueError(f"no requested tau lies between 1/rate and {max_m / rate_hz:g} s")
    return m / rate_hz


def allan_deviation(
    x: np.ndarray,
    rate_hz: float,
    taus: TausSpec = None,
    *,
    max_tau_s: float | None = None,
) -> AllanCurve:
    """Overlapping Allan deviation of a rate-like signal ``x`` (mg) sampled at ``rate_hz``.

    Wraps ``allantools.oadev(x, rate, data_type="freq", taus)``; see :func:`default_taus` for the
    grid. For an explicit tau array the cap still applies (a tau with fewer than 10 clusters is
    dropped unless ``max_tau_s`` raises the cap).
    """
    samples = np.asarray(x, dtype=float)
    if samples.ndim != 1:
        raise ValueError(f"x must be 1-D, got shape {samples.shape}")
    if samples.size < 3:
        raise ValueError(f"need at least 3 samples for an Allan deviation, got {samples.size}")
    if not np.all(np.isfinite(samples)):
        raise ValueError(f"x contains {np.count_nonzero(~np.isfinite(samples))} non-finite samples")
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be positive and finite, got {rate_hz}")
    grid = default_taus(samples.size, rate_hz, taus, max_tau_s)
    taus_s, adev, _naive_err, n_pairs = allantools.oadev(samples, rate=rate_hz, data_type="freq", taus=grid)
    clusters = samples.size / np.round(np.asarray(taus_s) * rate_hz)
    adev = np.asarray(adev, dtype=float)
    adev_err = adev / np.sqrt(2.0 * np.maximum(clusters - 1.0, 1.0))
    return AllanCurve(taus_s=taus_s, adev=adev, adev_err=adev_err, n_pairs=n_pairs)


# --------------------------------------------------------------------------------------------
# Noise coefficients
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TermFit:
    """How one coefficient was read: its value, where from, and whether its slope was really seen.

    ``observed`` False means the value is an upper-bound-style estimate: the term's signature was
    not found (slopes method: no run of matching slope spanning ``min_span_decades``; model
    method: the term never dominates the fitted variance), so reports should flag it.
    """

    value: float
    observed: bool
    tau_range_s: tuple[float, float]
    read_tau_s: float
    slope: float
    n_points: int


@dataclass(frozen=True)
class NoiseCoefficients:
    """The five IEEE 952 coefficients of one signal (mg-based units, see the physics catalogue)."""

    q_mg: float
    n_mg_rt_s: float
    b_mg: float
    b_tau_s: float
    k_mg_per_rt_s: float
    r_mg_per_s: float
    method: str
    fits: Mapping[str, TermFit]

    def to_dict(self) -> dict[str, object]:
        """Plain floats/bools/lists for JSON reports."""
        return {
            "q_mg": self.q_mg,
            "n_mg_rt_s": self.n_mg_rt_s,
            "b_mg": self.b_mg,
            "b_tau_s": self.b_tau_s,
            "k_mg_per_rt_s": self.k_mg_per_rt_s,
            "r_mg_per_s": self.r_mg_per_s,
            "method": self.method,
            "fits": {
                name: {
                    "value": fit.value,
                    "observed": fit.observed,
                    "tau_range_s": list(fit.tau_range_s),
                    "read_tau_s": fit.read_tau_s,
                    "slope": fit.slope,
                    "n_points": fit.n_points,
                }
                for name, fit in self.fits.items()
            },
        }


@dataclass(frozen=True)
class _SlopeTerm:
    name: str
    slope: float
    read_tau_s: float
    unit_sigma_at_read: float  # sigma(read_tau) for a unit coefficient; 1 for every catalogue term


# Each catalogue convention is chosen so the unit-coefficient ADEV equals 1 at its read tau.
_SLOPE_TERMS: tuple[_SlopeTerm, ...] = (
    _SlopeTerm("q_mg", -1.0, math.sqrt(3.0), 1.0),  # sqrt(3) q / tau
    _SlopeTerm("n_mg_rt_s", -0.5, 1.0, 1.0),  # n / sqrt(tau)
    _SlopeTerm("k_mg_per_rt_s", 0.5, 3.0, 1.0),  # k sqrt(tau / 3)
    _SlopeTerm("r_mg_per_s", 1.0, math.sqrt(2.0), 1.0),  # r tau / sqrt(2)
)
_TERM_ORDER: tuple[str, ...] = ("q_mg", "n_mg_rt_s", "b_mg", "k_mg_per_rt_s", "r_mg_per_s")


def local_slopes(taus_s: np.ndarray, adev: np.ndarray, window_decades: float = 0.25) -> np.ndarray:
    """Log-log slope at each tau: least-squares over the points within ``window_decades`` of it.

    The window always includes the immediate neighbours, so a sparse (octave) grid still gets a
    two-sided difference; a window instead of a bare central difference tames the estimator noise
    at long tau, at the cost of smoothing sharp corners.
    """
    log_tau = np.log10(taus_s)
    log_sigma = np.log10(adev)
    count = len(log_tau)
    slopes = np.full(count, np.nan)
    for i in range(count):
        inside = np.abs(log_tau - log_tau[i]) <= window_decades + 1e-12
        inside[max(i - 1, 0) : min(i + 2, count)] = True
        lt, ls = log_tau[inside], log_sigma[inside]
        if lt.size >= 2:
            dt = lt - lt.mean()
            slopes[i] = float(np.dot(dt, ls - ls.mean()) / np.dot(dt, dt))
    return slopes


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Inclusive (start, stop) index pairs of the contiguous True runs of ``mask``."""
    runs: list[tuple[int, int]] = []
    start = None
    for i, flag in enumerate(mask):
        if flag and start is None:
            start = i
        elif not flag and start is not None:
            runs.append((start, i - 1))
            start = None
    if start is not None:
        runs.append((start, len(mask) - 1))
    return runs


def _best_run(log_tau: np.ndarray, deviation: np.ndarray, tolerance: float) -> tuple[int, int] | None:
    """The widest run (in decades) of ``|deviation| <= tolerance``; ties: more points, then closer."""
    candidates = _runs(np.abs(deviation) <= tolerance)
    if not candidates:
        return None

    def rank(run: tuple[int, int]) -> tuple[float, int, float]:
        lo, hi = run
        return (log_tau[hi] - log_tau[lo], hi - lo, -float(np.mean(np.abs(deviation[lo : hi + 1]))))

    return max(candidates, key=rank)


def _line_weights(rel_err: np.ndarray, slope_deviation: np.ndarray) -> np.ndarray:
    """Inverse of each point's statistical variance plus the squared bias its slope mismatch implies.

    A neighbouring term whose slope differs by >= 0.5 and that moves the local slope by ``ds``
    carries <= 2 ds of the variance, so it biases sigma by about ``ds`` (relative). Weighting by
    ``1 / (rel_err^2 + ds^2)`` therefore favours points that are both well averaged and pure,
    instead of the contaminated short-tau edge of a run that pure 1/rel_err^2 weights favour.
    """
    return 1.0 / (rel_err**2 + slope_deviation**2 + 1e-24)


def _fit_slope_term(
    term: _SlopeTerm,
    taus: np.ndarray,
    adev: np.ndarray,
    rel_err: np.ndarray,
    slopes: np.ndarray,
    tolerance: float,
    min_span_decades: float,
    fallback: Fallback,
) -> TermFit:
    """Fixed-slope line through the term's run of matching slope, evaluated at its catalogue tau."""
    log_tau = np.log10(taus)
    deviation = slopes - term.slope
    run = _best_run(log_tau, deviation, tolerance)
    if run is not None:
        lo, hi = run
        observed = bool(log_tau[hi] - log_tau[lo] >= min_span_decades - 1e-9)
        sl = slice(lo, hi + 1)
        # log10(sigma) = slope * log10(tau) + c, c a weighted mean (see _line_weights).
        weights = _line_weights(rel_err[sl], deviation[sl])
        intercept = float(np.average(np.log10(adev[sl]) - term.slope * log_tau[sl], weights=weights))
    elif fallback == "envelope":
        # The largest coefficient the curve allows: the line of this slope touching the upper
        # 1-sigma envelope from below. On a noise-free (log-convex) curve this is the point of
        # closest slope; unlike a noisy local slope it cannot land on an arbitrary point.
        offsets = np.log10(adev * (1.0 + rel_err)) - term.slope * log_tau
        lo = hi = int(np.argmin(offsets))
        observed = False
        intercept = float(offsets[lo])
    else:  # "closest": MATLAB's literal rule, the line through the point of closest local slope
        lo = hi = int(np.nanargmin(np.abs(deviation)))
        observed = False
        intercept = float(np.log10(adev[lo]) - term.slope * log_tau[lo])
    sigma_at_read = 10.0**intercept * term.read_tau_s**term.slope
    return TermFit(
        value=float(sigma_at_read / term.unit_sigma_at_read),
        observed=observed,
        tau_range_s=(float(taus[lo]), float(taus[hi])),
        read_tau_s=term.read_tau_s,
        slope=term.slope,
        n_points=hi - lo + 1,
    )


def _fit_bias_instability(
    taus: np.ndarray,
    adev: np.ndarray,
    adev_err: np.ndarray,
    slopes: np.ndarray,
    tolerance: float,
    min_span_decades: float,
    fallback: Fallback,
) -> TermFit:
    """B = sigma_min / 0.664, sigma_min the lowest upper 1-sigma bound on the flat floor.

    A plain minimum over many noisy points picks a noise dip (biased low by about one standard
    error of the few-cluster points at long tau); minimising ``adev + adev_err`` instead lets
    well-determined points win, which removes that bias (see docs/allan.md). The floor is the
    widest run of near-zero slope; without one spanning ``min_span_decades`` the whole curve is
    searched (for ``fallback="closest"`` its plain minimum, MATLAB's rule) and the value is
    flagged unobserved (it then bounds B from above).
    """
    log_tau = np.log10(taus)
    upper = adev + adev_err
    run = _best_run(log_tau, slopes, tolerance)
    if run is not None and log_tau[run[1]] - log_tau[run[0]] >= min_span_decades - 1e-9:
        lo, hi = run
        i_min = lo + int(np.argmin(upper[lo : hi + 1]))
        observed = True
    else:
        if fallback == "closest":
            upper = adev
        i_min = int(np.argmin(upper))
        lo = hi = i_min
        observed = False
    return TermFit(
        value=float(upper[i_min]) / BIAS_INSTABILITY_FACTOR,
        observed=observed,
        tau_range_s=(float(taus[lo]), float(taus[hi])),
        read_tau_s=float(taus[i_min]),
        slope=0.0,
        n_points=hi - lo + 1,
    )


def _unobserved(read_tau_s: float, slope: float) -> TermFit:
    return TermFit(0.0, False, (math.nan, math.nan), read_tau_s, slope, 0)


def _coefficients(fits: dict[str, TermFit], method: str) -> NoiseCoefficients:
    ordered = {name: fits[name] for name in _TERM_ORDER}
    return NoiseCoefficients(
        q_mg=ordered["q_mg"].value,
        n_mg_rt_s=ordered["n_mg_rt_s"].value,
        b_mg=ordered["b_mg"].value,
        b_tau_s=ordered["b_mg"].read_tau_s,
        k_mg_per_rt_s=ordered["k_mg_per_rt_s"].value,
        r_mg_per_s=ordered["r_mg_per_s"].value,
        method=method,
        fits=MappingProxyType(ordered),
    )


def _noise_coefficients_slopes(
    curve: AllanCurve, tolerance: float, min_span_decades: float, window_decades: float, fallback: Fallback
) -> NoiseCoefficients:
    taus, adev = curve.taus_s, curve.adev
    rel_err = curve.adev_err / np.where(adev > 0, adev, 1.0)
    positive = adev > 0
    if np.count_nonzero(positive) < 2:  # a constant signal: nothing to read
        fits = {term.name: _unobserved(term.read_tau_s, term.slope) for term in _SLOPE_TERMS}
        fits["b_mg"] = _unobserved(float(taus[0]) if len(taus) else math.nan, 0.0)
        return _coefficients(fits, "slopes")
    taus, adev, rel_err = taus[positive], adev[positive], rel_err[positive]
    adev_err = curve.adev_err[positive]
    slopes = local_slopes(taus, adev, window_decades)
    fits = {
        term.name: _fit_slope_term(term, taus, adev, rel_err, slopes, tolerance, min_span_decades, fallback)
        for term in _SLOPE_TERMS
    }
    fits["b_mg"] = _fit_bias_instability(taus, adev, adev_err, slopes, tolerance, min_span_decades, fallback)
    return _coefficients(fits, "slopes")


def _model_design(taus: np.ndarray) -> np.ndarray:
    """Columns: Allan variance of each term per unit squared coefficient (Q, N, B, K, R)."""
    return np.column_stack(
        [
            3.0 / taus**2,
            1.0 / taus,
            np.full_like(taus, BIAS_INSTABILITY_FACTOR**2),
            taus / 3.0,
            taus**2 / 2.0,
        ]
    )


def _noise_coefficients_model(curve: AllanCurve, min_span_decades: float) -> NoiseCoefficients:
    positive = curve.adev > 0
    taus, adev = curve.taus_s[positive], curve.adev[positive]
    if taus.size == 0:  # a constant signal: nothing to fit
        taus, squared = curve.taus_s, np.zeros(len(_TERM_ORDER))
    else:
        avar = adev**2
        # sigma^2 has twice the relative error of sigma; dividing by avar * that makes every
        # residual a relative error in units of its own standard deviation.
        scale = avar * 2.0 * np.maximum(curve.adev_err[positive] / adev, 1e-6)
        design = _model_design(taus) / scale[:, None]
        column_norm = np.linalg.norm(design, axis=0)  # equalise columns spanning ~20 decades
        solution, _residual = nnls(design / column_norm, avar / scale)
        squared = solution / column_norm
    contributions = _model_design(taus) * squared  # each term's variance at each tau
    total = contributions.sum(axis=1)
    dominant = contributions > 0.5 * np.where(total > 0, total, np.inf)[:, None]
    reads = {"q_mg": math.sqrt(3.0), "n_mg_rt_s": 1.0, "k_mg_per_rt_s": 3.0, "r_mg_per_s": math.sqrt(2.0)}
    slopes = {"q_mg": -1.0, "n_mg_rt_s": -0.5, "b_mg": 0.0, "k_mg_per_rt_s": 0.5, "r_mg_per_s": 1.0}
    i_model_min = int(np.argmin(total)) if len(total) else 0
    fits: dict[str, TermFit] = {}
    for column, name in enumerate(_TERM_ORDER):
        rows = np.flatnonzero(dominant[:, column])
        tau_range = (float(taus[rows[0]]), float(taus[rows[-1]])) if rows.size else (math.nan, math.nan)
        span = math.log10(tau_range[1] / tau_range[0]) if rows.size else -math.inf
        fits[name] = TermFit(
            value=float(math.sqrt(max(squared[column], 0.0))),
            observed=bool(span >= min_span_decades - 1e-9),
            tau_range_s=tau_range,
            read_tau_s=float(taus[i_model_min]) if name == "b_mg" else reads[name],
            slope=slopes[name],
            n_points=int(rows.size),
        )
    return _coefficients(fits, "model")


def noise_coefficients(
    curve: AllanCurve,
    method: Literal["slopes", "model"] = "slopes",
    *,
    slope_tolerance: float = 0.15,
    min_span_decades: float = 0.5,
    slope_window_decades: float = 0.25,
    fallback: Fallback = "envelope",
) -> NoiseCoefficients:
    """Read Q, N, B, K, R off an Allan deviation curve.

    "slopes" (default, IEEE 952 / MATLAB practice): for each slope term, fit a line of the fixed
    slope through the widest contiguous run of taus whose local log-log slope is within
    ``slope_tolerance`` of the target, and evaluate it at the catalogue's tau. With no such run,
    ``fallback="envelope"`` (default) takes the largest coefficient the curve allows (the line
    touching ``adev + adev_err`` from below; on a noise-free curve the point of closest slope) and
    ``"closest"`` MATLAB's line through the point of closest local slope. B is sigma_min / 0.664,
    sigma_min the lowest ``adev + adev_err`` on the widest near-zero-slope run (whole curve if
    none). A term is
    ``observed`` only if its run spans ``min_span_decades`` (0.5 decade is wider than the ~0.27
    decade over which the transition between a -1/2 and a +1/2 term looks flat).

    "model": weighted non-negative least squares of the five-term Allan variance model
    3Q^2/tau^2 + N^2/tau + (2 ln2/pi) B^2 + K^2 tau/3 + R^2 tau^2/2; a term is observed when the
    taus where it carries more than half the fitted variance span ``min_span_decades``. Use it as
    a cross-check: it assumes the five terms are all there is (a deterministic thermal drift is not).
    """
    if len(curve) == 0:
        raise ValueError("empty Allan curve")
    if method == "slopes":
        if fallback not in ("envelope", "closest"):
            raise ValueError(f"unknown fallback {fallback!r}; use 'envelope' or 'closest'")
        return _noise_coefficients_slopes(
            curve, slope_tolerance, min_span_decades, slope_window_decades, fallback
        )
    if method == "model":
        return _noise_coefficients_model(curve, min_span_decades)
    raise ValueError(f"unknown method {method!r}; use 'slopes' or 'model'")


# --------------------------------------------------------------------------------------------
# Table 1
# --------------------------------------------------------------------------------------------

_TABLE_ROWS: tuple[tuple[str, str], ...] = (
    ("b_mg", "B (mg)"),
    ("k_mg_per_rt_s", "K (mg/s^1/2)"),
    ("r_mg_per_s", "R (mg/s)"),
)
_SUPERSCRIPT = str.maketrans("0123456789-+", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻⁺")


def improvement_percent(raw: float, compensated: float) -> float:
    """(raw - compensated) / raw * 100, the paper's improvement; NaN when raw is not positive."""
    if not (math.isfinite(raw) and raw > 0 and math.isfinite(compensated)):
        return math.nan
    return (raw - compensated) / raw * 100.0


def _sci_text(value: float) -> str:
    if not math.isfinite(value):
        return "n/a"
    return "0" if value == 0 else f"{value:.2e}"


def _sci_markdown(value: float) -> str:
    if not math.isfinite(value) or value == 0:
        return _sci_text(value)
    mantissa, exponent = f"{value:.2e}".split("e")
    return f"{mantissa}×10{str(int(exponent)).translate(_SUPERSCRIPT)}"


def _pct(value: float) -> str:
    return "n/a" if not math.isfinite(value) else f"{value:.2f}"


_FLAG_NOTE = (
    "the term's Allan signature was not observed (no matching slope over 0.5 decade, or the minimum "
    "is not on a flat floor); the value is an upper-bound-style estimate."
)


@dataclass(frozen=True)
class AllanTable:
    """The paper's Table 1: B, K, R of the raw signal and each compensated output, improvements.

    Improvements are computed from unrounded coefficients (the paper's PLA B row, 3.29 %, only
    matches that way). ``curves`` holds every ADEV curve, raw first, for :func:`plot_allan`.
    """

    raw_label: str
    raw: NoiseCoefficients
    compensated: Mapping[str, NoiseCoefficients]
    improvement_pct: Mapping[str, Mapping[str, float]]
    average_improvement_pct: Mapping[str, float]
    curves: Mapping[str, AllanCurve]

    def _cells(self, sci: Callable[[float], str], flag: str) -> tuple[list[str], list[list[str]], bool]:
        header = ["", self.raw_label]
        for method in self.compensated:
            header += [method, "Improvement (%)"]
        rows: list[list[str]] = []
        any_flag = False
        for key, label in _TABLE_ROWS:
            raw_fit = self.raw.fits[key]
            any_flag |= not raw_fit.observed
            row = [label, sci(raw_fit.value) + ("" if raw_fit.observed else flag)]
            for method, coefficients in self.compensated.items():
                fit = coefficients.fits[key]
                any_flag |= not fit.observed
                row += [
                    sci(fit.value) + ("" if fit.observed else flag),
                    _pct(self.improvement_pct[method][key]),
                ]
            rows.append(row)
        aver = ["Aver (%)", ""]
        for method in self.compensated:
            aver += ["", _pct(self.average_improvement_pct[method])]
        rows.append(aver)
        return header, rows, any_flag

    def to_markdown(self) -> str:
        """GitHub-flavoured Markdown, values as 5.43×10⁻⁴; unobserved coefficients marked †."""
        header, rows, any_flag = self._cells(_sci_markdown, "†")
        lines = [markdown_table(header, rows, align="l" + "r" * (len(header) - 1))]
        if any_flag:
            lines += ["", f"† {_FLAG_NOTE}"]
        return "\n".join(lines) + "\n"

    def to_text(self) -> str:
        """Fixed-width ASCII table, values as 5.43e-04; unobserved coefficients marked *."""
        header, rows, any_flag = self._cells(_sci_text, "*")
        widths = [max(len(r[c]) for r in [header, *rows]) for c in range(len(header))]

        def fmt(row: list[str]) -> str:
            first = row[0].ljust(widths[0])
            return "  ".join(
                [first] + [cell.rjust(w) for cell, w in zip(row[1:], widths[1:], strict=True)]
            ).rstrip()

        lines = [fmt(header), "  ".join("-" * w for w in widths)]
        lines += [fmt(row) for row in rows]
        if any_flag:
            lines += ["", f"* {_FLAG_NOTE}"]
        return "\n".join(lines) + "\n"


def allan_table(
    raw: np.ndarray,
    compensated: Mapping[str, np.ndarray],
    rate_hz: float,
    *,
    raw_label: str = "Validation Data",
    taus: TausSpec = None,
    method: Literal["slopes", "model"] = "slopes",
) -> AllanTable:
    """Score each compensated output against the raw signal the way the paper's Table 1 does.

    "Aver" is the mean of the B, K and R improvements. Compensated outputs keep the dict's order.
    """
    if raw_label in compensated:
        raise ValueError(f"compensated output named {raw_label!r} clashes with the raw column label")
    curves = {raw_label: allan_deviation(raw, rate_hz, taus)}
    for name, signal in compensated.items():
        curves[name] = allan_deviation(signal, rate_hz, taus)
    coefficients = {name: noise_coefficients(curve, method) for name, curve in curves.items()}
    raw_coefficients = coefficients.pop(raw_label)
    improvements: dict[str, Mapping[str, float]] = {}
    averages: dict[str, float] = {}
    for name, comp in coefficients.items():
        per_term = {
            key: improvement_percent(raw_coefficients.fits[key].value, comp.fits[key].value)
            for key, _ in _TABLE_ROWS
        }
        improvements[name] = MappingProxyType(per_term)
        averages[name] = float(np.mean(list(per_term.values())))
    return AllanTable(
        raw_label=raw_label,
        raw=raw_coefficients,
        compensated=MappingProxyType(coefficients),
        improvement_pct=MappingProxyType(improvements),
        average_improvement_pct=MappingProxyType(averages),
        curves=MappingProxyType(curves),
    )


# --------------------------------------------------------------------------------------------
# Figure 13
# --------------------------------------------------------------------------------------------


def plot_allan(
    curves: Mapping[str, AllanCurve],
    path: str | Path,
    title: str = "Allan deviation",
    *,
    error_bars: bool = False,
    signal: Signal | None = None,
) -> Path:
    """Log-log PNG of ADEV curves, one line each (the paper's Figure 13); returns the path.

    ``signal``: the channel the curves are of, named in the title and the axis (None: in mg,
    a one-axis recording's accelerometer).

    Follows the plotting convention of :mod:`trainer.scoring.plots` (object API on an Agg
    canvas, no global backend switch, no display needed); the file is written atomically.
    """
    from trainer.scoring.plots import new_figure, save_figure

    if not curves:
        raise ValueError("plot_allan needs at least one curve")
    figure = new_figure((7.0, 5.0), 120)
    axes = figure.add_subplot()
    for label, curve in curves.items():
        positive = curve.adev > 0
        (line,) = axes.loglog(curve.taus_s[positive], curve.adev[positive], label=label, linewidth=1.4)
        if error_bars:
            low = np.maximum(curve.adev - curve.adev_err, curve.adev * 1e-3)[positive]
            axes.fill_between(
                curve.taus_s[positive],
                low,
                (curve.adev + curve.adev_err)[positive],
                color=line.get_color(),
                alpha=0.2,
                linewidth=0,
            )
    axes.set_xlabel("averaging time τ (s)")
    shown = signal or Signal(ONE_AXIS_CHANNEL, DEFAULT_UNIT)
    axes.set_ylabel(shown.axis("Allan deviation σ(τ)"))
    axes.set_title(shown.title(title))
    axes.grid(True, which="both", alpha=0.3)
    axes.legend()
    figure.tight_layout()
    return save_figure(figure, path)
