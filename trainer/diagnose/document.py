"""The ``--json`` document of a diagnosis: the one place its numbers are rounded for writing."""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Mapping
from typing import Any

import numpy as np

from trainer.data.channels import UNIT_LABELS
from trainer.diagnose.detection import DetectionLimit
from trainer.diagnose.fit_summary import FitSummary
from trainer.diagnose.holdout import Holdout, HoldoutScore
from trainer.diagnose.locate import AllanComparison
from trainer.diagnose.profile import Region
from trainer.diagnose.result import Ambiguity, Diagnosis, LeftOut, Tested
from trainer.diagnose.select import AMBIGUOUS, MAX_ADDED, SUGGESTIVE, THRESHOLD
from trainer.diagnose.where import AllanWhere
from trainer.physics.catalogue.units import CATALOGUE_UNIT, channel_param_name
from trainer.physics.effects import MULTI_INSTANCE, EffectConfig

CRITERION = (
    "BIC of the GLS likelihood of block means, noise (white, flicker, random walk) "
    "re-estimated for every model (REML)"
)
RMS_NOTE = "RMS and residual plots are least-squares fits of each model's terms"

# decimals of each significance statistic a region can carry (p-values: 3 significant digits)
SIGNIFICANCE_DECIMALS = {
    "z": 2,
    "z_before": 2,
    "z_after": 2,
    "mean_residual_mg": 5,
    "peak_mg": 5,
    "likelihood_ratio": 1,
    "delta_bic": 1,
    "peak_over_background": 1,
    "max_adev_ratio": 3,
}


def sig(value: float, digits: int) -> float:
    """``value`` to ``digits`` significant digits."""
    return float(f"{value:.{digits}g}")


def params(values: dict[str, float]) -> dict[str, float]:
    return {k: sig(v, 6) for k, v in values.items()}


