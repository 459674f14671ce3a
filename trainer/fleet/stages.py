"""One unit's work as Dask tasks: load, diagnose, one task per method, assemble.

``load`` (import and validate) feeds ``diagnose`` and every ``method`` task (fit, score, export
the C module, verify it bit for bit); ``assemble`` gathers them into the unit's files and its
``result.json``. A method is scored exactly as ``trainer report`` scores the same model on the same
recording and hold-out (:mod:`trainer.scoring.unit_scores`): the fleet's drift left of a unit is
the sign-off report's. The tasks return plain data and write nothing under OUTDIR: the client writes a
finished unit atomically (:mod:`.cache`), so workers only need to see the recordings.

No task raises for a unit's own problem: a bad file, a failed fit or a failed export becomes a
:class:`Failure` carrying the one-line error, the unit's result records it, and the fleet goes on.
A failure that is not the unit's (a bug, a lost worker, or the environment: a full disk, a file
too large, a denied or read-only write, :func:`environment_failure`) is recorded the same way but
marked ``retry``, and a restarted run computes that unit again.
"""

from __future__ import annotations

import errno
import json
import math
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from trainer.data.channels import signal_of
from trainer.data.holdout import Holdout, parse_holdout
from trainer.data.recording import Recording
from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
from trainer.errors import UserError
from trainer.fleet.cluster import pinned
from trainer.fleet.manifest import FleetSettings, UnitSpec
from trainer.fleet.options import UnitImport
from trainer.fleet.result import FAILED, OK, RESULT_FILE, Failure, UnitResult, finite, json_bytes
from trainer.train_stats import TrainStats

T = TypeVar("T")
SMOOTHING_S = PAPER_RUN_SMOOTHING_S  # the scoring smoothing, `trainer report --smoothing`'s default
TIMING_FILE = "timing.json"  # wall times: the one file of a unit that differs between identical runs


# OSError numbers of a failure of the machine rather than of the unit: a full disk or quota, a file
# over the size limit, a denied or read-only write. They pass when the environment is fixed.
ENVIRONMENT_ERRNOS = frozenset(
    {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EACCES, errno.EPERM, errno.EROFS}
)


@dataclass(frozen=True)
class UnitData:
    """A unit's recordings, validated: fit and diagnose on ``train``; score the model's output over
    ``scored`` (a second run, or the one run with its ``holdout`` part held out, as ``trainer report
    --recording scored --holdout``)."""

    train: Recording
    scored: Recording
    holdout: Holdout | None
    evaluated_on: str
    seconds: float
    notes: tuple[str, ...] = ()  # what the import said (corrections undone, implausible values accepted)

    def valid_rows(self) -> tuple[Recording, slice]:
        """The samples the figures are of (the held-out part, or the whole second run), and their rows
        in ``scored``."""
        if self.holdout is None:
            return self.scored, slice(0, len(self.scored))
        from trainer.scoring.unit_scores import held_out_rows

        return held_out_rows(self.scored, self.holdout)

    @property
    def valid(self) -> Recording:
        return self.valid_rows()[0]


@dataclass(frozen=True)
class StageOutput:
    """Files (path relative to the unit's directory -> bytes) and the summary for ``result.json``."""

    files: dict[str, bytes]
    summary: dict[str, Any]
    seconds: float
    failures: tuple[Failure, ...] = ()  # retryable failures of a part of the stage (an export)


@dataclass(frozen=True)
class UnitOutcome:
    """Everything the client writes for one unit."""

    unit_id: str
    files: dict[str, bytes] = field(repr=False)
    result: UnitResult


def environment_failure(exc: BaseException) -> bool:
    """Whether ``exc``, or an exception it was raised from or while handling (a one-line UserError
    keeps its OSError as context), is an OSError of :data:`ENVIRONMENT_ERRNOS`."""
    seen: set[int] = set()
    current: BaseException | None = exc
    while current is not None and id(current) not in seen:
        seen.add(id(current))
        if isinstance(current, OSError) and current.errno in ENVIRONMENT_ERRNOS:
            return True
        current = current.__cause__ or current.__context__
    return False


def one_line(exc: BaseException) -> tuple[str, bool]:
    """``(message, retry)``: a UserError's own line, anything else prefixed with its type; ``retry``
    unless the unit itself is at fault (a UserError not caused by the environment)."""
    if isinstance(exc, UserError):
        return " ".join(str(exc).split()), environment_failure(exc)
    if environment_failure(exc):
        return " ".join(f"environment: {exc}".split()), True
    return " ".join(f"internal error: {type(exc).__name__}: {exc}".split()), True


def _guarded(stage: str, work: Callable[[], T]) -> T | Failure:
    try:
        return work()
    except Exception as exc:  # one unit's failure must not stop the fleet
        message, retry = one_line(exc)
        return Failure(stage, message, retry)


