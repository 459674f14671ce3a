"""``codegen verify``: the generated C equals the golden model on a whole recording, bit for bit.

The recording is converted once to the step API's integers (``round(accel_mg * 16000)`` in 1/16 ug,
``round(temp_c * 1000)`` mdegC, round half to even: the "ADC"), streamed through the compiled
``NAME_run`` in one call and through the golden model; every output sample and the final state
must be identical. The golden output is then compared with the float model of the trainer on the
float recording and on the same integer inputs (the error budget, in mg; for the streaming models
also before the output's rounding to 1/16 ug), and optionally the paper's Table 1 of the quantised
model is compared with the float model's on both.
"""

from __future__ import annotations

import dataclasses
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from codegen.export import LoadedModel, load_for_codegen, manifest_name
from codegen.families.physics.quantise import QPhysics
from codegen.families.stream.golden import GoldenStream
from codegen.families.stream.quantise import QStream
from codegen.family import QuantModel, family_of
from codegen.fixedpoint import INT32_MAX, INT32_MIN
from codegen.golden_select import golden_for
from codegen.hostbuild import load_module
from codegen.input_limits import raw_limits_of_clamps
from codegen.quantize import ACCEL_PER_MG
from codegen.rate import declared_rate_millihz, retime_compensator
from codegen.rate import resample as resample_recording
from codegen.render import clamp_text
from codegen.step_units import STEP_UNITS
from trainer.data.recording import Recording
from trainer.data.recording_io import RECORDING_SUFFIXES
from trainer.errors import UserError

if TYPE_CHECKING:
    from trainer.scoring.allan import AllanTable


ERROR_BUDGET_RMS_MG = 1e-3  # golden minus float on the same integer inputs, docs/codegen.md "Error budget"
ERROR_BUDGET_MAX_MG = 5e-3


@dataclass(frozen=True)
class ClampedSamples:
    """The samples whose input the module clamps (``NAME_FLAG_INPUT_CLAMPED``, sample by sample in the
    golden model), compared apart from the error budget: there the module differs from the float
    model by what the clamp removes, which is no quantisation error."""

    count: int
    clamps: str  # where the module clamps (its declaration, as NAME.h says it)
    rms_mg: float  # golden minus the float model behind the clamp, on these samples (same integer inputs)
    max_abs_mg: float
    effect_max_mg: float  # max |float behind the clamp - float on raw inputs|: the clamp's own effect


@dataclass(frozen=True)
class ErrorBudget:
    """Golden minus float, mg, over the samples of the recording the module does not clamp (the float
    model fed the inputs as the module's front end clamps them: :func:`behind_clamps`)."""

    rms_mg: float
    max_abs_mg: float
    noise_mg: float  # the sensor's white noise per sample, for scale
    arithmetic_rms_mg: float  # golden minus float on the same integer inputs: the generator's share
    arithmetic_max_abs_mg: float
    smoothed_rms_mg: float  # the arithmetic share after the paper's 0.5 s validation smoothing
    network_rms_mg: float | None = None  # the arithmetic share before the output's rounding to 1/16 ug
    network_max_abs_mg: float | None = None
    compared: int | None = None  # samples in the figures above (None: every sample)
    clamped: ClampedSamples | None = None  # the samples beyond the input clamp, compared apart

    @property
    def noise_ratio(self) -> float:
        return self.noise_mg / self.rms_mg if self.rms_mg > 0 else float("inf")

    @property
    def met(self) -> bool:
        """The generator's share (golden minus float on the same integer inputs) within the budget of
        docs/codegen.md: what the quantiser is sized for, whatever network it is given (vacuously,
        when the module clamps an input of every sample: nothing left to judge)."""
        if self.compared == 0:
            return True
        return (
            self.arithmetic_rms_mg <= ERROR_BUDGET_RMS_MG
            and self.arithmetic_max_abs_mg <= ERROR_BUDGET_MAX_MG
        )


