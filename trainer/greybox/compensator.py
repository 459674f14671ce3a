"""``physics``: the grey-box compensator (registered in :mod:`trainer.methods`).

Drift model: the catalogue's bias polynomial in the proof-mass temperature plus the effects the
structure names (:mod:`.structure`), fitted jointly (:mod:`.fit`) and evaluated by the simulator's
own formula (:func:`trainer.physics.effects.drift`) on the thermometer reading, clipped to the
training range (outside it the compensator holds the range's edge, as a flight stack's cubic does).
:mod:`.stream` runs the same model sample by sample.

Offset safety: the offset policy (:mod:`trainer.reference`, ``--offset``) shifts the fitted
bias polynomial's constant so that the drift is relative to its settled value at the reference
temperature; the constant (which on a chamber run includes gravity on the vertical axis) is left to
the accelerometer's own offset calibration, as flight stacks do.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import replace
from pathlib import Path
from typing import Any, Self

import numpy as np

from trainer import payload as payload_fields
from trainer.compensator import Compensator
from trainer.data.channels import UNIT_LABELS
from trainer.data.recording import Recording
from trainer.errors import UserError
from trainer.greybox import structure as structures
from trainer.greybox.fit import FittedPhysics, fit_physics
from trainer.greybox.least_squares import fit_least_squares
from trainer.greybox.play_sum import fit_play_sum
from trainer.greybox.stream import PhysicsModel, play_start_within
from trainer.greybox.terms import parse_effects
from trainer.physics.catalogue import BACKBONE, EFFECTS
from trainer.physics.catalogue.streamed import instance_suffixes
from trainer.physics.catalogue.units import CATALOGUE_UNIT, catalogue_names, channel_params
from trainer.physics.effects import EffectConfig, check_instances, drift


class PhysicsCompensator(Compensator):
    """Catalogue physics fitted to the training run; a stateful function of the temperature history."""

    def __init__(
        self,
        *,
        effects: str = "auto",
        from_sim: str | None = None,
        with_warmup: bool = False,
        progress: bool = False,
        given_by: str = "--effects",  # who gave a forced structure (the summary says): auto's candidate
        play_start_c: float | None = None,  # the branch at power-on: that of a sensor brought from here
        least_squares: bool = False,  # every parameter by least squares (greybox.least_squares), not the finder
        width_sum: bool = False,  # the effect at several widths, amplitudes by bounded least squares (greybox.play_sum)
    ) -> None:
        structures.check_source(effects, from_sim)
        self.given_by = given_by
        self.effects_option = effects
        self.forced = None if effects == "auto" else parse_effects(effects)
        self.from_sim = from_sim
        self.with_warmup = with_warmup
        self.progress = progress
        self.play_start_c = play_start_c
        self.least_squares = least_squares
        self.width_sum = width_sum
        self.effects: tuple[EffectConfig, ...] = ()
        self.temp_range_c = (np.nan, np.nan)
        self.report: dict[str, Any] = {}

    # -- fitting ---------------------------------------------------------------------------------
    def _structure(self, rec: Recording) -> structures.Structure:
        if self.from_sim is not None:
            path = Path(self.from_sim)
            if not path.is_file():
                raise UserError(
                    f"--from-sim: {path}: no such file (trainer diagnose --report writes augmented.toml)"
                )
            return structures.from_sim(path, rec, warmup_allowed=self.with_warmup)
        if self.forced is not None:
            return structures.forced(self.forced, self.given_by)
        return structures.auto(rec, warmup_allowed=self.with_warmup, progress=self.progress)

    def fit(self, rec: Recording) -> Self:
        temp = np.asarray(rec.temp_c, dtype=np.float64)
        held = rec.held_out()  # a cross-validation fold: the rows it trains on set the valid range,
        if held is not None and not held.all():  # as --holdout's would
            temp = temp[~held]
        lo, hi = float(np.min(temp)), float(np.max(temp))
        if not hi > lo:
            raise UserError(f"physics: the training temperature does not vary (constant {lo} degC)")
        chosen = self._structure(rec)
        start = play_start_within(self.play_start_c, (lo, hi))
        if self.width_sum:
            fitted = fit_play_sum(rec, chosen, (lo, hi), start)
        elif self.least_squares:
            fitted = fit_least_squares(rec, chosen, (lo, hi), start)
        else:
            fitted = fit_physics(rec, chosen)
        if self.forced is None and self.from_sim is None:
            fitted = _only_determined(rec, fitted)
        self.effects = fitted.effects
        self.temp_range_c = (lo, hi)
        self.report = _report(chosen, fitted)
        if self.play_start_c is not None:
            self.report["notes"].append(
                f"power-on: the branch of a sensor brought to its first temperature from {self.play_start_c:g} degC "
                "(the play operator starts there, clamped into T0 +- width/2)"
            )
        return self

    @property
    def unit(self) -> str:
        """The unit suffix of the channel the model was fitted to (mg, dps, pa): its parameters' names."""
        return str(self.report.get("unit", CATALOGUE_UNIT))

    def describe(self) -> list[str]:
        return summary_lines(self.report) if self.report else []

    @classmethod
    def undetermined_in(cls, payload: dict[str, Any]) -> list[str]:
        """Raises TypeError for a report whose flags are not lists of parameter names (a malformed
        model file: the loaders turn it into one line naming the field)."""
        report = payload.get("report") or {}
        if not isinstance(report, dict):
            raise TypeError("'report' is not a table")
        for key in UNDETERMINED_KEYS:
            names = report.get(key, [])
            if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
                raise TypeError(f"'report.{key}' is not a list of parameter names")
        return undetermined_lines(report)

    # -- running ---------------------------------------------------------------------------------
    @property
    def model(self) -> PhysicsModel:
        return PhysicsModel.from_effects(self.effects, self.temp_range_c, self.play_start_c)

    def drift_at_reference(self, t_ref_c: float, rate_hz: float, training: Recording | None = None) -> float:
        """Exactly the settled drift (filters settled, mid-branch, warm-up over), no simulation."""
        del rate_hz, training
        return self.model.static_drift_mg(t_ref_c)

    def shift_drift(self, delta_mg: float) -> None:
        """Moves the bias polynomial's constant ``c0_mg`` (so the export carries the shift)."""
        self.effects = tuple(
            EffectConfig(e.identifier, {**e.params, "c0_mg": e.params["c0_mg"] + delta_mg})
            if e.identifier == BACKBONE
            else e
            for e in self.effects
        )

    def predict_drift(self, rec: Recording) -> np.ndarray:
        t = np.asarray(rec.time_s, dtype=np.float64)
        temp = np.clip(np.asarray(rec.temp_c, dtype=np.float64), *self.temp_range_c)
        return drift(self.effects, t - t[0], temp, play_start_c=self.model.play_start_c).total

    def out_of_range(self, temp_c: np.ndarray) -> np.ndarray:
        return (temp_c < self.temp_range_c[0]) | (temp_c > self.temp_range_c[1])

    # -- checkpoint ------------------------------------------------------------------------------
    def to_payload(self) -> dict[str, Any]:
        return {
            # parameters as the channel names them (amp_dps on a gyroscope: physics-catalogue.md,
            # "Other channels"), as everything else a user or another program reads does
            "effects": [
                [e.identifier, {k: float(v) for k, v in channel_params(e.params, self.unit).items()}]
                for e in self.effects
            ],
            "temp_range_c": [float(v) for v in self.temp_range_c],
            "with_warmup": bool(self.with_warmup),
            "effects_option": self.effects_option,
            "report": self.report,
            "play_start_c": self.play_start_c,
        }

    @classmethod
    def from_payload(cls, payload: dict[str, Any]) -> Self:
        model = cls(with_warmup=payload_fields.flag(payload, "with_warmup"))
        model.effects_option = str(payload["effects_option"])
        cls.undetermined_in(payload)  # its flags are what the sign-off reads: checked on loading
        model.report = dict(payload["report"])
        if model.unit not in UNIT_LABELS:
            raise ValueError(
                f"payload.report.unit: {model.unit!r} is not a channel unit ({', '.join(UNIT_LABELS)})"
            )
        model.effects = _effects_of(payload["effects"], model.unit)
        model.temp_range_c = payload_fields.temp_range(payload)
        start = payload.get("play_start_c")  # absent from checkpoints written before it existed: half-way
        model.play_start_c = None if start is None else payload_fields.number(start, "payload.play_start_c")
        return model


