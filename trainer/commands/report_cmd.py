"""``trainer report MODEL... --recording REC -o DIR``: the sign-off report of one unit (docs/signoff.md)."""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import shutil
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
from trainer.errors import UserError, raise_write_error
from trainer.options.numbers import MAX_SECONDS, check_finite
from trainer.train_stats import TrainStats

if TYPE_CHECKING:
    from trainer.data.recording import Recording

EXIT_FAILED = 1  # the unit fails a threshold (bad input stays 2, run_cli)
ANY_RANGE_C = (-math.inf, math.inf)  # scores that need no in-range part
# options that may be given once for every model: one recording of the unit; one IMU module (or its
# verify JSON) holding every model's channel (a one-channel module refuses the other models in one line)
ONCE_FOR_ALL = ("--recording", "--verify")

# Heavy modules (torch, matplotlib, cffi) are imported inside run() so that 'trainer --help' starts fast.


def add_parser(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "report",
        help="sign-off report of one unit: per channel drift and fit, drift left by branch and on held-out "
        "data, coverage, model id, codegen verify, flash/RAM/instructions, pass/fail",
    )
    parser.add_argument("models", nargs="+", help="one model.pt per channel of the unit")
    parser.add_argument(
        "--recording",
        action="append",
        required=True,
        metavar="REC",
        help="the unit's recording: once for every model, or repeated once per model in the same order",
    )
    parser.add_argument("-o", "--out-dir", required=True, help="report.md and its PNGs go here")
    parser.add_argument("--unit", help="the unit's name in the title (default: the first recording's stem)")
    parser.add_argument(
        "--config", metavar="TOML", help="pass/fail thresholds, table [thresholds] (keys: docs/signoff.md)"
    )
    parser.add_argument(
        "--holdout",
        metavar="SPEC",
        help="also score the held-out part of each recording (as 'trainer compare --holdout': F, first:F, "
        "T0:, :T1); the models should have been trained on the rest",
    )
    parser.add_argument(
        "--verify",
        action="append",
        metavar="DIR|JSON",
        help="repeated once per model, in order: a directory written by 'codegen export' (verified now on "
        "the recording) or the JSON of 'codegen verify --json'; an IMU module (or its JSON) once for all models",
    )
    parser.add_argument(
        "--bench",
        metavar="JSON",
        help="Cortex-M4 measurements: model_id, instructions_per_sample, flash_bytes, ram_bytes (docs/signoff.md)",
    )
    parser.add_argument(
        "--smoothing", type=float, default=PAPER_RUN_SMOOTHING_S, help="scoring smoothing in s (0.5)"
    )
    parser.set_defaults(func=run)


def _per_model(values: list[str] | None, models: list[str], option: str) -> list[str | None]:
    if values is None:
        return [None] * len(models)
    if len(values) == 1 and len(models) > 1 and option in ONCE_FOR_ALL:
        return [values[0]] * len(models)
    if len(values) != len(models):
        raise UserError(f"{option}: {len(values)} given for {len(models)} models; give one per model")
    return list(values)


def _read_json(path: Path, what: str) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise UserError(f"{path}: cannot read the {what} ({exc.strerror})") from None
    except ValueError as exc:
        raise UserError(f"{path}: not valid JSON ({exc})") from None


def _field(data: Any, key: str, kind: type | tuple[type, ...], path: Path) -> Any:
    value = data.get(key) if isinstance(data, dict) else None
    if not isinstance(value, kind) or (isinstance(value, bool) and kind is not bool):
        raise UserError(f"{path}: field {key!r} is missing or not a {getattr(kind, '__name__', 'number')}")
    return value


def _model_id(path: Path) -> str:
    return f"sha256:{hashlib.sha256(path.read_bytes()).hexdigest()}"