# ------------------------------------------------------------------------------------- load


def _importer(unit: UnitSpec) -> UnitImport:
    return unit.importer or UnitImport.parse(unit.import_text, f"unit {unit.id}: import")


def _read(path: Path, unit: UnitSpec) -> tuple[Recording, list[str]]:
    return _importer(unit).read(path)


def _training_checks(train: Recording, unit: UnitSpec) -> list[str]:
    """``trainer fit``'s checks of the training part for every method of the unit (rate, ranges,
    gravity, temperature span): a run too short in temperature for one of them fails the unit in
    that command's line, before anything is diagnosed or fitted (the diagnosis fits the cubic's
    backbone, whose coefficients a flat run leaves free). Warnings when the unit accepts them."""
    from trainer import methods
    from trainer.data.plausibility import check_training

    accept = _importer(unit).accepts_implausible
    warnings: list[str] = []
    for name in dict.fromkeys((methods.CUBIC, *unit.methods)):
        warnings += check_training(train, methods.get(name), accept=accept).warnings
    return list(dict.fromkeys(warnings))


@pinned
def load(unit: UnitSpec, settings: FleetSettings) -> UnitData | Failure:
    """Import (or read) and validate the unit's recordings; split off the scoring part."""

    def work() -> UnitData:
        started = time.perf_counter()
        from trainer.data.holdout import split

        read = [_read(path, unit) for path in unit.recordings]
        recordings = [rec for rec, _ in read]
        notes = tuple(
            f"{path.name}: {note}"
            for path, (_, said) in zip(unit.recordings, read, strict=True)
            for note in said
        )
        if len(recordings) == 2:
            train, second = recordings
            first, other = signal_of(train), signal_of(second)
            if other != first:
                raise UserError(
                    f"{unit.recordings[1]}: channel {other.heading}, but the unit's first run "
                    f"{unit.recordings[0].name} is {first.heading}: both runs must be of one channel"
                )
            notes += tuple(f"{unit.recordings[0].name}: {w}" for w in _training_checks(train, unit))
            where = f"second run {unit.recordings[1].name}"
            return UnitData(train, second, None, where, time.perf_counter() - started, notes)
        holdout = parse_holdout(settings.holdout)
        train, _ = split(recordings[0], holdout)
        notes += tuple(f"{unit.recordings[0].name}: {w}" for w in _training_checks(train, unit))
        where = f"{unit.recordings[0].name}, {holdout.describe()} (--holdout {settings.holdout})"
        return UnitData(train, recordings[0], holdout, where, time.perf_counter() - started, notes)

    return _guarded("load", work)


# --------------------------------------------------------------------------------- diagnose


def _diagnosis_summary(doc: dict[str, Any]) -> dict[str, Any]:
    """What the fleet report reads: the baseline as the final model fitted it beside the effects named
    (and as calibrated alone), the effects named, the fit (its block
    RMS under the channel's own name, ``rms_block_dps`` on a gyroscope: the diagnosis' naming)."""
    from trainer.physics.catalogue.units import CATALOGUE_UNIT, channel_param_name

    rms_key = channel_param_name("rms_block_mg", (doc.get("channel") or {}).get("unit", CATALOGUE_UNIT))
    return {
        "baseline_calibrated": doc["baseline_calibrated"],
        "baseline_final": doc["baseline_final"],
        "left_out": [
            {"effect": e["effect"], "params": e["params"], "flags": e.get("flags", [])}
            for e in doc["left_out"]
        ],
        "ambiguous": [a["effects"] for a in doc["ambiguous"]],
        rms_key: {"before": doc["fit"]["before"][rms_key], "after": doc["fit"]["after"][rms_key]},
    }


@pinned
def diagnose(
    data: UnitData | Failure, settings: FleetSettings, sim_text: str | None
) -> StageOutput | Failure:
    """``trainer diagnose`` on the fitted recording; ``diagnosis.json`` without its wall time."""
    if isinstance(data, Failure):
        return data

    def work() -> StageOutput:
        from trainer.diagnose import diagnose as find
        from trainer.diagnose.blocks import DEFAULT_MAX_BLOCKS
        from trainer.diagnose.document import json_text
        from trainer.physics.config import parse_config_text

        started = time.perf_counter()
        sim = None if sim_text is None else parse_config_text(sim_text, str(settings.sim))
        result = find(
            data.train,
            sim,
            holdout_fraction=settings.diagnose_holdout,
            max_blocks=settings.diagnose_blocks or DEFAULT_MAX_BLOCKS,
        )
        doc = json.loads(json_text(result))
        doc.pop("seconds", None)  # the one non-deterministic field; timing.json has it
        return StageOutput(
            {"diagnosis.json": json_bytes(doc)}, _diagnosis_summary(doc), time.perf_counter() - started
        )

    return _guarded("diagnose", work)


