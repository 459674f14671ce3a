"""Locating: where a fit's residual is structured, and where each found effect shows.

Builds on the scans of :mod:`.locate` (windows, spectra, Allan deviation) and the step and
period scans of :mod:`.candidates` (which itself uses :mod:`.locate`, hence a module of its own).
Significances are kept unrounded; the report rounds them when it writes them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trainer.diagnose.blocks import BlockData
from trainer.diagnose.candidates import FAST_PERIOD_BLOCKS, fine_residual, scan_periods, scan_steps
from trainer.diagnose.gls import window_variances
from trainer.diagnose.locate import TINY, AllanComparison, modelled_adev, scan_regions, spectral_peaks
from trainer.diagnose.model import ModelFit
from trainer.diagnose.profile import Profile, Region, region
from trainer.diagnose.select import THRESHOLD
from trainer.physics.catalogue import DEFINITIONS
from trainer.physics.catalogue.base import WhereContext
from trainer.physics.catalogue.periodic import REGION_KIND as PERIODIC_KIND
from trainer.physics.effects import EffectConfig

ENVELOPE_FRACTION = 0.02  # moving-RMS window of an effect's visible part, as a fraction of the run
MAX_EFFECT_REGIONS = 4


@dataclass(frozen=True)
class AllanWhere:
    """Where a noise term shows: a tau range of the Allan deviation (in time, the whole run).

    ``max_adev_ratio`` is the largest residual-over-model ratio of an Allan departure; None when
    there was no clear departure and the range is where the term dominates the noise model.
    """

    t_end_s: float
    segment: str
    temp_min_c: float
    temp_max_c: float
    tau_range_s: tuple[float, float]
    max_adev_ratio: float | None
    t_start_s: float = 0.0
    branch: str = "mixed"
    kind: str = "allan"


def noise_cov(fit: ModelFit) -> np.ndarray:
    """``fit``'s block noise covariance (unit covariance times the profiled scale)."""
    return fit.gls.cov_unit * (fit.rss / fit.data.n)


def window_z(residual: np.ndarray, cov: np.ndarray, a: int, b: int) -> float:
    """The summed residual over blocks ``a:b`` over its standard deviation under ``cov``."""
    _, var = window_variances(cov[a:b, a:b], b - a, 1)
    return float(np.sum(residual[a:b]) / math.sqrt(max(float(var[0]), TINY)))


def where_regions(
    visible: np.ndarray, data: BlockData, profile: Profile, residual: np.ndarray, cov: np.ndarray
) -> list[Region]:
    """Where an effect's visible part (what the rest of the model cannot absorb) is large.

    The visible part is the final model's prediction minus that of the model without the effect.
    Its envelope (moving RMS over ~2 % of the run) above half its peak gives the regions, so a
    sawtooth or a branch offset is one region, not many single blocks.
    """
    if visible.size == 0 or float(np.max(np.abs(visible))) <= 0:
        return []
    width = max(3, round(ENVELOPE_FRACTION * data.n) | 1)
    kernel = np.ones(width) / width
    envelope = np.sqrt(np.convolve(visible * visible, kernel, mode="same"))
    mask = envelope >= 0.5 * float(np.max(envelope))
    idx = np.flatnonzero(mask)
    runs: list[list[int]] = []
    for k in idx.tolist():
        if runs and k - runs[-1][1] <= width:
            runs[-1][1] = k
        else:
            runs.append([k, k])
    scored = sorted(runs, key=lambda r: -float(np.sum(envelope[r[0] : r[1] + 1])))[:MAX_EFFECT_REGIONS]
    out = []
    for a, b in sorted(scored):
        z = window_z(residual, cov, a, b + 1)
        sig = {"z": z, "peak_mg": float(np.max(np.abs(visible[a : b + 1])))}
        out.append(region(data, profile, a, b + 1, sig, "effect"))
    return out


def special_where(
    effect: EffectConfig, data: BlockData, profile: Profile, residual: np.ndarray, cov: np.ndarray, step: str
) -> list[Region] | None:
    """Effects whose location is a parameter (a step's time, a warm-up's start, a period): the
    definition's ``where`` hook; ``None`` when it has none."""
    hook = DEFINITIONS[effect.identifier].finder.where
    if hook is None:
        return None
    context = WhereContext(
        data,
        step,
        lambda a, b: window_z(residual, cov, a, b),
        lambda a, b, sig, kind, note: region(data, profile, a, b, sig, kind, note),
    )
    return hook(effect.params, context)