@dataclass(frozen=True)
class ScheduleCheck:
    """A module whose network step is spread (``--schedule spread``) against the step schedule of
    the same quantised model on the same integer inputs (both golden models; the C equals its own)."""

    name: str
    latency_samples: int
    rate_hz: float
    delayed_equal: bool  # its drift removed = the step schedule's delayed by the latency, every sample
    output_mg: dict[str, np.ndarray]  # the fixed-point output (mg) by schedule: "step" and name
    # trainer evaluate's drift left against the truth, by schedule, each on its schedule_parts
    truth_drift_left_mg: dict[str, float] | None


@dataclass(frozen=True)
class VerifyResult:
    name: str
    method: str  # the model's name as the user knows it (LoadedModel.name: poly2, auto's choice)
    samples: int
    mismatches: int
    first_mismatch: int | None
    state_equal: bool
    budget: ErrorBudget
    table1: Table1Check | None  # against the float model on the recording
    table1_integer_inputs: Table1Check | None  # against the float model on the C's integer inputs
    rate_millihz: int = 0  # the module's NAME_SAMPLE_RATE_MILLIHZ (0: any rate)
    resampled_from_hz: float | None = None  # the recording's own rate when --resample interpolated it
    schedule: ScheduleCheck | None = None  # a spread module: against the step schedule
    unit: str = "mg"  # the model's channel unit (deg/s, Pa): the report's "mg" reads as it


def to_step_units(rec: Recording) -> tuple[np.ndarray, np.ndarray]:
    """The recording as the step function's int32 inputs (1/16 ug, mdegC)."""

    def convert(values: np.ndarray, scale: float) -> np.ndarray:
        return np.clip(np.rint(values * scale), INT32_MIN, INT32_MAX).astype(np.int32)

    return convert(rec.accel_mg, ACCEL_PER_MG), convert(rec.temp_c, 1000.0)


def check_module_dir(out_dir: Path) -> None:
    """Refuse an ``out_dir`` that is no directory; a recording there is the arguments swapped (both
    forms of ``codegen verify``: checked before the recording is read, which would blame the module)."""
    if not out_dir.is_dir():
        order = "the order is model out_dir recording"
        if out_dir.is_file() and out_dir.suffix.lower() in RECORDING_SUFFIXES:
            raise UserError(
                f"{out_dir}: a recording, not the generated module's directory (arguments swapped? {order})"
            )
        if out_dir.is_file():  # a model file here is MODEL and OUTDIR swapped
            raise UserError(
                f"{out_dir}: a file, not the generated module's directory (arguments swapped? {order})"
            )
        raise UserError(f"{out_dir}: no such directory")


def find_manifest(out_dir: Path, name: str | None) -> tuple[str, dict[str, Any]]:
    check_module_dir(out_dir)
    if name is None:
        found = sorted(out_dir.glob("*.manifest.json"))
        if len(found) != 1:
            what = "no" if not found else f"{len(found)}"
            raise UserError(
                f"{out_dir}: {what} generated modules (*.manifest.json) found; name one with codegen verify --name, or keep one module per directory"
            )
        name = found[0].name[: -len(".manifest.json")]
    path = out_dir / manifest_name(name)
    try:
        manifest = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise UserError(f"{path}: cannot read the manifest ({exc})") from None
    return name, manifest


def manifest_raw_clamp(manifest: dict[str, Any], path: Path) -> tuple[str, int] | None:
    """Where the module (or an IMU module's channel, its entry) clamps its raw input, from its
    manifest's ``input_limits``: (channel unit, +-LSB), None when it never clamps it."""
    units = {step.label: unit for unit, step in STEP_UNITS.items()}
    try:
        signal = manifest["input_limits"]["input"]
        if not signal["clamped"]:
            return None
        lsb = signal["lsb"][1]
        if not isinstance(lsb, int) or signal["lsb"][0] != -lsb:
            raise ValueError(lsb)
        return units[signal["unit"]], lsb
    except (KeyError, TypeError, IndexError, ValueError):
        raise UserError(
            f"{path}: field 'input_limits.input' is missing or malformed (a module of another codegen "
            "version? export it again)"
        ) from None


