"""Out-of-family units: robust z-scores on fitted parameters and scores, rare and missing effects.

A unit is out of family when one of its numbers lies more than :data:`Z_LIMIT` robust standard
deviations from the fleet's median (z = (x - median) / (1.4826 MAD), Iglewicz and Hoaglin's
modified z-score: a few bad units cannot hide themselves by inflating a standard deviation), or
when the finder names an effect in it that few units show, or misses one that nearly all show.

The numbers are every fitted parameter of the catalogue's deterministic effects (the calibrated
baseline as the final model fitted it beside the effects the finder named, and those effects) and the white-noise density, plus each method's drift
left. The other noise terms are left out: fitted to block means of a short run, their estimates
spread over orders of magnitude between identical units and would flag noise, not units.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.stats import median_abs_deviation

from trainer.fleet.result import UnitResult
from trainer.physics.catalogue import EFFECTS, WHITE_NOISE

Z_LIMIT = 5.0  # 24 normal units x 10 numbers stay below ~4; a planted defect scores far above
MIN_UNITS = 8  # fewer units than this: no fleet statistics
RARE_SHARE = 0.2  # an effect named in at most this share of the units is unusual where it is named
COMMON_SHARE = 0.8  # an effect named in at least this share is unusual where it is missing
SCORED_NOISE = (WHITE_NOISE,)


@dataclass(frozen=True)
class Finding:
    """Why a unit is out of family; ``z`` is None for a rare or missing effect."""

    unit: str
    feature: str
    reason: str
    value: float | None = None
    median: float | None = None
    z: float | None = None


DRIFT_PREFIX = "drift left "


def drift_feature(method: str, unit: str) -> str:
    """The feature name of a method's drift left, in the unit's channel unit (mg, deg/s, Pa)."""
    return f"{DRIFT_PREFIX}{method} ({unit})"


def unit_label(result: UnitResult) -> str:
    """The unit a unit's figures are in (``result.json`` ``unit``; results written before it: mg)."""
    return result.unit or "mg"


def _params(features: dict[str, float], effect: str, params: Any, seen: Counter[str]) -> None:
    instances = params if isinstance(params, list) else [params]
    for values in instances:
        seen[effect] += 1
        label = effect if seen[effect] == 1 else f"{effect}#{seen[effect]}"
        for name, value in values.items():
            if isinstance(value, int | float) and np.isfinite(value):
                features[f"{label}.{name}"] = float(value)


def unit_features(result: UnitResult) -> dict[str, float]:
    """The numbers of one finished unit that the fleet compares (see the module docstring)."""
    features: dict[str, float] = {}
    diagnosis = result.diagnosis or {}
    seen: Counter[str] = Counter()
    # the final model's baseline: calibrated alone it absorbs what the finder names (a bias step bent
    # the polynomial of its unit into "c1 17 robust SD above the fleet"); a summary cached before it: as calibrated
    baseline = diagnosis.get("baseline_final", diagnosis.get("baseline_calibrated")) or {}
    for effect, params in baseline.items():
        if effect in EFFECTS or effect in SCORED_NOISE:
            _params(features, effect, params, seen)
    for entry in diagnosis.get("left_out", []):
        if entry["effect"] in EFFECTS or entry["effect"] in SCORED_NOISE:
            _params(features, entry["effect"], entry["params"], seen)
    for method, summary in result.methods.items():
        drift = summary.get("drift_left_mg")
        if isinstance(drift, int | float) and np.isfinite(drift):
            features[drift_feature(method, unit_label(result))] = float(drift)
    return features


def named_effects(result: UnitResult) -> list[str]:
    """The effects the finder named in a unit (each once)."""
    diagnosis = result.diagnosis or {}
    return sorted({entry["effect"] for entry in diagnosis.get("left_out", [])})


def robust_z(values: np.ndarray) -> tuple[np.ndarray, float, float]:
    """``(z, median, scale)``; z is all-zero when the scale is 0 (identical values say nothing)."""
    median = float(np.median(values))
    scale = float(median_abs_deviation(values, scale="normal"))
    if not scale > 0:
        return np.zeros_like(values), median, scale
    return (values - median) / scale, median, scale


def find_out_of_family(results: dict[str, UnitResult]) -> list[Finding]:
    """Every reason each ``ok`` unit is out of family, in unit then feature order."""
    ok = {uid: r for uid, r in results.items() if r.ok}
    if len(ok) < MIN_UNITS:
        return []
    features = {uid: unit_features(r) for uid, r in ok.items()}
    findings: list[Finding] = []
    names = sorted({name for f in features.values() for name in f})
    for name in names:
        holders = [uid for uid in ok if name in features[uid]]
        if len(holders) < MIN_UNITS:
            continue  # a rare effect's parameters: the effect itself is the finding
        values = np.array([features[uid][name] for uid in holders])
        z, median, _ = robust_z(values)
        for uid, value, score in zip(holders, values, z, strict=True):
            if abs(score) > Z_LIMIT:
                side = "above" if score > 0 else "below"
                reason = (
                    f"{name} = {value:.4g}, {abs(score):.1f} robust SD {side} the fleet median {median:.4g}"
                )
                findings.append(Finding(uid, name, reason, float(value), median, float(score)))
    named = {uid: named_effects(r) for uid, r in ok.items()}
    counts = Counter(effect for effects in named.values() for effect in effects)
    n = len(ok)
    for effect, count in sorted(counts.items()):
        if count <= RARE_SHARE * n:
            for uid in ok:
                if effect in named[uid]:
                    findings.append(
                        Finding(uid, effect, f"the finder names {effect}, as in only {count} of {n} units")
                    )
        elif count >= COMMON_SHARE * n and count < n:
            for uid in ok:
                if effect not in named[uid]:
                    findings.append(
                        Finding(
                            uid, effect, f"the finder does not name {effect}, which {count} of {n} units show"
                        )
                    )
    order = list(results)
    return sorted(findings, key=lambda f: (order.index(f.unit), f.feature))