def _effects_of(raw: Any, unit: str) -> tuple[EffectConfig, ...]:
    """``payload.effects``: ``[identifier, {parameter: value}]`` pairs, each a catalogue effect with
    exactly its catalogue parameters as a channel of ``unit`` names them (a missing one would change
    the exported tables without a word, an unknown effect fail deep inside the drift formula), held
    under the catalogue's names. A file written before the channel's names were used holds the
    catalogue's (``amp_mg`` on a gyroscope) and reads as before."""
    if not isinstance(raw, list | tuple) or not raw:
        raise ValueError(f"payload.effects must be a list of [effect, parameters] pairs, got {raw!r}")
    effects = []
    for index, item in enumerate(raw):
        where = f"payload.effects[{index}]"
        if not (isinstance(item, list | tuple) and len(item) == 2 and isinstance(item[1], dict)):
            raise ValueError(f"{where} must be [effect, {{parameter: value}}], got {item!r}")
        identifier, params = item
        definition = EFFECTS.get(identifier) if isinstance(identifier, str) else None
        if definition is None:
            raise ValueError(f"{where}: {identifier!r} is not a catalogue effect")
        named = catalogue_names(definition.params, unit)  # {name on the channel: catalogue name}
        if sorted(params) == sorted(named.values()):
            named = {name: name for name in named.values()}
        elif sorted(params) != sorted(named):
            raise ValueError(
                f"{where} ({identifier}) has parameters {sorted(params)}; the catalogue's are {list(named)}"
            )
        # each value by the catalogue's rule (a width, a time constant > 0: a play of width 0 gives NaN)
        rules = {p.name: p.rule for p in definition.params}
        values = {
            named[k]: payload_fields.number(v, f"{where}.{k}", rules[named[k]]) for k, v in params.items()
        }
        effects.append(EffectConfig(identifier, values))
    try:
        check_instances(e.identifier for e in effects)
    except ValueError as error:
        raise ValueError(f"payload.effects: {error}") from None
    return tuple(effects)