def manifest_raw_limits(manifest: dict[str, Any], path: Path) -> dict[str, float]:
    """The raw-input limits the module was exported with (``--accel-limit-g``, ``--gyro-limit-dps``:
    unit -> value), read from where its manifest says it clamps; empty (the defaults, which then change
    nothing) when it never clamps its raw input."""
    clamp = manifest_raw_clamp(manifest, path)
    return raw_limits_of_clamps([] if clamp is None else [clamp], str(path))


def sensor_noise_mg(accel_mg: np.ndarray) -> float:
    """White noise per sample from successive differences (drift cancels out)."""
    return float(np.std(np.diff(accel_mg)) / np.sqrt(2.0))


def _rms_max(err: np.ndarray) -> tuple[float, float]:
    if not err.size:
        return float("nan"), float("nan")
    return float(np.sqrt(np.mean(err**2))), float(np.max(np.abs(err)))


def error_budget(
    golden: np.ndarray,
    float_mg: np.ndarray,
    float_on_ints_mg: np.ndarray,
    accel_mg: np.ndarray,
    rate_hz: float,
    fine_mg: np.ndarray | None = None,
    apart: np.ndarray | None = None,
) -> ErrorBudget:
    """Golden minus float on the float recording (total) and on the integer inputs (arithmetic),
    the latter also after the paper's 0.5 s smoothing and, given ``fine_mg`` (the golden output
    before the estimate's rounding to 1/16 ug), before that rounding: the output LSB costs up to
    one LSB per sample, which the error feedback pushes to high frequencies. ``apart``: the samples
    left out of every figure (those the module clamps, :class:`ClampedSamples`)."""
    from trainer.scoring.evaluate import PAPER_VALIDATION_SMOOTHING_S, smooth_for_scoring

    keep = np.ones(golden.size, dtype=bool) if apart is None else ~apart
    golden_mg = golden / ACCEL_PER_MG
    arithmetic = golden_mg - float_on_ints_mg
    smoothed = smooth_for_scoring(arithmetic, rate_hz, PAPER_VALIDATION_SMOOTHING_S)[keep]
    network = _rms_max((fine_mg - float_on_ints_mg)[keep]) if fine_mg is not None else (None, None)
    return ErrorBudget(
        *_rms_max((golden_mg - float_mg)[keep]),
        sensor_noise_mg(accel_mg),
        *_rms_max(arithmetic[keep]),
        float(np.sqrt(np.mean(smoothed**2))) if smoothed.size else float("nan"),
        network_rms_mg=network[0],
        network_max_abs_mg=network[1],
        compared=None if apart is None else int(np.count_nonzero(keep)),
    )


