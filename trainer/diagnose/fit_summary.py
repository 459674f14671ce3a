"""How well a model's terms fit: residuals at the full rate and as block means, per segment, Allan deviation."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trainer.diagnose.locate import AllanComparison, allan_comparison
from trainer.diagnose.model import ModelFit, catalogue_effects, fit_model
from trainer.diagnose.profile import Profile
from trainer.physics.catalogue import DEFINITIONS
from trainer.physics.effects import drift


@dataclass(frozen=True)
class SegmentFit:
    """Residual RMS (mg) over one segment of the temperature profile."""

    segment: str
    t_start_s: float
    t_end_s: float
    rms_mg: float
    rms_block_mg: float


@dataclass
class FitSummary:
    rms_mg: float  # full-rate residual RMS
    rms_block_mg: float  # residual RMS of the block means (where drift mismatches show)
    bic: float  # with the model's own ML noise estimate (what the selection compared)
    noise: dict[str, dict[str, float]]
    loglik: float
    n_params: int
    per_segment: list[SegmentFit]
    residual_block: np.ndarray
    residual_full: np.ndarray
    allan: AllanComparison
    bic_common: float = math.nan  # both models at the final model's noise covariance


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x * x))) if x.size else float("nan")


def full_rate_model(fit: ModelFit) -> np.ndarray:
    """The fitted model re-simulated at the full rate with ``physics.effects.drift`` (the rerun),
    plus what the terms' ``full_rate`` hooks add (a noise trend, the scale factor on the input)."""
    data = fit.data
    dequant = any(DEFINITIONS[identifier].finder.dequantize for identifier in fit.identifiers)
    T_full = np.interp(data.full_t, data.t, data.temperature(dequant))
    rate_full = np.interp(data.full_t, data.t, data.rate(dequant))
    effects = catalogue_effects(fit)
    g_in = 0.0
    breakdown = drift(effects, data.full_t, T_full, g_in_mg=g_in, dT_die_dt_c_per_min=rate_full)
    out = np.asarray(breakdown.total, dtype=np.float64).copy()
    for index, term in enumerate(fit.terms):
        hook = DEFINITIONS[term.identifier].finder.full_rate
        extra = None if hook is None else hook(fit.linear(index), data, breakdown.T_pm)
        if extra is not None:
            out += extra
    return out


def summarise(
    fit: ModelFit, profile: Profile, noise: dict[str, dict[str, float]], own: ModelFit
) -> FitSummary:
    """Residuals, RMS and Allan comparison of ``fit``'s terms; ``own`` carries the BIC (own noise).

    Residuals and RMS are those of a least-squares fit of the same terms (nonlinear parameters as
    fitted): a GLS fit under a strong random walk pins the level loosely, which makes its raw
    residual hard to read, while the least-squares residual shows what the terms explain.
    ``noise`` is the noise model the residual's Allan deviation is compared with.
    """
    data = fit.data
    fit = fit_model(fit.terms, (), data, refit_noise=False, optimise=False)
    residual_full = data.full_accel - full_rate_model(fit)
    per_segment = []
    for seg in profile.segments:
        mb = (data.t >= seg.start_s) & (data.t < seg.end_s)
        mf = (data.full_t >= seg.start_s) & (data.full_t < seg.end_s)
        per_segment.append(
            SegmentFit(seg.label, seg.start_s, seg.end_s, rms(residual_full[mf]), rms(fit.residual[mb]))
        )
    allan = allan_comparison(residual_full, data.fs, data.duration_s, noise)
    return FitSummary(
        rms_mg=rms(residual_full),
        rms_block_mg=rms(fit.residual),
        bic=own.bic,
        noise=noise,
        loglik=own.loglik,
        n_params=own.n_params,
        per_segment=per_segment,
        residual_block=fit.residual,
        residual_full=residual_full,
        allan=allan,
    )