def significance(values: Mapping[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in values.items():
        if key == "p_value":
            out[key] = sig(value, 3)
        elif key in SIGNIFICANCE_DECIMALS:
            out[key] = round(value, SIGNIFICANCE_DECIMALS[key])
        else:  # text or flags
            out[key] = value
    return out


def region(r: Region) -> dict[str, Any]:
    out: dict[str, Any] = {
        "t_start_s": round(r.t_start_s, 3),
        "t_end_s": round(r.t_end_s, 3),
        "segment": r.segment,
        "temp_min_c": round(r.temp_min_c, 3),
        "temp_max_c": round(r.temp_max_c, 3),
        "branch": r.branch,
        "significance": significance(r.significance),
        "kind": r.kind,
    }
    if r.note:
        out["note"] = r.note
    return out


def allan_where(w: AllanWhere) -> dict[str, Any]:
    ratio = w.max_adev_ratio
    return {
        "t_start_s": w.t_start_s,
        "t_end_s": round(w.t_end_s, 3),
        "segment": w.segment,
        "temp_min_c": round(w.temp_min_c, 3),
        "temp_max_c": round(w.temp_max_c, 3),
        "branch": w.branch,
        "tau_range_s": [round(w.tau_range_s[0], 3), round(w.tau_range_s[1], 3)],
        "significance": {"dominant_in_model": True} if ratio is None else {"max_adev_ratio": round(ratio, 3)},
        "kind": w.kind,
    }


def left_out(entry: LeftOut) -> dict[str, Any]:
    out: dict[str, Any] = {
        "effect": entry.effect,
        "params": params(entry.params),
        "where": [allan_where(w) if isinstance(w, AllanWhere) else region(w) for w in entry.where],
    }
    if entry.peak_visible_mg is not None:
        out["peak_visible_mg"] = round(entry.peak_visible_mg, 5)
    if entry.flags:
        out["flags"] = entry.flags
    ev = entry.evidence
    out["evidence"] = {
        "criterion": "BIC",
        "delta_bic_when_added": round(ev.delta_bic_when_added, 2),
        "delta_bic_when_dropped": round(ev.delta_bic_when_dropped, 2),
        "how": ev.how,
    }
    out["advice"] = entry.advice
    if entry.ambiguous_with:
        out["ambiguous_with"] = entry.ambiguous_with
    if entry.absorbs:
        out["absorbs"] = entry.absorbs
    return out


def allan_departures(allan: AllanComparison) -> list[dict[str, float]]:
    return [
        {"tau_min_s": round(a, 4), "tau_max_s": round(b, 4), "max_ratio": round(r, 3)}
        for a, b, r in allan.departures
    ]


def fit_summary(fit: FitSummary) -> dict[str, Any]:
    return {
        "rms_mg": round(fit.rms_mg, 6),
        "rms_block_mg": round(fit.rms_block_mg, 6),
        "bic": round(fit.bic, 2),
        "bic_at_final_noise": round(fit.bic_common, 2),
        "noise": {k: {n: sig(v, 5) for n, v in p.items()} for k, p in fit.noise.items()},
        "loglik": round(fit.loglik, 2),
        "n_params": fit.n_params,
        "per_segment": [
            {
                "segment": s.segment,
                "t_start_s": round(s.t_start_s, 3),
                "t_end_s": round(s.t_end_s, 3),
                "rms_mg": round(s.rms_mg, 6),
                "rms_block_mg": round(s.rms_block_mg, 6),
            }
            for s in fit.per_segment
        ],
        "allan_departures": allan_departures(fit.allan),
    }


def holdout(h: Holdout) -> dict[str, Any]:
    def score(s: HoldoutScore) -> dict[str, float]:
        return {
            "test_rms_block_mg": round(s.test_rms_block_mg, 6),
            "test_rms_block_mg_ols": round(s.test_rms_block_mg_ols, 6),
            "train_rms_block_mg_ols": round(s.train_rms_block_mg_ols, 6),
        }

    def percent(value: float | None) -> float | None:
        return None if value is None else round(value, 2)

    out: dict[str, Any] = {
        "train_t_end_s": round(h.train_t_end_s, 3),
        "test_t_start_s": round(h.test_t_start_s, 3),
        "test_t_end_s": round(h.test_t_end_s, 3),
    }
    if h.note:
        out["note"] = h.note
    out["before"] = score(h.before)
    out["after"] = score(h.after)
    out["improvement_percent"] = percent(h.improvement_percent)
    out["improvement_percent_ols"] = percent(h.improvement_percent_ols)
    return out


def ambiguity(a: Ambiguity) -> dict[str, Any]:
    out: dict[str, Any] = {
        "effects": list(a.effects),
        "delta_bic": round(a.delta_bic, 2),
        "preferred": a.preferred,
        "reason": a.reason,
    }
    if a.undetermined:
        out["undetermined"] = True
    if a.absorbed:
        out["absorbed"] = True
        if a.another:
            out["another"] = True
    if a.absorbed or a.undetermined:
        out["moves_beside"] = [
            {"effect": effect, "param": name, "value": value, "value_beside": beside}
            for effect, name, value, beside in a.moves
        ]
    if a.implausible is not None:  # the implausible best fit, kept with its flags, not named
        out["best_fit"] = left_out(a.implausible)
        out["alternatives"] = [
            {"effects": list(alt.effects), "delta_bic": round(alt.delta_bic, 2), "flags": alt.flags}
            for alt in a.alternatives
        ]
    return out


def undetected(u: DetectionLimit) -> dict[str, Any]:
    """A weakly identifiable effect not named, and the smallest amplitude named along its time
    constant (catalogue names; the channel's own unit is applied with the rest of the document)."""
    return {
        "effect": u.effect,
        "reason": u.reason,
        "recommended_test": u.recommended_test,
        "smallest_named": [
            {
                u.nl_name: sig(lim.nl_value, 4),
                u.amp_name: sig(lim.amplitude, 4),
                "absorbed": round(lim.absorbed, 3),
                **({"at_least": True} if lim.at_least else {}),
            }
            for lim in u.limits
        ],
    }


def tested(t: Tested) -> dict[str, Any]:
    if t.delta_bic is None:
        return {"effect": t.effect, "note": t.note}
    return {"effect": t.effect, "delta_bic": round(t.delta_bic, 2), "how": t.how}


def effects(calibrated: list[EffectConfig], noise: dict[str, dict[str, float]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for effect in calibrated:
        if effect.identifier in MULTI_INSTANCE:
            out.setdefault(effect.identifier, []).append(params(effect.params))
        else:
            out[effect.identifier] = params(effect.params)
    for term, values in noise.items():
        out[term] = params(values)
    return out


def final_baseline(d: Diagnosis) -> list[EffectConfig]:
    """The user's effects as the final model fitted them beside what the finder added: a bias step the
    baseline cannot hold bends its polynomial (``baseline_calibrated``), the final model's does not."""
    wanted = Counter(e.identifier for e in d.baseline_effects)
    out = []
    for effect in d.augmented.effects:
        if wanted[effect.identifier] > 0:
            wanted[effect.identifier] -= 1
            out.append(effect)
    return out


def document(d: Diagnosis) -> dict[str, Any]:
    """The ``--json`` document (numbers rounded; NaN left for :func:`json_text`).

    ``channel`` names the channel diagnosed (``name``, ``unit``, ``label``; an accelerometer's too,
    ``accel0_x`` of ``--channels accel0_x`` once had none); only a one-axis recording whose metadata
    name no channel has none. On a non-mg channel every key that names a quantity in mg names it in
    the channel's unit (``amp_mg`` -> ``amp_dps``, ``rms_block_mg`` -> ``rms_block_dps``: the
    catalogue's one renaming, :func:`~trainer.physics.catalogue.units.channel_param_name`), and
    ``channel`` adds the ``cubic_drift_span`` its amplitudes are judged against.
    """
    out = _document(d)
    if d.unit != CATALOGUE_UNIT:
        out = _renamed_keys(out, d.unit)
    if d.channel is None and d.unit == CATALOGUE_UNIT:
        return out
    channel: dict[str, Any] = {"name": d.channel, "unit": d.unit, "label": UNIT_LABELS[d.unit]}
    if d.scale is not None:
        channel["cubic_drift_span"] = sig(d.scale.drift_span, 6)
    return {"channel": channel, **out}


def _renamed_keys(value: Any, unit: str) -> Any:
    if isinstance(value, dict):
        return {channel_param_name(str(k), unit): _renamed_keys(v, unit) for k, v in value.items()}
    if isinstance(value, list):
        return [_renamed_keys(v, unit) for v in value]
    return value


def _document(d: Diagnosis) -> dict[str, Any]:
    data = d.data
    return {
        "recording": {
            "source": d.source,
            "rows": int(data.full_t.size),
            "sample_rate_hz": data.fs,
            "duration_s": round(data.duration_s, 3),
            "block_s": round(data.block_s, 6),
            "blocks": data.n,
            "white_noise_n_mg_rt_s": sig(data.white_n_mg_rt_s, 5),
        },
        "baseline": list(d.baseline.identifiers),
        "baseline_calibrated": effects(d.baseline_effects, d.before.noise),
        "baseline_final": effects(final_baseline(d), d.after.noise),
        "profile": d.profile.to_dict(),
        "criterion": {
            "name": CRITERION,
            "rms_note": RMS_NOTE,
            "add_threshold": THRESHOLD,
            "ambiguous_below": AMBIGUOUS,
            "suggestive_from": SUGGESTIVE,
            "max_added": MAX_ADDED,  # a suggestive entry at or above add_threshold: the search was full
        },
        "mismatch": [region(r) for r in d.mismatch],
        "left_out": [left_out(e) for e in d.left_out],
        "ambiguous": [ambiguity(a) for a in d.ambiguous],
        "not_identifiable": [
            {"effect": n.effect, "reason": n.reason, "recommended_test": n.recommended_test}
            for n in d.not_identifiable
        ],
        "not_supported": [
            {"effect": n.effect, "delta_bic": round(n.delta_bic, 2), "reason": n.reason}
            for n in d.not_supported
        ],
        "undetected": [undetected(u) for u in d.undetected],
        "suggestive": [
            {"effect": m.effect, "params": params(m.params), "delta_bic_when_added": round(m.delta_bic, 2)}
            | ({"flags": m.flags} if m.flags else {})
            | ({"joint_instances": m.joint} if m.joint > 1 else {})
            | (
                {
                    "shares_signature_with": [
                        {
                            "effect": x.effect,
                            "delta_bic_without": round(x.delta_bic, 2),
                            "in_place_delta_bic": round(x.in_place_bic, 2),
                        }
                        for x in m.shares
                    ]
                }
                if m.shares
                else {}
            )
            for m in d.suggestive
        ],
        "tested": [tested(t) for t in d.tested],
        "fit": {"before": fit_summary(d.before), "after": fit_summary(d.after)},
        "unexplained": [region(r) for r in d.unexplained],
        "holdout": None if d.holdout is None else holdout(d.holdout),
        "notes": d.notes + d.baseline.notes,
        "seconds": round(d.seconds, 2),
    }


def _json_safe(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        number = float(value)
        return number if math.isfinite(number) else None
    return value


def json_text(diagnosis: Diagnosis) -> str:
    return json.dumps(_json_safe(document(diagnosis)), indent=2) + "\n"