def _imu_result(out_dir: Path, recording: str, whole: Any, model: Path, runs: dict[Any, Any]) -> Any:
    """``codegen verify --channels`` of the IMU module in ``out_dir`` on the whole recording, run once
    per (module, recording) of this report (``runs``); the module's channel models are found beside
    ``model`` (the 'trainer fit --channels' directory); the report then checks the model's sha256."""
    from codegen.imu_verify import imu_manifest, verify_imu

    key = (out_dir.resolve(), recording)
    if key not in runs:
        found = imu_manifest(out_dir, None)
        assert found is not None
        name, manifest = found
        models = []
        for channel in manifest.get("channels", []):
            entry = channel.get("model") if isinstance(channel, dict) else None
            entry = entry if isinstance(entry, dict) else {}
            file = entry.get("file")
            candidate = model.parent / str(file)
            if not isinstance(file, str) or not candidate.is_file():
                raise UserError(
                    f"--verify {out_dir}: the IMU module's channel {channel.get('name')!r} was exported from "
                    f"{file!r}, not found beside {model}: give the models of the 'trainer fit --channels' "
                    "directory the module was exported from"
                )
            if _model_id(candidate) != f"sha256:{entry.get('sha256')}":
                raise UserError(
                    f"--verify {out_dir}: the IMU module's channel {channel.get('name')!r} was exported from "
                    f"another model than {candidate} (sha256 differs): export the module again, or give "
                    "the models it was exported from"
                )
            models.append(candidate)
        runs[key] = verify_imu(models, out_dir, whole, name=name)
    return runs[key]


def _imu_summary(result: Any, model: Path, source: str) -> Any:
    """The VerifySummary of ``model``'s channel in an IMU module's verify result."""
    from trainer.scoring.signoff import VerifySummary

    model_id = _model_id(model)
    if model_id not in result.model_ids:
        raise UserError(
            f"--verify {source}: the IMU module holds no channel exported from {model} ({model_id[:23]}...); "
            f"its channels: {', '.join(result.channels)}"
        )
    k = result.model_ids.index(model_id)
    return VerifySummary(
        result.channel_mismatches(k),
        result.samples,
        all(run.state_equal for run in result.runs),
        model_id,
        source,
        result.rate_millihz,
    )


def _imu_json_summary(data: dict[str, Any], model: Path, path: Path) -> Any:
    """The VerifySummary of ``model``'s channel from ``codegen verify --channels --json``."""
    from trainer.scoring.signoff import VerifySummary

    model_id = _model_id(model)
    channels = data.get("channels")
    if not isinstance(channels, list):
        raise UserError(f"{path}: field 'channels' is missing or not a list")
    entry = next((c for c in channels if isinstance(c, dict) and c.get("model_id") == model_id), None)
    if entry is None:
        raise UserError(f"{path}: no channel of model {model} ({model_id[:23]}...) in this IMU verify result")
    return VerifySummary(
        int(_field(entry, "mismatches", int, path)),
        int(_field(data, "samples", int, path)),
        bool(_field(data, "state_equal", bool, path)),
        model_id,
        str(path),
        int(data.get("rate_millihz") or 0),
    )


def _verify(
    model: Path,
    target: str,
    recording: str,
    rec: Any,
    whole: Any,
    smoothing_s: float,
    imu_runs: dict[Any, Any],
) -> tuple[Any, dict[str, Any] | None]:
    """(VerifySummary, manifest sizes or None) from a module directory (run now) or a JSON; an IMU
    module (docs/imu-module.md) or its JSON gives the model's channel. A spread module run now is also
    scored under both schedules on the recording (when it was not resampled)."""
    from codegen.imu_verify import IMU_VERIFY_FORMAT, imu_manifest
    from codegen.verify import find_manifest, schedule_parts, verify
    from trainer.scoring.signoff import VerifySummary
    from trainer.scoring.unit_scores import score_part

    path = Path(target)
    if path.is_dir() and imu_manifest(path, None) is not None:
        return _imu_summary(_imu_result(path, recording, whole, model, imu_runs), model, str(path)), None
    if path.is_dir():
        result = verify(model, path, recording, table1=False, resample=True)
        _, manifest = find_manifest(path, result.name)
        sc = result.schedule
        scores: tuple[tuple[str, Any], ...] = ()
        if sc is not None and result.resampled_from_hz is None:
            # each schedule over the samples holding the same run of estimates (schedule_parts)
            parts = schedule_parts(len(rec), sc.latency_samples)
            scores = tuple(
                (k, score_part(rec.slice(part.start, part.stop), v[part], smoothing_s, ANY_RANGE_C).model)
                for (k, v), part in zip(sc.output_mg.items(), parts, strict=True)
            )
        summary = VerifySummary(
            result.mismatches,
            result.samples,
            result.state_equal,
            _model_id(model),
            str(path),
            result.rate_millihz,
            result.resampled_from_hz,
            *(() if sc is None else (sc.name, sc.latency_samples, sc.delayed_equal, scores)),
        )
        return summary, manifest.get("sizes")
    data = _read_json(path, "verify result")
    if isinstance(data, dict) and data.get("format") == IMU_VERIFY_FORMAT:
        return _imu_json_summary(data, model, path), None
    summary = VerifySummary(
        int(_field(data, "mismatches", int, path)),
        int(_field(data, "samples", int, path)),
        bool(_field(data, "state_equal", bool, path)),
        str(_field(data, "model_id", str, path)),
        str(path),
        int(data.get("rate_millihz") or 0),
        data.get("resampled_from_hz") if isinstance(data.get("resampled_from_hz"), int | float) else None,
    )
    schedule = data.get("schedule")
    if schedule is not None:  # a spread module's: every field checked like the others
        summary = dataclasses.replace(
            summary,
            schedule=str(_field(schedule, "name", str, path)),
            latency_samples=int(_field(schedule, "latency_samples", int, path)),
            delayed_equal=bool(_field(schedule, "delayed_equal", bool, path)),
        )
    sizes = data.get("sizes")
    return summary, sizes if isinstance(sizes, dict) else None


