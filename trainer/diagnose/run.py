"""The finder end to end: calibrate the user's model, search, locate, and compare before/after."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from tqdm import tqdm

from trainer.data.recording import Recording
from trainer.diagnose.baseline import Baseline, build_baseline
from trainer.diagnose.blocks import DEFAULT_MAX_BLOCKS, BlockData, build_blocks
from trainer.diagnose.candidates import FAST_PERIOD_BLOCKS, fine_residual, scan_periods, scan_steps
from trainer.diagnose.gls import unit_matrices, window_variances
from trainer.diagnose.locate import (
    AllanComparison,
    allan_comparison,
    modelled_adev,
    scan_regions,
    spectral_peaks,
)
from trainer.diagnose.model import (
    PLAUSIBLE,
    ModelFit,
    build_design,
    catalogue_effects,
    fit_model,
)
from trainer.diagnose.profile import Profile, Region, analyse_profile, region
from trainer.diagnose.select import (
    THRESHOLD,
    Selection,
    baseline_support,
    final_indices,
    forward_select,
    resolve,
)
from trainer.diagnose.threads import single_blas_thread
from trainer.physics.catalogue import ADVICE, CANDIDATE_ORDER  # the finder's order and advice, per effect
from trainer.physics.config import PhysicsConfig
from trainer.physics.effects import EFFECT_PARAMETERS, EffectConfig, drift


@dataclass
class FitSummary:
    rms_mg: float  # full-rate residual RMS
    rms_block_mg: float  # residual RMS of the block means (where drift mismatches show)
    bic: float  # with the model's own ML noise estimate (what the selection compared)
    noise: dict[str, dict[str, float]]
    loglik: float
    n_params: int
    per_segment: list[dict[str, Any]]
    residual_block: np.ndarray
    residual_full: np.ndarray
    allan: AllanComparison
    bic_common: float = math.nan  # both models at the final model's noise covariance

    def to_dict(self) -> dict[str, Any]:
        return {
            "rms_mg": round(self.rms_mg, 6),
            "rms_block_mg": round(self.rms_block_mg, 6),
            "bic": round(self.bic, 2),
            "bic_at_final_noise": round(self.bic_common, 2),
            "noise": {k: {n: float(f"{v:.5g}") for n, v in p.items()} for k, p in self.noise.items()},
            "loglik": round(self.loglik, 2),
            "n_params": self.n_params,
            "per_segment": self.per_segment,
            "allan_departures": self.allan.to_dict()["departures"],
        }


@dataclass
class Diagnosis:
    """Everything the report needs; :meth:`to_dict` is the ``--json`` document."""

    source: str
    data: BlockData
    profile: Profile
    baseline: Baseline
    baseline_fit: ModelFit
    selection: Selection
    left_out: list[dict[str, Any]]
    ambiguous: list[dict[str, Any]]
    not_identifiable: list[dict[str, Any]]
    not_supported: list[dict[str, Any]]
    mismatch: list[Region]
    unexplained: list[Region]
    before: FitSummary
    after: FitSummary
    tested: list[dict[str, Any]]
    augmented: PhysicsConfig
    holdout: dict[str, Any] | None
    seconds: float
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        d = self.data
        return {
            "recording": {
                "source": self.source,
                "rows": int(d.full_t.size),
                "sample_rate_hz": d.fs,
                "duration_s": round(d.duration_s, 3),
                "block_s": round(d.block_s, 6),
                "blocks": d.n,
                "white_noise_n_mg_rt_s": float(f"{d.white_n_mg_rt_s:.5g}"),
            },
            "baseline": list(self.baseline.identifiers),
            "baseline_calibrated": _effects_dict(catalogue_effects(self.baseline_fit), self.before.noise),
            "profile": self.profile.to_dict(),
            "criterion": {
                "name": (
                    "BIC of the GLS likelihood of block means, noise (white, flicker, random walk) "
                    "re-estimated for every model (REML)"
                ),
                "rms_note": "RMS and residual plots are least-squares fits of each model's terms",
                "add_threshold": THRESHOLD,
                "ambiguous_below": 6.0,
            },
            "mismatch": [r.to_dict() for r in self.mismatch],
            "left_out": self.left_out,
            "ambiguous": self.ambiguous,
            "not_identifiable": self.not_identifiable,
            "not_supported": self.not_supported,
            "tested": self.tested,
            "fit": {"before": self.before.to_dict(), "after": self.after.to_dict()},
            "unexplained": [r.to_dict() for r in self.unexplained],
            "holdout": self.holdout,
            "notes": self.notes + self.baseline.notes,
            "seconds": round(self.seconds, 2),
        }


def _effects_dict(effects: list[EffectConfig], noise: dict[str, dict[str, float]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for effect in effects:
        params = {k: float(f"{v:.6g}") for k, v in effect.params.items()}
        if effect.identifier in ("periodic", "bias_step"):
            out.setdefault(effect.identifier, []).append(params)
        else:
            out[effect.identifier] = params
    for term, params in noise.items():
        out[term] = {k: float(f"{v:.6g}") for k, v in params.items()}
    return out


# ------------------------------------------------------------------------------------ helpers


def full_rate_model(fit: ModelFit) -> np.ndarray:
    """The fitted model re-simulated at the full rate with ``physics.effects.drift`` (the rerun)."""
    data = fit.data
    dequant = "temp_quantization" in fit.identifiers
    T_full = np.interp(data.full_t, data.t, data.temperature(dequant))
    rate_full = np.interp(data.full_t, data.t, data.rate(dequant))
    effects = catalogue_effects(fit)
    g_in = 0.0
    breakdown = drift(effects, data.full_t, T_full, g_in_mg=g_in, dT_die_dt_c_per_min=rate_full)
    out = np.asarray(breakdown.total, dtype=np.float64).copy()
    for index, term in enumerate(fit.terms):
        if term.identifier == "rate_ramp":
            out += fit.linear(index)["r_mg_per_s"] * data.full_t
        if term.identifier == "scale_factor_tc" and data.known_input_block is not None:
            lin = fit.linear(index)
            if "sf_ppm_per_c" in lin:
                g = np.interp(data.full_t, data.t, data.known_input_block)
                out += g * 1e-6 * lin["sf_ppm_per_c"] * (breakdown.T_pm - 25.0)
    return out


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x * x))) if x.size else float("nan")


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
            {
                "segment": seg.label,
                "t_start_s": round(seg.start_s, 3),
                "t_end_s": round(seg.end_s, 3),
                "rms_mg": round(_rms(residual_full[mf]), 6),
                "rms_block_mg": round(_rms(fit.residual[mb]), 6),
            }
        )
    allan = allan_comparison(residual_full, data.fs, data.duration_s, noise)
    return FitSummary(
        rms_mg=_rms(residual_full),
        rms_block_mg=_rms(fit.residual),
        bic=own.bic,
        noise=noise,
        loglik=own.loglik,
        n_params=own.n_params,
        per_segment=per_segment,
        residual_block=fit.residual,
        residual_full=residual_full,
        allan=allan,
    )


def _cov(fit: ModelFit) -> np.ndarray:
    return fit.gls.cov_unit * (fit.rss / fit.data.n)


def window_z(residual: np.ndarray, cov: np.ndarray, a: int, b: int) -> float:
    _, var = window_variances(cov[a:b, a:b], b - a, 1)
    return float(np.sum(residual[a:b]) / math.sqrt(max(float(var[0]), 1e-300)))


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
    width = max(3, round(0.02 * data.n) | 1)
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
    scored = sorted(runs, key=lambda r: -float(np.sum(envelope[r[0] : r[1] + 1])))[:4]
    out = []
    for a, b in sorted(scored):
        z = window_z(residual, cov, a, b + 1)
        sig = {"z": round(z, 2), "peak_mg": round(float(np.max(np.abs(visible[a : b + 1]))), 5)}
        out.append(region(data, profile, a, b + 1, sig, "effect"))
    return out


def _special_where(
    effect: EffectConfig, data: BlockData, profile: Profile, residual: np.ndarray, cov: np.ndarray, step: str
) -> list[Region] | None:
    """Effects whose location is a parameter: a step's time, a warm-up's start, a period."""
    p = effect.params
    if effect.identifier == "bias_step":
        j = int(np.clip(np.searchsorted(data.starts, p["t_s"]), 1, data.n - 1))
        a, b = max(0, j - 1), min(data.n, j + 1)
        before_z = window_z(residual, cov, max(0, j - 10), j)
        after_z = window_z(residual, cov, j, min(data.n, j + 10))
        sig = {"z_before": round(before_z, 2), "z_after": round(after_z, 2)}
        return [
            region(
                data, profile, a, b, sig, "change_point", f"step of {p['step_mg']:.4g} mg at {p['t_s']:.1f} s"
            )
        ]
    if effect.identifier == "warmup":
        b = int(np.clip(np.searchsorted(data.starts, 3.0 * p["tau_s"]), 2, data.n))
        sig = {"z": round(window_z(residual, cov, 0, b), 2)}
        return [region(data, profile, 0, b, sig, "effect", "first three warm-up time constants")]
    if effect.identifier == "periodic":
        sig = {"evidence": step}  # type: ignore[dict-item]
        return [region(data, profile, 0, data.n, sig, "periodic", f"period {p['period_s']:.4g} s, whole run")]
    return None


def _param_flags(effect: EffectConfig) -> list[str]:
    flags = []
    for name, value in effect.params.items():
        bounds = PLAUSIBLE.get((effect.identifier, name))
        if bounds and not (bounds[0] <= abs(value) <= bounds[1]):
            flags.append(
                f"{name} = {value:.4g} is outside the catalogue's plausible {bounds[0]:g}..{bounds[1]:g}"
            )
    return flags


# ------------------------------------------------------------------------------------ main


def diagnose(
    rec: Recording,
    sim: PhysicsConfig | None = None,
    *,
    holdout_fraction: float = 0.25,
    max_blocks: int = DEFAULT_MAX_BLOCKS,
    progress: bool = False,
) -> Diagnosis:
    """Find what the user's simulation ``sim`` leaves out of recording ``rec``.

    ``rec`` may contain ``true_*`` columns; they are removed before anything is read.
    """
    with single_blas_thread():
        return _diagnose(
            rec, sim, holdout_fraction=holdout_fraction, max_blocks=max_blocks, progress=progress
        )


def _diagnose(
    rec: Recording, sim: PhysicsConfig | None, *, holdout_fraction: float, max_blocks: int, progress: bool
) -> Diagnosis:
    started = time.perf_counter()
    rec = rec.without_truth()
    stages = tqdm(total=5, desc="diagnose", unit="stage", disable=None if progress else True, leave=False)
    t_axis = np.asarray(rec.time_s, dtype=np.float64) - float(rec.time_s[0])
    probe = build_blocks(rec, max_blocks=max_blocks)
    baseline = build_baseline(sim, t_axis, probe.lattice_lsb_c)
    data = (
        probe
        if baseline.known_input is None
        else build_blocks(rec, known_input=baseline.known_input, max_blocks=max_blocks)
    )
    profile = analyse_profile(data, rec.meta, baseline.input_varies)
    ident = profile.identifiability
    stages.update()

    baseline_fit = fit_model(baseline.terms, baseline.noise_terms, data)
    stages.update()

    present = set(baseline.identifiers)
    candidates = [
        c for c in CANDIDATE_ORDER if c not in present and ident.get(c, None) and ident[c].identifiable
    ]
    selection = forward_select(baseline_fit, data, candidates, progress=progress)
    identifiable = {c for c in CANDIDATE_ORDER if ident.get(c) and ident[c].identifiable}
    resolve(selection, data, identifiable, progress=progress)
    stages.update()

    final = selection.final
    cov_final = _cov(final)
    # Both models at the same (reference) noise covariance: their BICs compare, and the baseline's
    # residual is not distorted by a noise fit that absorbed the missing effect.
    baseline_common = fit_model(baseline_fit.terms, final.noise.terms, data, gls=final.gls, refit_noise=False)
    before = summarise(baseline_common, profile, baseline_fit.noise_params(), own=baseline_fit)
    before.bic_common = baseline_common.bic
    after = summarise(final, profile, selection.final_ml.noise_params(), own=selection.final_ml)
    after.bic_common = final.bic

    left_out = _left_out(selection, data, profile, baseline_common, cov_final, before)
    mismatch = locate_mismatch(baseline_common, data, profile, cov_final, before.allan)
    unexplained = locate_mismatch(final, data, profile, cov_final, after.allan)
    stages.update()

    not_identifiable = [
        {"effect": effect, "reason": info.reason, "recommended_test": info.test}
        for effect, info in ident.items()
        if not info.identifiable and effect not in present and effect != "temp_quantization"
    ]
    tested = [
        {"effect": t.effect, "delta_bic": round(t.delta_bic, 2), "how": t.note}
        for t in selection.tested_first_round
    ]
    for effect, info in ident.items():
        if info.identifiable and info.weak and effect in candidates:
            tested.append({"effect": effect, "note": f"weakly identifiable: {info.reason}; {info.test}"})
    not_supported = baseline_support(baseline_common, data)
    augmented = augmented_config(sim, selection.final_ml, data, profile, rec)
    holdout = holdout_check(baseline_common, final, data, holdout_fraction) if holdout_fraction > 0 else None
    stages.update()
    stages.close()
    notes = []
    found = [e["effect"] for e in left_out]
    if (
        data.lattice_lsb_c is not None
        and "temp_quantization" not in found
        and "temp_quantization" not in present
    ):
        notes.append(
            f"the thermometer column is quantised ({data.lattice_lsb_c:g} degC) but modelling the staircase "
            "does not improve the fit"
        )
    return Diagnosis(
        source=rec.source,
        data=data,
        profile=profile,
        baseline=baseline,
        baseline_fit=baseline_common,
        selection=selection,
        left_out=left_out,
        ambiguous=selection.ambiguous,
        not_identifiable=not_identifiable,
        not_supported=not_supported,
        mismatch=mismatch,
        unexplained=unexplained,
        before=before,
        after=after,
        tested=tested,
        augmented=augmented,
        holdout=holdout,
        seconds=time.perf_counter() - started,
        notes=notes,
    )


def _left_out(
    selection: Selection,
    data: BlockData,
    profile: Profile,
    baseline_fit: ModelFit,
    cov: np.ndarray,
    before: FitSummary,
) -> list[dict[str, Any]]:
    final = selection.final
    effects_by_index = {}
    catalogue = catalogue_effects(final)
    term_positions = [k for k, term in enumerate(final.terms) if term.identifier in EFFECT_PARAMETERS]
    for position, effect in zip(term_positions, catalogue, strict=True):
        effects_by_index[position] = effect
    noise_params = selection.final_ml.noise_params()
    out = []
    seen: dict[str, int] = {}
    indices = final_indices(selection)
    for step in selection.steps:
        occurrence = seen.get(step.effect, 0)
        seen[step.effect] = occurrence + 1
        index = indices[(step.effect, occurrence)]
        importance, reduced = selection.drop_one.get(
            (step.effect, occurrence), (step.delta_bic, baseline_fit)
        )
        entry: dict[str, Any] = {"effect": step.effect}
        if index is None:
            entry["params"] = {k: float(f"{v:.6g}") for k, v in noise_params.get(step.effect, {}).items()}
            departures = before.allan.departures
            entry["where"] = [
                {
                    "t_start_s": 0.0,
                    "t_end_s": round(data.duration_s, 3),
                    "segment": "+".join(dict.fromkeys(s.label for s in profile.segments)),
                    "temp_min_c": round(profile.temp_min_c, 3),
                    "temp_max_c": round(profile.temp_max_c, 3),
                    "branch": "mixed",
                    "tau_range_s": [round(a, 3), round(b, 3)],
                    "significance": {"max_adev_ratio": round(r, 3)},
                    "kind": "allan",
                }
                for a, b, r in departures
            ] or [_noise_where(step.effect, noise_params, data, profile)]
        else:
            effect = effects_by_index.get(index) or _rate_ramp_effect(final, index)
            entry["params"] = {k: float(f"{v:.6g}") for k, v in effect.params.items()}
            visible = final.prediction - reduced.prediction
            where = _special_where(effect, data, profile, baseline_fit.residual, cov, step.evidence)
            if where is None:
                where = where_regions(visible, data, profile, baseline_fit.residual, cov)
            entry["where"] = [r.to_dict() for r in where]
            entry["peak_visible_mg"] = round(float(np.max(np.abs(visible))), 5)
            flags = _param_flags(effect)
            if flags:
                entry["flags"] = flags
        entry["evidence"] = {
            "criterion": "BIC",
            "delta_bic_when_added": round(step.delta_bic, 2),
            "delta_bic_when_dropped": round(importance, 2),
            "how": step.evidence,
        }
        entry["advice"] = ADVICE.get(step.effect, "")
        ambiguous_with = [a["effects"][1] for a in selection.ambiguous if a["effects"][0] == step.effect]
        if ambiguous_with:
            entry["ambiguous_with"] = ambiguous_with
        out.append(entry)
    out.sort(key=lambda e: -e["evidence"]["delta_bic_when_dropped"])
    return out


def _noise_where(
    effect: str, noise: dict[str, dict[str, float]], data: BlockData, profile: Profile
) -> dict[str, Any]:
    """Where a noise term shows when the Allan test saw no clear departure: the taus where it
    dominates the fitted noise model (the whole run in time)."""
    taus = np.logspace(math.log10(1.0 / data.fs), math.log10(max(data.duration_s / 10.0, 2.0 / data.fs)), 200)
    alone = modelled_adev(taus, 1.0 / data.fs, data.duration_s, {effect: noise[effect]})
    others = modelled_adev(
        taus, 1.0 / data.fs, data.duration_s, {k: v for k, v in noise.items() if k != effect}
    )
    dominant = taus[alone > others]
    span = [float(dominant[0]), float(dominant[-1])] if dominant.size else [float(taus[-1]), float(taus[-1])]
    return {
        "t_start_s": 0.0,
        "t_end_s": round(data.duration_s, 3),
        "segment": "+".join(dict.fromkeys(s.label for s in profile.segments)),
        "temp_min_c": round(profile.temp_min_c, 3),
        "temp_max_c": round(profile.temp_max_c, 3),
        "branch": "mixed",
        "tau_range_s": [round(span[0], 3), round(span[1], 3)],
        "significance": {"dominant_in_model": True},
        "kind": "allan",
    }


def _rate_ramp_effect(final: ModelFit, index: int) -> EffectConfig:
    """``rate_ramp`` is a catalogue noise term with a deterministic trend; report it like an effect."""
    return EffectConfig("rate_ramp", {"r_mg_per_s": final.linear(index)["r_mg_per_s"]})


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
    lr = data.n * math.log(max(base_rss, 1e-300) / max(float(rss[k]), 1e-300))
    if lr - 2.0 * math.log(data.n) > THRESHOLD:
        j = int(np.searchsorted(data.starts, times[k]))
        out.append(
            region(
                data,
                profile,
                max(0, j - 1),
                min(data.n, j + 1),
                {"likelihood_ratio": round(lr, 1), "delta_bic": round(lr - 2.0 * math.log(data.n), 1)},
                "change_point",
                f"best single step at t = {times[k]:.1f} s",
            )
        )
    lo_slow = FAST_PERIOD_BLOCKS * data.block_s
    if 0.5 * data.duration_s > lo_slow:
        freqs = np.arange(2.0 / data.duration_s, 1.0 / lo_slow, 1.0 / (4.0 * data.duration_s))
        rss_p = scan_periods(fit, data, 1.0 / freqs)
        k = int(np.argmin(rss_p))
        lr = data.n * math.log(max(base_rss, 1e-300) / max(float(rss_p[k]), 1e-300))
        if lr - 3.0 * math.log(data.n) > THRESHOLD:
            out.append(
                region(
                    data,
                    profile,
                    0,
                    data.n,
                    {"likelihood_ratio": round(lr, 1), "delta_bic": round(lr - 3.0 * math.log(data.n), 1)},
                    "periodic",
                    f"slow periodic component near {1.0 / freqs[k]:.0f} s (GLS scan)",
                )
            )
    x = fine_residual(fit, data)
    for term in fit.terms:
        if term.identifier == "periodic" and term.offset is not None:
            amp, phase = term.offset
            x = x - amp * np.sin(2 * math.pi * data.fine_t / term.nl[0] + phase)
    lo = max(4.0, 2.5 * data.fine_step_s)
    for peak in spectral_peaks(x, data.fine_step_s, lo, lo_slow):
        out.append(
            region(
                data,
                profile,
                0,
                data.n,
                {"p_value": float(f"{peak.p_value:.3g}"), "peak_over_background": round(peak.ratio, 1)},
                "periodic",
                f"spectral peak at period {peak.period_s:.2f} s",
            )
        )
    for a, b, ratio in allan.departures:
        out.append(
            region(
                data,
                profile,
                0,
                data.n,
                {"max_adev_ratio": round(ratio, 3)},
                "allan",
                f"Allan deviation above the modelled noise for tau {a:.3g}..{b:.3g} s",
            )
        )
    return out


def predict(fit: ModelFit, data: BlockData) -> np.ndarray:
    """``fit``'s terms and coefficients evaluated on (possibly longer) ``data``, matching columns by role.

    Columns that the fitting data did not have (a quantised hold that only starts later) get 0.
    """
    design = build_design(fit.terms, data)
    coef = dict(zip(fit.roles, fit.beta, strict=True))
    beta = np.array([coef.get(role, 0.0) for role in design.roles])
    return design.X @ beta + design.offset


def noise_forecast(fit: ModelFit, data: BlockData, n_train: int, residual_train: np.ndarray) -> np.ndarray:
    """Conditional mean of the modelled noise over blocks ``n_train:`` given the training residual.

    With flicker and a random walk in the noise model, the best forecast of a held-out stretch is
    the regression plus this kriging term (the BLUP); with white noise only it is zero.
    """
    if not fit.noise.terms:
        return np.zeros(data.n - n_train)
    units = unit_matrices(data.n, data.block_s, data.duration_s)
    cov = np.eye(data.n)
    for term, ratio in fit.noise.ratios().items():
        cov += ratio * units[term]
    weights = np.linalg.solve(cov[:n_train, :n_train], residual_train)
    return cov[n_train:, :n_train] @ weights


def holdout_check(
    baseline_fit: ModelFit, final: ModelFit, data: BlockData, fraction: float
) -> dict[str, Any] | None:
    """Fit both models on the leading part of the run and score them on the held-out tail.

    Two scores: the models as fitted (GLS, the held-out forecast is the regression plus the
    noise model's conditional mean, the BLUP) and the same terms refitted by ordinary least
    squares and extrapolated bare, which is what a compensator without noise model would do.
    """
    n_train = round((1.0 - fraction) * data.n)
    if n_train < 120 or data.n - n_train < 20:
        return None
    train = data.subset(n_train)
    cut = float(data.starts[n_train])
    out: dict[str, Any] = {
        "train_t_end_s": round(cut, 3),
        "test_t_start_s": round(cut, 3),
        "test_t_end_s": round(data.duration_s, 3),
    }
    if any(t.identifier == "bias_step" and t.nl[0] >= cut - data.block_s for t in final.terms):
        out["note"] = (
            "a bias_step inside the held-out part cannot be learned from the fitting part; left out of both"
        )
    for name, fit in (("before", baseline_fit), ("after", final)):
        terms = [t for t in fit.terms if not (t.identifier == "bias_step" and t.nl[0] >= cut - data.block_s)]
        refit = fit_model(terms, fit.noise.terms, train, start=fit.noise)
        residual = data.accel - predict(refit, data)
        forecast = noise_forecast(refit, data, n_train, residual[:n_train])
        ols = fit_model(terms, (), train)
        residual_ols = data.accel - predict(ols, data)
        out[name] = {
            "test_rms_block_mg": round(_rms(residual[n_train:] - forecast), 6),
            "test_rms_block_mg_ols": round(_rms(residual_ols[n_train:]), 6),
            "train_rms_block_mg_ols": round(_rms(residual_ols[:n_train]), 6),
        }
    for key, label in (
        ("test_rms_block_mg", "improvement_percent"),
        ("test_rms_block_mg_ols", "improvement_percent_ols"),
    ):
        b, a = out["before"][key], out["after"][key]
        out[label] = round(100.0 * (b - a) / b, 2) if b > 0 else None
    return out


# ------------------------------------------------------------------------------------ config


def augmented_config(
    sim: PhysicsConfig | None, final: ModelFit, data: BlockData, profile: Profile, rec: Recording
) -> PhysicsConfig:
    """The user's simulation with the fitted (and found) effects, ready for ``trainer simulate``."""
    from trainer.physics.config import NoiseConfig, ProtocolConfig, RecordingConfig

    effects = catalogue_effects(final)
    order = list(EFFECT_PARAMETERS)
    effects = sorted(effects, key=lambda e: order.index(e.identifier))
    noise_values = final.noise_params()
    noise = [NoiseConfig("white_noise", {"n_mg_rt_s": noise_values["white_noise"]["n_mg_rt_s"]})]
    for term in ("bias_instability", "rate_random_walk"):
        if term in noise_values:
            noise.append(NoiseConfig(term, dict(noise_values[term])))
    for index, term in enumerate(final.terms):
        if term.identifier == "rate_ramp":
            noise.append(NoiseConfig("rate_ramp", {"r_mg_per_s": final.linear(index)["r_mg_per_s"]}))
    if sim is not None:
        if any(n.identifier == "quantization_noise" for n in sim.noise):
            noise.insert(0, next(n for n in sim.noise if n.identifier == "quantization_noise"))
        return replace(sim, effects=tuple(effects), noise=tuple(noise))
    from trainer.physics.profiles import SegmentSpec

    temp = data.temperature(True)
    chamber = rec.columns.get("chamber_c")
    specs: list[SegmentSpec] = []

    def temp_at(t_s: float) -> float:
        if chamber is not None:
            return float(np.interp(t_s, rec.time_s - rec.time_s[0], chamber))
        return float(np.interp(t_s, data.t, temp))

    current = temp_at(0.0)
    start_c = current
    for seg in profile.segments:
        duration = seg.end_s - seg.start_s
        end_c = temp_at(seg.end_s - 1e-6)
        label = seg.label
        if (label == "ramp_up" and end_c <= current + 0.01) or (
            label == "ramp_down" and end_c >= current - 0.01
        ):
            label = "hold"
        if label in ("soak", "hold"):
            end_c = temp_at(0.5 * (seg.start_s + seg.end_s)) if chamber is None else end_c
        specs.append(SegmentSpec(label, duration, round(end_c, 4)))
        current = end_c
    sensor = rec.meta.get("sensor", "diagnosed").strip() or "diagnosed"
    return PhysicsConfig(
        recording=RecordingConfig(sample_rate_hz=data.fs, sensor=sensor.splitlines()[0]),
        protocol=ProtocolConfig("custom", round(start_c, 4), tuple(specs)),
        effects=tuple(effects),
        noise=tuple(noise),
    )