# ----------------------------------------------------------------------------------- method


def _rms(left: Any) -> float:
    return math.nan if left is None else float(left.rms_mg)


DRIFT_LEFT_KEYS = (  # the figures the verdict takes (trainer.scoring.verdict.Figures), in its order
    "drift_left_mg",
    "drift_left_uncompensated_mg",
    "drift_left_in_range_mg",
    "drift_left_uncompensated_in_range_mg",
    "noise_floor_mg",
)


COVERAGE_KEYS = ("trained_range_c", "scored_range_c", "coverage")  # result.json: the scored part's coverage


def drift_left_summary(scores: Any) -> dict[str, float]:
    """What ``result.json`` keeps of a method's :class:`~trainer.scoring.unit_scores.UnitScores`:
    the headline part's drift left RMS (mg), the model's and the uncompensated output's, whole and
    in the trained range, and the noise floor."""
    part = scores.headline
    values = (part.model, part.uncompensated, part.model_in_range, part.uncompensated_in_range)
    return dict(zip(DRIFT_LEFT_KEYS, [*map(_rms, values), float(part.noise_floor_mg)], strict=True))


def _scores(method: str, data: UnitData, model: Any, stats: TrainStats) -> dict[str, Any]:
    from trainer.scoring.evaluate import drift_score, evaluate, truth_reference_c
    from trainer.scoring.unit_scores import coverage, score_unit

    trained = stats.temp_range_c
    whole_run = model.compensate(data.scored.without_truth())
    scores = score_unit(data.scored, whole_run, SMOOTHING_S, trained, data.holdout)
    valid, rows = data.valid_rows()
    compensated = whole_run[rows]
    outside = (valid.temp_c < trained[0]) | (valid.temp_c > trained[1])
    reference = truth_reference_c(model)  # as trainer evaluate scores it: one figure under one name
    references = {} if reference is None else {method: reference}
    table = evaluate(
        valid, {method: compensated}, out_of_range={method: outside}, references=references
    ).table
    truth = drift_score(valid, compensated, reference)
    left = scores.headline.model
    coefficients = table.compensated[method]
    scored = (float(np.min(valid.temp_c)), float(np.max(valid.temp_c)))
    return {
        "method": method,
        "evaluated_on": data.evaluated_on,
        "samples": len(valid),
        # how far the scored part lies inside the trained range (trainer report's coverage)
        "trained_range_c": list(trained),
        "scored_range_c": list(scored),
        "coverage": coverage(scored, trained),
        **drift_left_summary(scores),
        "drift_left_max_mg": left.max_abs_mg,
        "drift_left_heating_mg": left.heating_rms_mg,
        "drift_left_cooling_mg": left.cooling_rms_mg,
        "smoothing_s": SMOOTHING_S,
        # simulated data only: the residual against the simulator's ground truth (trainer evaluate's headline)
        "residual_vs_truth_mg": None if truth is None else truth.residual_rms_mg,
        "fit_residual_rms_mg": stats.fit_residual_rms_mg,
        "out_of_range_fraction": float(np.mean(outside)),
        "allan": {
            "B_mg": coefficients.b_mg,
            "K_mg_per_rt_s": coefficients.k_mg_per_rt_s,
            "R_mg_per_s": coefficients.r_mg_per_s,
            "improvement_pct": dict(table.improvement_pct[method]),
            "average_improvement_pct": table.average_improvement_pct[method],
        },
    }


def _export_and_verify(
    model_path: Path, valid: Recording, name: str, tmp: Path
) -> tuple[dict[str, bytes], dict[str, Any]]:
    """``codegen export`` + ``codegen verify`` on the scoring recording (0 mismatches to pass)."""
    from codegen.export import export
    from codegen.verify import json_document, verify
    from trainer.data.recording_io import write_recording

    c_dir = tmp / "c"
    _, files = export(model_path, c_dir, name=name)
    write_recording(valid, tmp / "verify.npz")
    result = verify(model_path, c_dir, tmp / "verify.npz", name=name, table1=False)
    passed = result.mismatches == 0 and result.state_equal
    report = {  # codegen verify --json's document: trainer report --verify reads it
        **json_document(result, c_dir),
        "passed": passed,
        "error_budget_rms_mg": result.budget.rms_mg,
        "error_budget_max_abs_mg": result.budget.max_abs_mg,
    }
    return {f"c/{file_name}": (c_dir / file_name).read_bytes() for file_name in sorted(files)}, report