def _bench_entry(bench: Any, model_id: str, path: Path) -> dict[str, Any] | None:
    entries = bench.get("modules", [bench]) if isinstance(bench, dict) else None
    if not isinstance(entries, list):
        raise UserError(f'{path}: expected an object or {{"modules": [...]}}')
    for entry in entries:
        if isinstance(entry, dict) and entry.get("model_id") == model_id:
            return entry
    return None


def _cost(sizes: dict[str, Any] | None, bench: dict[str, Any] | None, bench_path: Path | None) -> Any:
    from trainer.scoring.signoff import TABLES_ONLY, Cost

    def number(entry: dict[str, Any] | None, key: str, source: str) -> tuple[float, str] | None:
        if entry is None or key not in entry:
            return None
        value = entry[key]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise UserError(f"{source}: field {key!r} must be a number")
        return float(value), source

    bench_src = f"bench {bench_path}" if bench_path else ""
    manifest_src = "manifest"
    return Cost(
        number(bench, "flash_bytes", bench_src)
        or _labelled(number(sizes, "flash_table_bytes", manifest_src), TABLES_ONLY),
        number(bench, "ram_bytes", bench_src)
        or _labelled(number(sizes, "ram_state_bytes", manifest_src), "manifest: one state struct"),
        number(bench, "instructions_per_sample", bench_src),
    )


def _labelled(item: tuple[float, str] | None, label: str) -> tuple[float, str] | None:
    return None if item is None else (item[0], label)