def behind_clamps(q: QuantModel, accel: np.ndarray, temp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The step's integer inputs as the module's front end clamps them (its family's declaration,
    ``CFamily.input_clamps``, which its C is rendered from): what its model reads."""
    clamps = family_of(q).input_clamps(q)
    if clamps.signal_lsb is not None:
        accel = np.clip(accel, -clamps.signal_lsb, clamps.signal_lsb)
    if clamps.temp_mdegc is not None:
        temp = np.clip(temp, *clamps.temp_mdegc)
    return accel, temp


def float_behind_clamps(
    float_model: Any, q: QuantModel, rec: Recording, accel: np.ndarray, temp: np.ndarray, *, integers: bool
) -> np.ndarray:
    """The float model's output (mg) behind the module's input clamp: fed the inputs as the module
    clamps them, with what the clamp took off the raw input added back (the module subtracts its
    drift estimate from the raw input, not from the clamped one). ``integers``: on the step's integer
    inputs ``accel``, ``temp``; else on the float recording, whose samples the module clamps (their
    integers beyond a clamp) replaced by the clamp's bound. On a recording the module clamps nowhere
    both are the float model's output on the recording as it is."""
    clamped, clamped_temp = behind_clamps(q, accel, temp)
    if integers:
        raw_mg, clamped_mg = accel / ACCEL_PER_MG, clamped / ACCEL_PER_MG
        view = integer_recording(rec, clamped, clamped_temp)
    else:
        raw_mg = rec.accel_mg
        clamped_mg = np.where(clamped != accel, clamped / ACCEL_PER_MG, raw_mg)
        temp_c = np.where(clamped_temp != temp, clamped_temp / 1000.0, rec.temp_c)
        columns = {**rec.without_truth().columns, "accel_mg": clamped_mg, "temp_c": temp_c}
        view = Recording(columns, dict(rec.meta), rec.source)
    out: np.ndarray = float_model.compensate(view) + (raw_mg - clamped_mg)
    return out


def held_fine_output(accel: np.ndarray, fine_estimates: list[float], decimation: int) -> np.ndarray:
    """The output with the unrounded estimates (accel LSB) held from each network step, in mg."""
    held = np.repeat(np.asarray(fine_estimates, dtype=np.float64), decimation)[: accel.size]
    return (accel - held) / ACCEL_PER_MG


def integer_recording(rec: Recording, accel: np.ndarray, temp: np.ndarray) -> Recording:
    """``rec`` with the step API's integers converted back to mg and degC (what the C saw)."""
    columns = {**rec.without_truth().columns, "accel_mg": accel / ACCEL_PER_MG, "temp_c": temp / 1000.0}
    return Recording(columns, dict(rec.meta), rec.source)


IMPROVEMENT_BUDGET_PP = 0.1  # the quantised model's Allan improvements within 0.1 percentage point
DRIFT_LEFT_BUDGET = 0.01  # and its drift left within 1 % of the float model's


@dataclass(frozen=True)
class Table1Check:
    """Table 1 of the quantised model against the float model's, figure by figure.

    A figure "matches" when it prints the same, or when the two unrounded values differ by less
    than half a unit in the last printed place: then only a rounding boundary lies between them,
    which no finite precision can exclude (the float value may sit exactly on it).
    """

    figures: int
    identical: int
    within_half_unit: int
    text: str
    worst_half_unit_fraction: float = 0.0  # max |quantised - float| / (half a unit in the last place)
    max_improvement_diff_pp: float = 0.0  # max |quantised - float| of the Allan improvements, points
    drift_left_mg: tuple[float, float] | None = None  # RMS drift left (float, quantised), with truth

    @property
    def within_budget(self) -> bool:
        """Allan improvements within 0.1 percentage point, drift left within 1 % (docs/codegen.md)."""
        ratio = self.drift_left_ratio
        return self.max_improvement_diff_pp < IMPROVEMENT_BUDGET_PP and (
            ratio is None or ratio < DRIFT_LEFT_BUDGET
        )

    @property
    def drift_left_ratio(self) -> float | None:
        """|quantised / float - 1| of the drift left (the budget: at most 1 %)."""
        if self.drift_left_mg is None or self.drift_left_mg[0] <= 0:
            return None
        return abs(self.drift_left_mg[1] / self.drift_left_mg[0] - 1.0)

    @property
    def ok(self) -> bool:
        return self.identical + self.within_half_unit == self.figures


def _half_unit_sci(value: float) -> float:
    """Half a unit in the last place of ``f"{value:.2e}"``."""
    exponent = int(f"{value:.2e}".split("e")[1])
    return 0.5 * 10.0 ** (exponent - 2)


def _figures(table: AllanTable, column: str) -> list[tuple[float, str]]:
    """The seven printed figures of one column: B, K, R (value, improvement) and Aver."""
    out: list[tuple[float, str]] = []
    for key in table.improvement_pct[column]:  # the table's rows: B, K, R
        out += [
            (table.compensated[column].fits[key].value, "sci"),
            (table.improvement_pct[column][key], "pct"),
        ]
    out.append((table.average_improvement_pct[column], "pct"))
    return out


def _check(
    table: AllanTable, reference: str, quantised: str, drift: tuple[float, float] | None = None
) -> Table1Check:
    identical = near = 0
    worst = points = 0.0
    pairs = list(zip(_figures(table, reference), _figures(table, quantised), strict=True))
    for (a, kind), (b, _) in pairs:
        if not (np.isfinite(a) and np.isfinite(b)):
            identical += int(np.isfinite(a) == np.isfinite(b))
            continue
        text = (lambda v: f"{v:.2e}") if kind == "sci" else (lambda v: f"{v:.2f}")
        half = _half_unit_sci(a) if kind == "sci" else 0.005
        worst = max(worst, abs(a - b) / half)
        if kind == "pct":
            points = max(points, abs(a - b))
        if text(a) == text(b):
            identical += 1
        elif abs(a - b) < half:
            near += 1
    return Table1Check(len(pairs), identical, near, table.to_text(), worst, points, drift)


def compare_table1(
    rec: Recording, method: str, float_mg: np.ndarray, golden_mg: np.ndarray, float_on_ints_mg: np.ndarray
) -> tuple[Table1Check, Table1Check]:
    """Table 1 of the quantised model against the float model's on the recording (everything,
    the "ADC" included) and on the same integer inputs the C saw (the generator's share)."""
    from trainer.scoring.evaluate import evaluate

    columns = {method: golden_mg, "float": float_mg, "float, integer inputs": float_on_ints_mg}
    result = evaluate(rec, columns)
    table, drift = result.table, result.drift

    def left(reference: str) -> tuple[float, float] | None:
        if reference not in drift or method not in drift:
            return None
        return drift[reference].residual_rms_mg, drift[method].residual_rms_mg

    return (
        _check(table, "float", method, left("float")),
        _check(table, "float, integer inputs", method, left("float, integer inputs")),
    )


def verify(
    model_path: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    recording: str | os.PathLike[str],
    *,
    name: str | None = None,
    cc: str | None = None,
    table1: bool = True,
    resample: bool = False,
) -> VerifyResult:
    from trainer.checkpoint import load_model
    from trainer.data.channels import channel_unit, model_view
    from trainer.data.plausibility import check_scored
    from trainer.data.recording_io import read_recording
    from trainer.train_stats import TrainStats

    out = Path(out_dir)
    name, manifest = find_manifest(out, name)
    raw_limits = manifest_raw_limits(manifest, out / manifest_name(name))
    rates = manifest.get("rates")
    declared = rates.get("sample_rate_millihz") if isinstance(rates, dict) else None
    module_rate = declared if isinstance(declared, int) and declared > 0 else None
    schedule = str(manifest.get("schedule", {}).get("name", "step"))
    model: LoadedModel = load_for_codegen(
        model_path, raw_limits=raw_limits, rate_millihz=module_rate, schedule=schedule
    )
    model_entry = manifest.get("model")
    stamped = model_entry.get("sha256") if isinstance(model_entry, dict) else None
    if stamped != model.sha256:
        raise UserError(
            f"{out / name}.c was generated from another model (sha256 {stamped}, not {model.sha256})"
        )
    float_model, raw = load_model(model_path)
    # the model's own channel of a multi-channel file (gyro0_x), never the file's accel_mg
    channel = TrainStats.of_checkpoint(raw).channel
    rec = check_scored(model_view(read_recording(recording), channel, model_path))
    q = model.quantised
    rate_hz = declared_rate_millihz(q) / 1000
    resampled_from = None
    if rate_hz and abs(rec.sample_rate_hz - rate_hz) > 0.01 * rate_hz:
        if not resample:
            what = "the model's filters are for" if isinstance(q, QPhysics) else "the model runs at"
            raise UserError(
                f"{rec.source}: sample rate {rec.sample_rate_hz:g} Hz, {what} {rate_hz:g} Hz "
                "(--resample interpolates the recording onto it)"
            )
        resampled_from = rec.sample_rate_hz
        rec = resample_recording(rec, rate_hz)
    accel, temp = to_step_units(rec)

    host = load_module(out, name, cc=cc)
    if host.model_id() != f"sha256:{model.sha256}":
        raise UserError(f"{out / name}.c carries model id {host.model_id()}, not sha256:{model.sha256}")
    state = host.new_state()
    c_out = host.run(state, accel, temp)
    # The error budget and Table 1 measure the arithmetic, on the step schedule's output: a spread
    # module's is the same delayed by its latency (checked below), which against the float model
    # would count the delay as error. A step module's golden model is that one (run once).
    golden = golden_for(q)
    step_golden = golden
    if isinstance(q, QStream) and q.schedule != "step":
        step_golden = golden_for(dataclasses.replace(q, schedule="step"))
    spread = step_golden is not golden
    stream = step_golden if isinstance(step_golden, GoldenStream) else None
    if stream is not None:
        stream.fine_estimates = []
    g_out = golden.run(accel, temp)
    differ = np.flatnonzero(c_out.astype(np.int64) != g_out)
    c_state, g_state = host.read_state(state), golden.state()
    state_equal = c_state.keys() == g_state.keys() and all(
        np.array_equal(np.asarray(c_state[k]), np.asarray(g_state[k])) for k in c_state
    )
    step_out = step_golden.run(accel, temp) if spread else g_out
    offset = float_model.offset
    t_ref = offset.t_ref_c if offset is not None and offset.relative else None
    retime_compensator(float_model, declared_rate_millihz(q))
    # the float model behind the module's input clamp: what the clamp removes is apart from the budget
    float_out = float_behind_clamps(float_model, q, rec, accel, temp, integers=False)
    float_on_ints = float_behind_clamps(float_model, q, rec, accel, temp, integers=True)
    fine = None
    if stream is not None and stream.fine_estimates is not None:
        fine = held_fine_output(accel, stream.fine_estimates, stream.model.frontend.decimation)
    apart = np.asarray(step_golden.input_clamped, dtype=bool)
    budget = error_budget(
        step_out,
        float_out,
        float_on_ints,
        rec.accel_mg,
        rec.sample_rate_hz,
        fine,
        apart if apart.any() else None,
    )
    if apart.any():
        on_raw = float_model.compensate(integer_recording(rec, accel, temp))  # no clamp: the clamp's effect
        err = step_out[apart] / ACCEL_PER_MG - float_on_ints[apart]
        step = STEP_UNITS[q.limits.unit]
        clamped = ClampedSamples(
            int(np.count_nonzero(apart)),
            clamp_text(family_of(q).input_clamps(q), step),
            *_rms_max(err),
            float(np.max(np.abs(float_on_ints - on_raw))),
        )
        budget = dataclasses.replace(budget, clamped=clamped)
    tables = (
        compare_table1(rec, model.name, float_out, step_out / ACCEL_PER_MG, float_on_ints)
        if table1
        else (None, None)
    )
    return VerifyResult(
        name,
        model.name,  # as the header names it: auto's choice or the variant (poly2), not the class (poly3)
        int(accel.size),
        int(differ.size),
        int(differ[0]) if differ.size else None,
        state_equal,
        budget,
        tables[0],
        tables[1],
        rate_millihz=declared_rate_millihz(q),
        resampled_from_hz=resampled_from,
        schedule=schedule_check(q, rec, accel, g_out, step_out, t_ref),
        unit=channel_unit(rec),
    )


def schedule_parts(n: int, latency: int) -> tuple[slice, slice]:
    """The samples on which a schedule's drift left is compared with the step schedule's: each over
    n - latency samples, the step schedule's from the first, the delayed one's from sample latency on,
    so that both hold the same run of estimates, start-up transient included, and differ only by
    the delay (scored on the same samples, the step schedule's start-up would fall outside)."""
    return slice(0, n - latency), slice(latency, n)


def schedule_check(
    q: QuantModel, rec: Recording, accel: np.ndarray, out: np.ndarray, step: np.ndarray, t_ref_c: float | None
) -> ScheduleCheck | None:
    """For a spread module (output ``out``; ``step``: the step schedule's on the same inputs): whether
    the drift removed is the step schedule's delayed by the latency on every sample (and none before),
    and the drift left under each against the recording's true drift when it has one."""
    if not isinstance(q, QStream) or q.schedule == "step":
        return None
    lat = q.latency_samples
    removed, removed_step = accel.astype(np.int64) - out, accel.astype(np.int64) - step
    delayed = bool(np.array_equal(removed[lat:], removed_step[: removed_step.size - lat]))
    outputs = {"step": step / ACCEL_PER_MG, q.schedule: out / ACCEL_PER_MG}
    truth = None
    if rec.truth("drift_mg") is not None:  # as trainer evaluate scores it (relative to T_ref, if any)
        from trainer.scoring.evaluate import drift_score

        truth = {}
        for (k, v), part in zip(outputs.items(), schedule_parts(out.size, lat), strict=True):
            score = drift_score(rec.slice(part.start, part.stop), v[part], t_ref_c)
            assert score is not None
            truth[k] = score.residual_rms_mg
    return ScheduleCheck(
        q.schedule, lat, q.frontend.rate_hz, delayed and not np.any(removed[:lat]), outputs, truth
    )


def report_lines(result: VerifyResult) -> list[str]:
    b = result.budget
    rate = (
        f"{result.rate_millihz / 1000:g} Hz"
        if result.rate_millihz
        else "any rate (nothing in it depends on the sample rate)"
    )
    lines = [
        f"module rate: {rate}"
        + (
            f" (recording resampled from {result.resampled_from_hz:g} Hz)"
            if result.resampled_from_hz is not None
            else ""
        ),
        f"samples compared: {result.samples}",
        f"mismatches: {result.mismatches}"
        + (f" (first at sample {result.first_mismatch})" if result.first_mismatch is not None else ""),
        f"final state identical: {'yes' if result.state_equal else 'NO'}",
    ]
    c = b.clamped
    if c is not None:
        lines.append(
            f"{c.count} samples beyond the input clamp, compared apart ({result.name.upper()}_FLAG_INPUT_CLAMPED: "
            f"{c.clamps}): "
            f"the clamp moves the output by up to {c.effect_max_mg:.3g} mg against the float model on the raw "
            f"inputs, which is the clamp, not the arithmetic; golden - float behind the clamp there: RMS "
            f"{c.rms_mg:.3g} mg, max {c.max_abs_mg:.3g} mg. The figures below are over the other "
            f"{b.compared} samples, the float model fed the inputs as the module clamps them"
        )
    if b.compared == 0:
        lines.append("error budget: not measured (the module clamps an input of every sample)")
        return lines + _schedule_and_table_lines(result)
    lines += [
        f"error budget (golden - float, {result.method}): RMS {b.rms_mg:.3g} mg, max {b.max_abs_mg:.3g} mg "
        f"(sensor noise {b.noise_mg:.3g} mg per sample, {b.noise_ratio:.3g} x the RMS)",
        f"  of which integer arithmetic (golden - float on the same integer inputs): RMS "
        f"{b.arithmetic_rms_mg:.3g} mg, max {b.arithmetic_max_abs_mg:.3g} mg; "
        f"RMS {b.smoothed_rms_mg:.3g} mg over 0.5 s means: "
        + (
            "within the budget"
            if b.met
            else "OVER THE BUDGET (the quantised model strays further from the float model than "
            "docs/codegen.md allows; the C still equals its golden model)"
        )
        + f" ({ERROR_BUDGET_RMS_MG:g} mg RMS, {ERROR_BUDGET_MAX_MG:g} mg max)",
    ]
    if b.network_rms_mg is not None:
        lines.append(
            f"  before the output's rounding to one LSB (the model's own arithmetic): RMS "
            f"{b.network_rms_mg:.3g} mg, max {b.network_max_abs_mg:.3g} mg"
        )
    return lines + _schedule_and_table_lines(result)


def _schedule_and_table_lines(result: VerifyResult) -> list[str]:
    """The report's lines on a spread schedule and Table 1."""
    lines: list[str] = []
    sc = result.schedule
    if sc is not None:
        lines.append(
            f"schedule {sc.name}: the estimate takes effect {sc.latency_samples} samples "
            f"({sc.latency_samples / sc.rate_hz:g} s) later; drift removed = the step schedule's delayed by "
            f"{sc.latency_samples} samples on every sample: {'yes' if sc.delayed_equal else 'NO'}"
            + (
                f", drift left against the true drift, each over its {result.samples - sc.latency_samples} "
                f"samples with the same estimates: "
                + ", ".join(f"{k} {v:.4g} mg RMS" for k, v in sc.truth_drift_left_mg.items())
                if sc.truth_drift_left_mg is not None
                else ""
            )
        )
    for label, t in (
        ("float", result.table1),
        ("float on the same integer inputs", result.table1_integer_inputs),
    ):
        if t is None:
            continue
        lines.append(
            f"Table 1 (quantised vs {label}): {t.identical} of {t.figures} figures print identically; "
            f"improvements within {t.max_improvement_diff_pp:.2g} percentage points"
            + (
                f", drift left {t.drift_left_mg[1]:.4g} mg vs {t.drift_left_mg[0]:.4g} mg "
                f"({100 * (t.drift_left_ratio or 0.0):.2g} %)"
                if t.drift_left_mg is not None
                else ""
            )
            + (": within the budget" if t.within_budget else ": OUTSIDE THE BUDGET")
            + f" ({IMPROVEMENT_BUDGET_PP:g} pp, {100 * DRIFT_LEFT_BUDGET:g} %)"
        )
    return lines


def write_json(result: VerifyResult, out_dir: str | os.PathLike[str], path: str | os.PathLike[str]) -> None:
    """The result as JSON (``codegen verify --json``; ``trainer report --verify`` reads it), with the
    module's sizes from its manifest; written atomically."""
    from trainer.errors import atomic_output

    data = json_document(result, out_dir)
    with atomic_output(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n", encoding="utf-8")


def json_document(result: VerifyResult, out_dir: str | os.PathLike[str]) -> dict[str, Any]:
    """What ``codegen verify --json`` writes (and ``trainer fleet``'s ``verify.json`` holds, so that
    ``trainer report --verify`` reads either)."""
    _, manifest = find_manifest(Path(out_dir), result.name)
    model = manifest.get("model")
    data = {
        "name": result.name,
        "method": result.method,
        "model_id": model.get("id") if isinstance(model, dict) else None,
        "samples": result.samples,
        "mismatches": result.mismatches,
        "first_mismatch": result.first_mismatch,
        "state_equal": result.state_equal,
        "error_budget": {
            "arithmetic_rms": result.budget.arithmetic_rms_mg,
            "arithmetic_max_abs": result.budget.arithmetic_max_abs_mg,
            "unit": STEP_UNITS[result.unit].label,  # as the manifest spells it (deg/s, not dps)
            "met": result.budget.met,
            "compared_samples": result.samples if result.budget.compared is None else result.budget.compared,
            "clamped_samples": 0 if result.budget.clamped is None else result.budget.clamped.count,
        },
        "rate_millihz": result.rate_millihz,
        "resampled_from_hz": result.resampled_from_hz,
        "schedule": None
        if result.schedule is None
        else {
            "name": result.schedule.name,
            "latency_samples": result.schedule.latency_samples,
            "delayed_equal": result.schedule.delayed_equal,
        },
        "sizes": manifest.get("sizes"),
    }
    return data