@pinned
def method(data: UnitData | Failure, unit: UnitSpec, name: str) -> StageOutput | Failure:
    """Fit ``name``, score it on the scoring recording, export and verify its C module."""
    if isinstance(data, Failure):
        return data

    def work() -> StageOutput:
        from trainer import methods
        from trainer.checkpoint import save_model
        from trainer.fitting import fit_with_stats
        from trainer.scoring.fit_holdout import record_of
        from trainer.scoring.verdict import Figures, worse_than_uncompensated

        started = time.perf_counter()
        model, stats = fit_with_stats(name, data.train, unit.fit_kwargs.get(name, {}))
        scores = _scores(name, data, model, stats)
        figures = [scores[key] for key in DRIFT_LEFT_KEYS]
        if data.holdout is not None:  # as trainer fit --holdout: the model file keeps its held-out figures
            stats = replace(stats, held_out=record_of(data.holdout, figures))
        # the sign-off's guard on the scored part: a compensator worse than none there is not exported
        guard = worse_than_uncompensated(name, Figures(data.evaluated_on, *figures))
        files: dict[str, bytes] = {}
        failures: tuple[Failure, ...] = ()
        with tempfile.TemporaryDirectory(prefix="fleet-") as tmp_name:
            tmp = Path(tmp_name)
            save_model(
                model,
                tmp / "model.pt",
                train_stats=stats,
                valid_temp_range_c=stats.temp_range_c,
            )
            files["model.pt"] = (tmp / "model.pt").read_bytes()
            if methods.get(name).renderer is None:
                verified: dict[str, Any] = {"passed": None, "error": f"{name} has no code generator"}
            elif not guard.ok:
                verified = {
                    "passed": None,
                    "error": f"not exported: {guard.detail}: a compensator worse than none must not reach firmware",
                }
            else:
                outcome = _guarded(
                    "export", lambda: _export_and_verify(tmp / "model.pt", data.valid, unit.export_name, tmp)
                )
                if isinstance(outcome, Failure):
                    verified = {"passed": False, "error": outcome.error}
                    if outcome.retry:  # not the model's fault: the unit is computed again next run
                        failures = (Failure(f"export {name}", outcome.error, True),)
                else:
                    c_files, verified = outcome
                    files.update(c_files)
        files["scores.json"] = json_bytes(finite(scores))
        files["verify.json"] = json_bytes(finite(verified))
        summary = {
            **{k: scores[k] for k in (*DRIFT_LEFT_KEYS, *COVERAGE_KEYS, "residual_vs_truth_mg")},
            "verify": verified,
            # parameters the unit's run does not determine: the verdict asks for a review, as trainer report's
            **({"undetermined": undetermined} if (undetermined := model.undetermined()) else {}),
        }
        return StageOutput(
            {f"{name}/{k}": v for k, v in files.items()}, summary, time.perf_counter() - started, failures
        )

    return _guarded(f"method {name}", work)


# --------------------------------------------------------------------------------- assemble


@pinned
def assemble(
    unit: UnitSpec,
    key: str,
    data: UnitData | Failure,
    diagnosis: StageOutput | Failure,
    *outputs: StageOutput | Failure,
) -> UnitOutcome:
    """The unit's files and ``result.json`` (status, errors, per-method summary, diagnosis summary)."""
    files: dict[str, bytes] = {}
    errors: list[Failure] = []
    timing: dict[str, float] = {}
    if isinstance(data, Failure):
        errors.append(data)
    else:
        timing["load"] = data.seconds
    if isinstance(diagnosis, StageOutput):
        files.update(diagnosis.files)
        timing["diagnose"] = diagnosis.seconds
    elif diagnosis != data:  # the load's failure, passed on (a copy when Dask moved it)
        errors.append(diagnosis)
    method_results: dict[str, Any] = {}
    for name, output in zip(unit.methods, outputs, strict=True):
        if isinstance(output, StageOutput):
            files.update(output.files)
            method_results[name] = output.summary
            timing[name] = output.seconds
            errors.extend(output.failures)
        else:
            method_results[name] = {"error": output.error}
            if output != data:
                errors.append(output)
    loaded = None if isinstance(data, Failure) else data
    result = UnitResult(
        id=unit.id,
        key=key,
        status=FAILED if errors else OK,
        retry=any(e.retry for e in errors),
        errors=tuple(errors),
        recordings=tuple(str(p) for p in unit.recordings),
        evaluated_on=None if loaded is None else loaded.evaluated_on,
        export_name=unit.export_name,
        methods=method_results,
        diagnosis=diagnosis.summary if isinstance(diagnosis, StageOutput) else None,
        channel=None if loaded is None else signal_of(loaded.train).channel,
        unit=None if loaded is None else signal_of(loaded.train).label,
        import_notes=() if loaded is None else tuple(loaded.notes),
    )
    files[TIMING_FILE] = json_bytes({k: round(v, 3) for k, v in timing.items()})
    files[RESULT_FILE] = result.to_json()
    return UnitOutcome(unit.id, files, result)