def instance_labels(identifiers: list[str]) -> list[str]:
    """Each effect's name in the report: its identifier, a later instance's with its suffix (``_2``)."""
    return [k + suffix for k, suffix in zip(identifiers, instance_suffixes(identifiers), strict=True)]


def undetermined_terms(fitted: FittedPhysics, rejected: dict[str, str]) -> dict[str, str]:
    """``{effect: why}`` for compensated effects (not the bias polynomial) that the run does not
    determine: a parameter at the end of its search range or outside the plausible range (the
    finder's rule, on the values the compensator would carry), or one the finder itself fitted
    implausibly (its verdict is final: `trainer diagnose` on the same run says the same)."""
    out: dict[str, str] = {}
    for e in fitted.structure.compensated:
        own = "; ".join(fitted.why.get(e.identifier, ()))
        finder = rejected.get(e.identifier, "")
        if finder and finder != own:
            own += ("; " if own else "") + f"the finder's fit: {finder}"
        elif finder:
            own += " (the finder's fit too)"
        if own:
            out[e.identifier] = own
    return out


def _only_determined(rec: Recording, fitted: FittedPhysics) -> FittedPhysics:
    """An automatic structure keeps only what the run determines: an undetermined effect is dropped and
    the rest refitted (until none is left). Such a term extrapolates wildly wherever its state is not
    the training run's: a 1500 s lag at its bound gave -7 deg/s of "drift" from a cold start on the
    bundled run's gyro x, where the cubic left 0.16 deg/s. The first fit's structure and notes (what
    the cross-validated stage added, and why) stay in the summary."""
    rejected = dict(fitted.structure.rejected)
    first = fitted
    dropped: dict[str, str] = {}
    while drop := undetermined_terms(fitted, rejected):
        dropped |= drop
        final = fitted.structure
        kept = tuple(e for e in final.compensated if e.identifier not in drop)
        fitted = fit_physics(rec, replace(final, compensated=kept, candidates=()))
    if not dropped:
        return fitted
    return replace(
        fitted, structure=replace(fitted.structure, dropped=tuple(dropped.items())), notes=first.notes
    )