def run(args: argparse.Namespace) -> int:
    from trainer import __version__
    from trainer.checkpoint import cross_validated_selection, load_model
    from trainer.commands.compare_cmd import publish
    from trainer.data.channels import UNIT_LABELS, channel_unit, model_view
    from trainer.data.holdout import overlap_warning, parse_holdout, training_row_share
    from trainer.data.plausibility import check_scored
    from trainer.data.recording import data_fingerprint
    from trainer.data.recording_io import read_recording
    from trainer.report_dir import check_report_dir
    from trainer.scoring import signoff
    from trainer.scoring.rate_coverage import rate_note
    from trainer.scoring.thresholds import load_thresholds
    from trainer.scoring.unit_scores import held_out_rows, score_unit
    from trainer.selection import shown_name

    check_finite("--smoothing", args.smoothing, maximum=MAX_SECONDS)
    thresholds = load_thresholds(args.config) if args.config else {}
    holdout = parse_holdout(args.holdout) if args.holdout else None
    recordings = _per_model(args.recording, args.models, "--recording")
    verifies = _per_model(args.verify, args.models, "--verify")
    bench_path = Path(args.bench) if args.bench else None
    bench = _read_json(bench_path, "bench result") if bench_path else None
    out_dir = Path(args.out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise UserError(f"--out-dir {out_dir}: exists and is not a directory")
    if not (out_dir.parent if str(out_dir.parent) else Path(".")).is_dir():
        raise UserError(f"--out-dir {out_dir}: parent directory {out_dir.parent} does not exist")
    check_report_dir(out_dir, "report")
    unit = args.unit or Path(str(recordings[0])).stem

    loaded = {path: check_scored(read_recording(path)) for path in dict.fromkeys(r for r in recordings if r)}
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(
        tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=out_dir.parent if str(out_dir.parent) else ".")
    )
    try:
        reports = []
        seen: set[str] = set()
        imu_runs: dict[Any, Any] = {}  # an IMU module given for several models is verified once
        for model_arg, rec_path, target in zip(args.models, recordings, verifies, strict=True):
            assert rec_path is not None
            model_path = Path(model_arg)
            model, ckpt = load_model(model_path)
            stats = TrainStats.of_checkpoint(ckpt)
            rec = model_view(loaded[rec_path], stats.channel or "", model_path)
            channel = stats.channel or model_path.stem
            shown = shown_name(str(ckpt["method"]), stats)
            label = f"{channel} / {shown}"
            if label in seen:
                raise UserError(
                    f"{model_path}: a second {shown} model for channel {channel} (the channel is the "
                    "training recording's 'channel' metadata: check the import)"
                )
            seen.add(label)
            lo, hi = (float(v) for v in ckpt["valid_temp_range_c"])
            model_id = _model_id(model_path)
            compensated = model.compensate(rec.without_truth())
            # the held-out part is cut from the whole run's output (unit_scores): the state has run
            # through what precedes it, as in firmware running since power-on (as trainer compare)
            scores = score_unit(rec, compensated, args.smoothing, (lo, hi), holdout)
            notes = []
            held_text = None
            held_rows = None
            held_warning = None
            held_share = None
            if holdout is not None:
                held, held_rows = held_out_rows(rec, holdout)
                held_text = (
                    f"{holdout.describe()}; the part held out: t = {held.time_s[0]:g} .. {held.time_s[-1]:g} s "
                    f"of `{rec_path}`"
                )
                held_fingerprint = data_fingerprint(held)
                held_warning = overlap_warning(stats, held, held_fingerprint, whole=rec, what="held-out")
                held_share = training_row_share(stats, held, held_fingerprint, whole=rec)
                if held_warning:
                    notes.append(f"held-out part: {held_warning}")
            fingerprint = data_fingerprint(rec)  # the scored run's: the overlap, selection and share read it
            warning = overlap_warning(stats, rec, fingerprint)
            if warning:
                notes.append(f"whole recording: {warning}")
            faster = rate_note(
                stats, held if holdout is not None else rec, rec, "held-out part" if holdout else "recording"
            )
            if faster:
                notes.append(faster)
            # an auto model carries the cross-validation that chose it: on its own training run those
            # figures, not an in-sample or single-split one, are what the verdict judges
            selection = cross_validated_selection(ckpt)
            if stats.selection is not None and selection is None:
                notes.append(
                    "the model's parameters are not those auto cross-validated (the file was changed after the "
                    "fit): its cross-validation is not used; the figures are this report's own"
                )
            crossval = selection if selection is not None and stats.data_sha256 == fingerprint else None
            verify, sizes = (
                (None, None)
                if target is None
                else _verify(model_path, target, rec_path, rec, loaded[rec_path], args.smoothing, imu_runs)
            )
            entry = _bench_entry(bench, model_id, bench_path) if bench_path else None
            if bench_path is not None and entry is None:
                notes.append(f"{bench_path} has no module of this model id: instructions not measured")
            report = signoff.ChannelReport(
                training_row_share=(share := training_row_share(stats, rec, fingerprint)),
                fit_held_out=stats.held_out if share is not None else None,
                held_out_training_share=held_share,
                scored_range_c=_temp_range(held if holdout is not None else rec),
                channel=channel,
                unit=UNIT_LABELS[channel_unit(rec)],
                model_path=str(model_path),
                model_id=model_id,
                method=str(ckpt["method"]),
                shown=shown,
                trained_range_c=(lo, hi),
                recording_range_c=_temp_range(rec),
                scores=scores,
                held_out=held_text,
                crossval=crossval,
                verify=verify,
                cost=_cost(sizes, entry, bench_path),
                notes=notes,
                undetermined=model.undetermined(),
            )
            report.figures = signoff.write_figures(
                report, rec, model, compensated, args.smoothing, staging, thresholds, held_rows
            )
            reports.append(report)
        text = signoff.render(
            unit,
            reports,
            thresholds,
            recordings=list(dict.fromkeys(r for r in recordings if r)),
            config=args.config,
            smoothing_s=args.smoothing,
            version=__version__,
        )
        (staging / "report.md").write_text(text, encoding="utf-8")
        publish(staging, out_dir, "report")
    except BaseException as exc:
        shutil.rmtree(staging, ignore_errors=True)
        raise_write_error(exc, out_dir)
        raise
    line = signoff.summary_line(unit, reports, thresholds)
    print(f"{line}; report written to {out_dir}/report.md")
    return EXIT_FAILED if signoff.unit_verdict(reports, thresholds).failed else 0


def _temp_range(rec: Recording) -> tuple[float, float]:
    return (float(rec.temp_c.min()), float(rec.temp_c.max()))
