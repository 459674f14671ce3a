"""Where a residual is structured rather than noise: multiscale windows, spectra, Allan deviation.

* Windows: the mean residual over windows of 4, 8, 16, ... blocks is compared with its standard
  deviation under the fitted noise covariance (flicker and random walk included), so slow noise
  is not mistaken for a mismatch; the threshold is Bonferroni-corrected over all windows.
* Spectrum: a Hann-tapered periodogram of the fine-grid residual against a running-median
  background (robust to coloured noise); under noise each ordinate over its background is
  exponential, which gives a p-value corrected for the number of independent frequencies.
* Allan deviation of the full-rate residual against the modelled noise (IEEE 952 terms), with
  the IEEE 952 cluster error bars: the tau range where it departs.

The finder's locating as a whole (steps, slow periods, where each found effect shows) is in
:mod:`.where`, which builds on these scans. Significances are kept unrounded; the report rounds them when it writes them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import median_filter
from scipy.optimize import minimize_scalar
from scipy.stats import norm

from trainer.diagnose.blocks import BlockData
from trainer.diagnose.gls import window_variances
from trainer.diagnose.profile import Profile, Region, region
from trainer.physics.catalogue import NOISE
from trainer.scoring.allan import allan_deviation

ALPHA = 1e-3
TINY = 1e-300  # floor of variances, sums of squares and p-values (no log or division of zero)


def scan_regions(
    residual: np.ndarray, cov: np.ndarray, data: BlockData, profile: Profile, *, alpha: float = ALPHA
) -> list[Region]:
    """Time ranges whose mean residual is significantly non-zero under the noise covariance ``cov``."""
    n = residual.size
    widths = [w for w in (4, 8, 16, 32, 64, 128, 256, 512) if w <= max(4, n // 3)]
    cum = np.concatenate(([0.0], np.cumsum(residual)))
    windows = []
    for width in widths:
        step = max(1, width // 2)
        starts, var = window_variances(cov, width, step)
        sums = cum[starts + width] - cum[starts]
        z = sums / np.sqrt(np.maximum(var, TINY))
        windows.append((width, starts, z))
    count = sum(z.size for _, _, z in windows)
    threshold = float(norm.isf(alpha / 2.0 / max(count, 1)))
    flagged: list[tuple[int, int, float]] = []
    for width, starts, z in windows:
        for s, value in zip(starts[np.abs(z) > threshold], z[np.abs(z) > threshold], strict=True):
            flagged.append((int(s), int(s) + width, float(value)))
    flagged.sort()
    merged: list[list[float]] = []
    for a, b, z in flagged:
        if merged and a <= merged[-1][1] and math.copysign(1, z) == math.copysign(1, merged[-1][3]):
            merged[-1][1] = max(merged[-1][1], b)
            if abs(z) > abs(merged[-1][2]):
                merged[-1][2] = z
        else:
            merged.append([a, b, z, z])
    out = []
    for start, stop, z, _ in merged:
        p = min(1.0, count * 2.0 * float(norm.sf(abs(z))))
        mean = float(np.mean(residual[int(start) : int(stop)]))
        out.append(
            region(
                data,
                profile,
                int(start),
                int(stop),
                {"z": z, "p_value": max(p, TINY), "mean_residual_mg": mean},
                "residual",
            )
        )
    return out


@dataclass(frozen=True)
class SpectralPeak:
    period_s: float
    ratio: float  # periodogram ordinate over its local background
    p_value: float  # corrected for the independent frequencies searched
    noise_var: float  # local noise variance per fine sample (white-equivalent)


def spectral_peaks(
    x: np.ndarray,
    dt: float,
    period_min: float,
    period_max: float,
    *,
    max_peaks: int = 3,
    alpha: float = ALPHA,
) -> list[SpectralPeak]:
    """Significant narrow-band peaks of ``x`` (a residual on a uniform grid of step ``dt``)."""
    m = x.size
    if m < 64 or period_max <= period_min:
        return []
    t = np.arange(m)
    detrended = x - np.polyval(np.polyfit(t, x, 1), t)
    window = np.hanning(m)
    oversample = 4
    nfft = 1 << math.ceil(math.log2(oversample * m))
    spec = np.abs(np.fft.rfft(detrended * window, nfft)) ** 2 / np.sum(window**2)
    freqs = np.fft.rfftfreq(nfft, dt)
    half = 40 * (nfft // m)
    background = median_filter(spec, size=2 * half + 1, mode="nearest") / math.log(2.0)
    band = (freqs >= 1.0 / period_max) & (freqs <= 1.0 / period_min)
    if not np.any(band):
        return []
    ratio = spec / np.maximum(background, TINY)
    independent = max(1.0, (1.0 / period_min - 1.0 / period_max) * m * dt / 2.0)  # Hann: 2 bins wide
    idx = np.flatnonzero(band)
    local_max = idx[
        (ratio[idx] >= ratio[np.maximum(idx - 1, 0)])
        & (ratio[idx] >= ratio[np.minimum(idx + 1, ratio.size - 1)])
    ]
    order = local_max[np.argsort(-ratio[local_max])]
    peaks: list[SpectralPeak] = []
    taken: list[float] = []
    for k in order:
        p = min(1.0, independent * math.exp(-float(ratio[k])))
        if p > alpha or len(peaks) >= max_peaks:
            break
        f = float(freqs[k])
        if any(abs(f - g) < 3.0 / (m * dt) for g in taken):
            continue
        taken.append(f)
        peaks.append(SpectralPeak(1.0 / f, float(ratio[k]), p, float(background[k])))
    return peaks


@dataclass(frozen=True)
class SineFit:
    period_s: float
    amp_mg: float
    phase_rad: float
    delta_rss: float


def fit_sine(t: np.ndarray, x: np.ndarray, period0: float, span_s: float) -> SineFit:
    """Least-squares ``amp sin(2 pi t / P + phase)`` (plus a constant) with ``P`` refined near ``period0``."""
    centred = x - np.mean(x)
    base_rss = float(centred @ centred)

    def rss(period: float) -> tuple[float, np.ndarray]:
        w = 2.0 * math.pi / period
        X = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
        beta, *_ = np.linalg.lstsq(X, x, rcond=None)
        r = x - X @ beta
        return float(r @ r), beta

    f0 = 1.0 / period0
    df = 1.0 / span_s
    result = minimize_scalar(
        lambda f: rss(1.0 / f)[0],
        bounds=(max(f0 - df, 1e-9), f0 + df),
        method="bounded",
        options={"xatol": df * 1e-3},
    )
    period = 1.0 / float(result.x)
    value, beta = rss(period)
    return SineFit(
        period, float(math.hypot(beta[0], beta[1])), float(math.atan2(beta[1], beta[0])), base_rss - value
    )


def modelled_adev(
    taus: np.ndarray, dt: float, duration_s: float, noise: dict[str, dict[str, float]]
) -> np.ndarray:
    """Allan deviation of the modelled noise terms (catalogue coefficients) at ``taus``."""
    var = np.zeros_like(taus, dtype=np.float64)
    for term, definition in NOISE.items():  # catalogue order
        allan_variance = definition.finder.allan_variance
        if term in noise and allan_variance is not None:
            var += allan_variance(taus, dt, duration_s, noise[term])
    return np.sqrt(var)


@dataclass
class AllanComparison:
    taus_s: np.ndarray
    adev: np.ndarray
    adev_err: np.ndarray
    model: np.ndarray
    departures: list[tuple[float, float, float]]  # (tau_min, tau_max, max ratio)


def allan_comparison(
    residual_full: np.ndarray, fs: float, duration_s: float, noise: dict[str, dict[str, float]]
) -> AllanComparison:
    """Allan deviation of the full-rate residual and the tau ranges where it exceeds the model.

    A point departs when it is above the model by more than 2.5 of its (conservative) IEEE 952
    error bars and by more than 20 %; a departure is reported when at least two neighbouring taus do.
    """
    curve = allan_deviation(residual_full, fs, 8)
    taus = np.asarray(curve.taus_s)
    model = modelled_adev(taus, 1.0 / fs, duration_s, noise)
    adev = np.asarray(curve.adev)
    err = np.asarray(curve.adev_err)
    over = (adev - model > 2.5 * err) & (adev > 1.2 * model)
    departures = []
    k = 0
    while k < over.size:
        if over[k]:
            j = k
            while j + 1 < over.size and over[j + 1]:
                j += 1
            if j > k:
                departures.append(
                    (float(taus[k]), float(taus[j]), float(np.max(adev[k : j + 1] / model[k : j + 1])))
                )
            k = j + 1
        else:
            k += 1
    return AllanComparison(taus, adev, err, model, departures)