def _report(chosen: structures.Structure, fitted: FittedPhysics) -> dict[str, Any]:
    """Plain values for the checkpoint and the fit summary: structure, parameters, flags, notes, and
    each effect dropped with its reason."""
    final = fitted.structure
    dropped = dict(final.dropped)
    added = [e.identifier for e in final.compensated if e not in chosen.compensated] + [
        name for name in dropped if name not in {e.identifier for e in chosen.compensated}
    ]
    how = chosen.how + (f"; cross-validation added {', '.join(added)}" if added else "")
    unit = fitted.unit  # parameters as the channel names them (amp_dps on a gyroscope)
    report: dict[str, Any] = {} if unit == CATALOGUE_UNIT else {"unit": unit}
    labels = instance_labels([e.identifier for e in fitted.effects])
    return report | {
        "structure": how,
        "effects": [e.identifier for e in fitted.effects],
        # keyed by instance: an effect's second instance is <effect>_2 (as its C state words are)
        "params": {
            label: channel_params(e.params, unit) for label, e in zip(labels, fitted.effects, strict=True)
        },
        # an undetermined parameter's standard deviation is infinite: left out (the report shows none),
        # so that the model file holds finite numbers only, as every reader requires
        "std": {
            label: channel_params(
                {k: v for k, v in fitted.std.get(label, {}).items() if np.isfinite(v)}, unit
            )
            for label in labels
        },
        "nuisance": [e.identifier for e in fitted.nuisance],
        "at_bound": list(fitted.at_bound),
        "implausible": list(fitted.implausible),
        "notes": [*chosen.notes, *fitted.notes],
        "dropped": dropped,
    }


UNDETERMINED_KEYS = ("at_bound", "implausible")  # the report's flags of parameters the run does not determine


def undetermined_lines(report: dict[str, Any]) -> list[str]:
    """Each parameter the fit flagged: at the end of its search range, or outside the plausible range."""
    return [f"{name} sits at the end of its search range" for name in report.get("at_bound", [])] + [
        f"{name} is outside the catalogue's plausible range" for name in report.get("implausible", [])
    ]


def summary_lines(report: dict[str, Any]) -> list[str]:
    """The fit summary a user reads: structure, parameters with one standard deviation, warnings."""
    lines = [f"physics structure: {report['structure']}"]
    if "unit" in report:
        lines[0] += f" (parameters in {UNIT_LABELS[report['unit']]})"
    for effect in instance_labels(report["effects"]):
        params = report["params"][effect]
        std = report["std"].get(effect, {})
        text = ", ".join(
            f"{k} = {v:.6g}" + (f" +- {std[k]:.2g}" if k in std and np.isfinite(std[k]) else "")
            for k, v in params.items()
        )
        lines.append(f"  {effect}: {text}")
    if report["nuisance"]:
        lines.append(f"  fitted but not compensated (not sensor drift): {', '.join(report['nuisance'])}")
    lines += [f"  warning: {line}" for line in undetermined_lines(report)]
    lines += [f"  note: {n}" for n in report["notes"]]
    dropped = report.get("dropped", {})  # absent from checkpoints written before it was recorded
    lines += [f"  dropped {name}: {why}" for name, why in dropped.items()]
    counts = Counter(report["effects"])  # the last word: what the exported compensator carries
    kept = " + ".join(f"{n} x {e}" if n > 1 else e for e, n in counts.items())
    undetermined = list(dict.fromkeys(name for key in UNDETERMINED_KEYS for name in report.get(key, [])))
    # an automatic structure drops what the run does not determine (_only_determined); one the user
    # forced (--effects, --from-sim) keeps it, and the last word must not claim otherwise
    why = (
        f"kept as given, although this run does not determine {', '.join(undetermined)}: an automatic "
        f"structure would drop {'it' if len(undetermined) == 1 else 'them'}"
        if undetermined
        else "a compensator carries only physics this run determines"
    )
    lines.append(f"  compensates: {kept} ({why})")
    return lines