def noise_where(
    effect: str, noise: dict[str, dict[str, float]], data: BlockData, profile: Profile, allan: AllanComparison
) -> list[AllanWhere]:
    """Where a noise term shows: the Allan departures of the starting model's residual or, when
    there is no clear departure, the taus where it dominates the fitted noise model."""
    segment = "+".join(dict.fromkeys(s.label for s in profile.segments))

    def where(span: tuple[float, float], ratio: float | None) -> AllanWhere:
        return AllanWhere(data.duration_s, segment, profile.temp_min_c, profile.temp_max_c, span, ratio)

    if allan.departures:
        return [where((a, b), r) for a, b, r in allan.departures]
    dt = 1.0 / data.fs
    taus = np.logspace(math.log10(dt), math.log10(max(data.duration_s / 10.0, 2.0 * dt)), 200)
    alone = modelled_adev(taus, dt, data.duration_s, {effect: noise[effect]})
    others = modelled_adev(taus, dt, data.duration_s, {k: v for k, v in noise.items() if k != effect})
    dominant = taus[alone > others]
    span = (float(dominant[0]), float(dominant[-1])) if dominant.size else (float(taus[-1]), float(taus[-1]))
    return [where(span, None)]


def locate_mismatch(
    fit: ModelFit,
    data: BlockData,
    profile: Profile,
    cov: np.ndarray,
    allan: AllanComparison,
) -> list[Region]:
    """Regions, change points, periodic components and Allan departures of ``fit``'s residual.

    The window scan reads the GLS residual against the noise covariance ``cov`` it was fitted
    under (a random walk pinned at the start and a least-squares residual would not agree).
    """
    out = scan_regions(fit.residual, cov, data, profile)
    times, rss = scan_steps(fit, data)
    k = int(np.argmin(rss))
    base_rss = float(np.sum(fit.gls.whiten(fit.residual) ** 2))
    penalty = math.log(data.n)  # BIC cost of one parameter
    lr = data.n * math.log(max(base_rss, TINY) / max(float(rss[k]), TINY))
    if lr - 2.0 * penalty > THRESHOLD:  # a step: level and time
        j = int(np.searchsorted(data.starts, times[k]))
        sig = {"likelihood_ratio": lr, "delta_bic": lr - 2.0 * penalty}
        note = f"best single step at t = {times[k]:.1f} s"
        out.append(region(data, profile, max(0, j - 1), min(data.n, j + 1), sig, "change_point", note))
    lo_slow = FAST_PERIOD_BLOCKS * data.block_s
    if 0.5 * data.duration_s > lo_slow:
        freqs = np.arange(2.0 / data.duration_s, 1.0 / lo_slow, 1.0 / (4.0 * data.duration_s))
        rss_p = scan_periods(fit, data, 1.0 / freqs)
        k = int(np.argmin(rss_p))
        lr = data.n * math.log(max(base_rss, TINY) / max(float(rss_p[k]), TINY))
        if lr - 3.0 * penalty > THRESHOLD:  # a sine: amplitude, phase and period
            sig = {"likelihood_ratio": lr, "delta_bic": lr - 3.0 * penalty}
            note = f"slow periodic component near {1.0 / freqs[k]:.0f} s (GLS scan)"
            out.append(region(data, profile, 0, data.n, sig, PERIODIC_KIND, note))
    x = fine_residual(fit, data)
    for term in fit.terms:  # components fitted on the fine grid are removed before looking
        fine_offset = DEFINITIONS[term.identifier].finder.fine_offset
        if fine_offset is not None and term.offset is not None:
            x = x - fine_offset(term, data.fine_t)
    lo = max(4.0, 2.5 * data.fine_step_s)
    for peak in spectral_peaks(x, data.fine_step_s, lo, lo_slow):
        sig = {"p_value": peak.p_value, "peak_over_background": peak.ratio}
        note = f"spectral peak at period {peak.period_s:.2f} s"
        out.append(region(data, profile, 0, data.n, sig, PERIODIC_KIND, note))
    for a, b, ratio in allan.departures:
        note = f"Allan deviation above the modelled noise for tau {a:.3g}..{b:.3g} s"
        out.append(region(data, profile, 0, data.n, {"max_adev_ratio": ratio}, "allan", note))
    return out
