"""Per-unit calibration as flight-stack parameters: PX4 ``.params`` and ArduPilot ``.parm`` files.

Both stacks apply a cubic of the temperature as an offset, so only a model that *is* a cubic of
the temperature qualifies (``poly3``; ``pla`` with one interval, a line). What each stack does
with the parameters (checked in their sources; docs/flight-stacks.md quotes them):

PX4 (``src/modules/temperature_compensation/TemperatureCompensation.cpp``,
``calc_thermal_offsets_3D`` / ``_1D``, applied in ``src/lib/sensor_calibration/Accelerometer.hpp``
as ``data - _thermal_offset - _offset``)::

    dT = clamp(T, TMIN, TMAX) - TREF
    offset = X0 + X1 dT + X2 dT^2 + X3 dT^3        (baro: up to X5 dT^5)
    corrected = raw - offset                      (m/s^2, rad/s, Pa)

ArduPilot (``libraries/AP_InertialSensor/AP_InertialSensor_tempcal.cpp``, ``correct_sensor``;
``Tools/scripts/tempcal_IMU.py`` writes the same set)::

    P(d) = (ACC1 + (ACC2 + ACC3 d) d) d * 1e-6      (no constant term; 1e-6 = SCALE_FACTOR)
    corrected = raw - P(clamp(T) - 35) + P(clamp(CALTEMP) - 35)

The sign is the same as ours (``compensated = raw - drift``), so the offset is the model's drift
converted to the stack's unit. The constant term belongs to the stack's ordinary calibration
(PX4 asks for an accelerometer calibration after the thermal one; ArduPilot keeps it in
``INS_ACCOFFS_*``, ``INS_ACC2OFFS_*``, ... at ``INS_ACCn_CALTEMP``), and a chamber recording's constant includes gravity,
so by default PX4's ``X0`` is 0: the offset is ``drift(T) - drift(TREF)``.
"""

from __future__ import annotations

import math
import os
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from codegen.families.cubic import Poly3Spec
from codegen.families.pla import PlaSpec
from codegen.spec import Checkpoint, parse_checkpoint
from trainer import methods
from trainer.baselines.poly3 import shift_polynomial
from trainer.data.ardupilot_tcal import INSTANCES as ARDUPILOT_INSTANCES  # INS_TCAL1..3
from trainer.data.ardupilot_tcal import PREFIX as ARDUPILOT_PREFIX
from trainer.data.ardupilot_tcal import SCALE as ARDUPILOT_SCALE
from trainer.data.ardupilot_tcal import TEMP_RANGE_C as ARDUPILOT_TEMP_RANGE_C  # @Range of TMIN/TMAX
from trainer.data.ardupilot_tcal import TEMP_REF_C as ARDUPILOT_TEMP_REF_C  # (the import undoes it)
from trainer.data.channels import UNIT_LABELS, unit_of_channel_name
from trainer.data.flightlog import STANDARD_GRAVITY, ChannelName, parse_channel
from trainer.data.plausibility import WIDER_RUN_HINT
from trainer.errors import UserError
from trainer.reference import OFFSET_LIMIT_MG, OFFSET_OPTION, OffsetRecord

EXTENSIONS = {"px4-params": ".params", "ardupilot-parm": ".parm"}  # the --format choices besides c
# model unit -> the stacks' unit (PX4 and ArduPilot alike: m/s^2, rad/s, Pa)
TO_STACK_UNIT = {"mg": STANDARD_GRAVITY / 1000.0, "dps": math.pi / 180.0, "pa": 1.0}
STACK_UNIT = {"mg": "m/s^2", "dps": "rad/s", "pa": "Pa"}
PX4_PREFIX = {"accel": "TC_A", "gyro": "TC_G", "baro": "TC_B"}
PX4_BARO_ORDER = 5  # TC_Bn_X0..X5
PX4_INSTANCES = 4  # ACCEL_COUNT_MAX etc. in TemperatureCompensation.h
MAV_PARAM_TYPE_INT32, MAV_PARAM_TYPE_REAL32 = 6, 9
GRAVITY_IN_CONSTANT_MG = 500.0  # a constant term this large holds gravity, not a bias
AXIS_INDEX = {"x": 0, "y": 1, "z": 2}
SENSOR_NOUN = {"accel": "an accelerometer", "gyro": "a gyroscope", "baro": "a barometer"}
INT32_MAX = 2**31 - 1  # PX4's TC_*_ID is an int32 parameter
# The most a sensor's offset can move with temperature, in the stacks' unit (keyed by our unit, as
# TO_STACK_UNIT). Generous on purpose: a cubic that moves more than this over its range is fitted to
# noise (a short temperature span), not to a drift, and is refused whatever --accept-implausible said.
PHYSICAL_DRIFT_BOUND = {
    # m/s^2 (~204 mg): a consumer MEMS accelerometer's zero-g offset moves well under 1 m/s^2
    # (~100 mg) over its whole operating range (-40..85 degC)
    "mg": 2.0,
    # rad/s (~29 deg/s): a MEMS gyroscope's zero-rate offset moves a few deg/s over its range
    # (the worst datasheet figures, of older parts, are about 20 deg/s over -40..85 degC)
    "dps": 0.5,
    # Pa (10 hPa, ~80 m of altitude): a barometer's offset moves a few hPa at most over its range
    "pa": 1000.0,
}


@dataclass(frozen=True)
class ChannelCubic:
    """One channel's drift as a cubic about ``t_ref_c`` in the stacks' unit, clamped to the range."""

    channel: ChannelName
    name: str
    device_id: int | None
    coefficients: np.ndarray  # c0..c3 of (T - t_ref)^k, stack unit / degC^k
    t_ref_c: float
    t_min_c: float
    t_max_c: float
    model_sha256: str
    ahrs_orientation: int | None = None  # the training log's board rotation (ArduPilot), None: not noted
    offset: OffsetRecord | None = None  # the fit's offset policy (None: a file written before it)
    fitted_channel: str | None = None  # the channel the model was fitted on, where --channel moved it

    @property
    def identity(self) -> bool:
        """No compensation at all (``trainer fit --method auto`` chose none): every coefficient zero."""
        return not bool(np.any(self.coefficients))


CUBIC_HINT = "use poly3, or pla with --intervals 1"  # what a flight-stack parameter file can hold


class NotACubicError(UserError):
    """A model that is not a cubic of the temperature (:func:`load_channel_cubics` names them all)."""

    def __init__(self, source: str, shown: str, channel: str | None) -> None:
        super().__init__(
            f"{source}: method {shown!r} is not a cubic of the temperature; flight-stack parameters hold one "
            f"({CUBIC_HINT})"
        )
        self.source, self.shown, self.channel = source, shown, channel


def _model_cubic(
    ckpt: Checkpoint, source: str, shown: str, channel: str | None = None
) -> tuple[np.ndarray, float, tuple[float, float]]:
    """(c0..c3 in the model's unit, t_ref, clamp range) of a model that is a cubic of the temperature
    (``shown``: its name as the user knows it, auto's candidate or the method; ``channel``: its
    channel, for the refusal)."""
    model = ckpt.model
    if isinstance(model, Poly3Spec):
        return model.coefficients_mg.copy(), model.t_ref_c, model.temp_range_c
    if isinstance(model, PlaSpec) and len(model.slopes_mg_per_c) == 1:
        lo, hi = ckpt.valid_temp_range_c
        t_ref = 0.5 * (lo + hi)
        slope, intercept = float(model.slopes_mg_per_c[0]), float(model.intercepts_mg[0])
        return np.array([intercept + slope * t_ref, slope, 0.0, 0.0]), t_ref, (lo, hi)
    raise NotACubicError(source, shown, channel)


def load_channel_cubic(
    path: str | os.PathLike[str], *, channel: str | None = None, device_id: int | None = None
) -> ChannelCubic:
    """A checkpoint as a channel's cubic; ``channel``/``device_id`` override what the training recorded."""
    import hashlib

    from trainer.checkpoint import load_checkpoint  # torch: imported on use, so --help stays fast
    from trainer.train_stats import TrainStats

    source = str(path)
    raw = load_checkpoint(path)
    from trainer.selection import shown_name

    ckpt = parse_checkpoint(raw, source)
    stats = TrainStats.of_checkpoint(raw)
    coefficients, t_ref, (lo, hi) = _model_cubic(
        ckpt, source, shown_name(ckpt.method, stats), channel or stats.channel
    )
    name = channel or stats.channel
    if not isinstance(name, str):
        raise UserError(
            f"{source}: the model does not record which sensor axis it was fitted on (its recording has no "
            f"'channel' metadata); pass --channel, e.g. accel0_z"
        )
    parsed = parse_channel(name)
    if parsed is None:
        raise UserError(
            f"{source}: channel {name!r} is not a channel name (accelN_x|y|z, gyroN_x|y|z, baroN)"
        )
    fitted_unit = stats.unit or unit_of_channel_name(stats.channel)
    if channel is not None and parsed.unit != fitted_unit:
        raise UserError(
            f"{source}: --channel {channel} is in {UNIT_LABELS[parsed.unit]}, but the model was fitted on a "
            f"channel in {UNIT_LABELS.get(fitted_unit, fitted_unit)} ({stats.channel or 'accel_mg'}): a model "
            "of another sensor"
        )
    if device_id is None and channel is None:
        device_id = stats.device_id
    if not lo < hi:
        raise UserError(f"{source}: the valid temperature range {lo:g} .. {hi:g} degC is empty")
    scale = TO_STACK_UNIT[parsed.unit]
    sha = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    offset = OffsetRecord.from_dict(raw["offset"]) if "offset" in raw else None  # checked by load_checkpoint
    moved = stats.channel if channel is not None and stats.channel not in (None, channel) else None
    return ChannelCubic(
        parsed,
        name,
        device_id,
        coefficients * scale,
        t_ref,
        lo,
        hi,
        sha,
        stats.ahrs_orientation,
        offset,
        moved,
    )


def load_channel_cubics(
    paths: Sequence[str | os.PathLike[str]], *, channel: str | None = None, device_id: int | None = None
) -> list[ChannelCubic]:
    """:func:`load_channel_cubic` of each model; the models that are not a cubic are refused together,
    in one line naming every one (a user fixes them all at once, not one per run)."""
    cubics, refused = [], []
    for path in paths:
        try:
            cubics.append(load_channel_cubic(path, channel=channel, device_id=device_id))
        except NotACubicError as exc:
            refused.append(exc)
    if len(refused) == 1:
        raise refused[0]
    if refused:
        named = ", ".join(
            f"{e.channel} (method {e.shown!r}, {e.source})"
            if e.channel
            else f"{e.source} (method {e.shown!r})"
            for e in refused
        )
        raise UserError(
            f"{len(refused)} of the {len(paths)} models are not a cubic of the temperature, which flight-stack "
            f"parameters hold ({CUBIC_HINT}): {named}"
        )
    return cubics


@dataclass(frozen=True)
class SensorSet:
    """The channels of one sensor instance on a common reference and range (one stack parameter set)."""

    sensor: str
    instance: int
    device_id: int | None
    t_ref_c: float
    t_min_c: float
    t_max_c: float
    axes: dict[str | None, ChannelCubic]  # axis (None for a barometer) -> channel


NOTE = "# note: "  # a file comment the export also prints: what the file says, the terminal says


def model_lines(channels: Sequence[ChannelCubic]) -> list[str]:
    """The file's comment per model: its sha256, and for an identity why its coefficients are zero
    (a reader of the file alone would take zeros for a missing calibration)."""
    lines = [
        f"# {c.name}: model sha256 {c.model_sha256}"
        + (
            " (the identity: no compensation left less drift held out, so its coefficients are zero)"
            if c.identity
            else ""
        )
        for c in channels
    ]
    return lines + [
        f"{NOTE}{c.name}: the model was fitted on {c.fitted_channel}, written as {c.name} (--channel)"
        for c in channels
        if c.fitted_channel is not None
    ]


def shared_range(members: Sequence[ChannelCubic]) -> tuple[float, float]:
    """The range one parameter set applies over: the intersection of its compensated channels' ranges
    (an identity channel's zero coefficients hold at every temperature: it narrows nothing)."""
    compensated = [c for c in members if not c.identity] or list(members)
    return max(c.t_min_c for c in compensated), min(c.t_max_c for c in compensated)


def narrowed_notes(members: Sequence[ChannelCubic], lo_c: float, hi_c: float, shared_by: str) -> list[str]:
    """A note per compensated channel whose own range the shared one cuts: the stack holds the edge
    value beyond it, where the channel's model was fitted."""
    return [
        f"{NOTE}{c.name}: fitted over {c.t_min_c:.2f} .. {c.t_max_c:.2f} degC, corrected over {lo_c:.2f} .. "
        f"{hi_c:.2f} degC only ({shared_by} share one range): outside it the stack holds the edge value"
        for c in members
        if not c.identity and (c.t_min_c < lo_c - 0.005 or c.t_max_c > hi_c + 0.005)
    ]


def group_by_instance(channels: Sequence[ChannelCubic]) -> list[SensorSet]:
    """Group channels per sensor instance; the instance's range is the intersection of its channels'."""
    groups: dict[tuple[str, int], list[ChannelCubic]] = defaultdict(list)
    for cubic in channels:
        groups[cubic.channel.sensor, cubic.channel.instance].append(cubic)
    sets = []
    for (sensor, instance), members in sorted(
        groups.items(), key=lambda item: (_sensor_rank(item[0][0]), item[0][1])
    ):
        axes: dict[str | None, ChannelCubic] = {}
        for cubic in members:
            if cubic.channel.axis in axes:
                raise UserError(
                    f"two models for channel {cubic.name} ({axes[cubic.channel.axis].name} given twice)"
                )
            axes[cubic.channel.axis] = cubic
        ids = {c.device_id for c in members if c.device_id is not None}
        if len(ids) > 1:
            raise UserError(f"{sensor}{instance}: the models name different device ids ({sorted(ids)})")
        lo, hi = shared_range(members)
        if not lo < hi:
            raise UserError(f"{sensor}{instance}: the models' temperature ranges do not overlap")
        for cubic in members:
            check_physical(cubic, lo, hi)
        sets.append(SensorSet(sensor, instance, next(iter(ids), None), 0.5 * (lo + hi), lo, hi, axes))
    return sets


def cubic_extremes(cubic: ChannelCubic, lo_c: float, hi_c: float, order: int = 0) -> tuple[float, float]:
    """(min, max) of the cubic's ``order``-th derivative over ``lo_c .. hi_c`` (exact: the ends and
    the stationary points inside), in the stack unit per degC^order."""
    poly = np.polynomial.Polynomial(cubic.coefficients).deriv(order)
    stationary = [float(r.real) + cubic.t_ref_c for r in poly.deriv().roots() if abs(r.imag) < 1e-12]
    temps = np.array([lo_c, hi_c, *(t for t in stationary if lo_c < t < hi_c)])
    values = poly(temps - cubic.t_ref_c)
    return float(values.min()), float(values.max())


def check_physical(cubic: ChannelCubic, lo_c: float, hi_c: float) -> None:
    """Refuse a cubic whose correction over its clamp range moves more than the sensor can drift.

    The range is widened to the span a cubic needs (``trainer fit``'s poly3 minimum, ArduPilot's
    TEMP_RANGE_MIN): within a tiny range the stacks' clamping hides what the coefficients say, and a
    cubic fitted to noise over 0.3 degC says the offset would move by tens of m/s^2 within 10 degC.
    """
    span_c = max(hi_c - lo_c, methods.get(methods.CUBIC).min_temp_span_c)
    mid_c = 0.5 * (lo_c + hi_c)
    moves = math.nan
    if np.all(np.isfinite(cubic.coefficients)):
        low, high = cubic_extremes(cubic, mid_c - 0.5 * span_c, mid_c + 0.5 * span_c)
        moves = high - low
    bound = PHYSICAL_DRIFT_BOUND[cubic.channel.unit]
    if not moves <= bound:  # NaN too
        unit = STACK_UNIT[cubic.channel.unit]
        where = f"{lo_c:.2f} .. {hi_c:.2f} degC" + (
            "" if hi_c - lo_c >= span_c else f" widened to {span_c:g} degC"
        )
        raise UserError(
            f"{cubic.name}: the cubic's correction moves by {moves:.3g} {unit} over {where}, more than "
            f"{SENSOR_NOUN[cubic.channel.sensor]}'s offset can drift with temperature ({bound:g} {unit}): "
            f"coefficients fitted to noise, not written (--accept-implausible does not change this); "
            f"{WIDER_RUN_HINT}"
        )


NO_MODEL = "no model given, coefficients 0"  # what both files say of what they write as zero


def missing_axes_note(group: SensorSet) -> str | None:
    """The comment naming the axes of a sensor written as zero (no model given); None: none are."""
    missing = [axis for axis in AXIS_INDEX if axis not in group.axes] if group.sensor != "baro" else []
    return f"# {group.sensor}{group.instance} axes {', '.join(missing)}: {NO_MODEL}" if missing else None


def _sensor_rank(sensor: str) -> int:
    return list(PX4_PREFIX).index(sensor)


def _number(value: float) -> str:
    """9 significant digits: a float32 parameter reads back to the same float32."""
    text = f"{value:.9g}"
    return "0" if text in ("0", "-0") else text


# --------------------------------------------------------------------------- PX4


def px4_values(group: SensorSet, *, keep_constant: bool) -> list[tuple[str, float | int, int]]:
    """(name, value, MAV_PARAM_TYPE) of one TC_A/TC_G/TC_B instance, in PX4's parameter names."""
    prefix = f"{PX4_PREFIX[group.sensor]}{group.instance}"
    if group.device_id is None:
        raise UserError(
            f"{group.sensor}{group.instance}: PX4 applies {prefix}_* to the sensor whose device id is {prefix}_ID, "
            f"and the model does not record it; pass --device-id (trainer import of a ULog records it)"
        )
    if not 0 < group.device_id <= INT32_MAX:
        what = "0 names no sensor" if group.device_id == 0 else f"{group.device_id} is not a sensor's id"
        raise UserError(
            f"{group.sensor}{group.instance}: device id {what}: PX4 applies {prefix}_* to the sensor whose "
            f"device id equals {prefix}_ID (1 .. {INT32_MAX}), so nothing would be compensated; pass the "
            f"sensor's id with --device-id (trainer import of a ULog records it)"
        )
    rows: list[tuple[str, float | int, int]] = [(f"{prefix}_ID", group.device_id, MAV_PARAM_TYPE_INT32)]
    rows += [
        (f"{prefix}_TREF", group.t_ref_c, MAV_PARAM_TYPE_REAL32),
        (f"{prefix}_TMIN", group.t_min_c, MAV_PARAM_TYPE_REAL32),
        (f"{prefix}_TMAX", group.t_max_c, MAV_PARAM_TYPE_REAL32),
    ]
    if group.sensor == "baro":
        coefficients = _px4_coefficients(group.axes[None], group.t_ref_c, keep_constant)
        padded = np.pad(coefficients, (0, PX4_BARO_ORDER + 1 - len(coefficients)))
        return rows + [
            (f"{prefix}_X{k}", float(padded[k]), MAV_PARAM_TYPE_REAL32) for k in range(PX4_BARO_ORDER + 1)
        ]
    per_axis = {
        axis: _px4_coefficients(group.axes[axis], group.t_ref_c, keep_constant)
        if axis in group.axes
        else np.zeros(4)
        for axis in AXIS_INDEX
    }
    for k in range(4):
        for axis, index in AXIS_INDEX.items():
            rows.append((f"{prefix}_X{k}_{index}", float(per_axis[axis][k]), MAV_PARAM_TYPE_REAL32))
    return rows


def _px4_coefficients(cubic: ChannelCubic, t_ref_c: float, keep_constant: bool) -> np.ndarray:
    coefficients = shift_polynomial(cubic.coefficients, cubic.t_ref_c, t_ref_c)
    if not keep_constant:
        coefficients[0] = 0.0
    else:
        _check_holds_constant(cubic)
        constant_model_unit = coefficients[0] / TO_STACK_UNIT[cubic.channel.unit]
        if cubic.channel.sensor == "accel" and abs(constant_model_unit) > GRAVITY_IN_CONSTANT_MG:
            raise UserError(
                f"{cubic.name}: the constant term {constant_model_unit:.1f} mg holds gravity, not a bias; export "
                f"without --keep-constant, or fit on a recording imported with --remove-gravity"
            )
    return coefficients


def _check_holds_constant(cubic: ChannelCubic) -> None:
    """Refuse --keep-constant for a model fitted relative to T_ref: ``trainer fit`` shifted its constant
    out (trainer/reference.py), so its X0 would be 0 whatever the option says."""
    if cubic.offset is None or not cubic.offset.relative:
        return
    unit = UNIT_LABELS[cubic.channel.unit]
    constant = f"{cubic.offset.drift_at_t_ref_mg:.4g} {unit}"
    todo = f"refit with 'trainer fit {OFFSET_OPTION} absolute' to keep it, or export without --keep-constant"
    if cubic.channel.sensor == "accel" and abs(cubic.offset.drift_at_t_ref_mg) > OFFSET_LIMIT_MG:
        # gravity: 'trainer fit --offset absolute' refuses it too
        todo = (
            f"{constant} is gravity or a static offset, which the ordinary calibration owns: export without "
            f"--keep-constant (or refit with {OFFSET_OPTION} absolute on a recording imported with --remove-gravity)"
        )
    raise UserError(
        f"{cubic.name}: --keep-constant: the model holds no constant to keep (fitted with {OFFSET_OPTION} "
        f"relative, the default: its constant, {constant} at T_ref {cubic.offset.t_ref_c:.2f} degC, was left "
        f"to the ordinary calibration), so X0 would be 0; {todo}"
    )


def check_distinct_ids(groups: Sequence[SensorSet]) -> None:
    """Refuse two instances of a sensor type under one device id: PX4 applies the first TC_x set whose
    ID matches (``TemperatureCompensation::set_sensor_id``), so the second set would never be applied
    and the sensor that really has the other id would go uncompensated."""
    seen: dict[tuple[str, int], SensorSet] = {}
    for group in groups:
        if group.device_id is None:
            continue
        first = seen.setdefault((group.sensor, group.device_id), group)
        if first is not group:
            raise UserError(
                f"{first.sensor}{first.instance} and {group.sensor}{group.instance} both have device id "
                f"{group.device_id}: PX4 applies the first {PX4_PREFIX[group.sensor]} set whose ID matches, so "
                f"{group.sensor}{group.instance}'s would never be applied; give each sensor its own id (--device-id)"
            )


def untouched_sets_notes(groups: Sequence[SensorSet]) -> list[str]:
    """A note per sensor type naming the PX4 sets this file leaves as the vehicle has them: the file
    switches ``TC_x_ENABLE`` on for the whole type, so a set left from an earlier calibration with a
    real device id applies again. They are named, not zeroed: a second file for another instance
    must not erase the first's set."""
    notes = []
    for sensor, prefix in PX4_PREFIX.items():
        carried = {g.instance for g in groups if g.sensor == sensor}
        if not carried:
            continue
        others = [f"{prefix}{i}" for i in range(PX4_INSTANCES) if i not in carried]
        if others:
            notes.append(
                f"{NOTE}{', '.join(others)}: not in this file, left as the vehicle has them; with "
                f"{prefix}_ENABLE 1 a set left there by an earlier calibration applies to the sensor whose id "
                f"is its {prefix}n_ID: set that _ID to 0 unless it is a calibration you keep"
            )
    return notes


def render_px4(channels: Sequence[ChannelCubic], *, keep_constant: bool = False) -> str:
    """A QGroundControl parameter file (``Vehicle-Id Component-Id Name Value Type``, tab-separated)."""
    groups = group_by_instance(channels)
    for group in groups:
        if group.instance >= PX4_INSTANCES:
            raise UserError(
                f"{group.sensor}{group.instance}: PX4 has thermal parameters for instances 0..3 only"
            )
    check_distinct_ids(groups)
    lines = [
        "# Sensor thermal compensation parameters (mems-tdc codegen export --format px4-params)",
        "# Applied by PX4's TemperatureCompensation: offset = X0 + X1 dT + X2 dT^2 + X3 dT^3,",
        "# dT = clamp(T, TMIN, TMAX) - TREF; corrected = raw - offset (m/s^2, rad/s, Pa).",
        f"# X0: {'the model constant' if keep_constant else '0, the constant belongs to the ordinary calibration'}.",
    ]
    lines += model_lines(channels)
    lines += [note for note in map(missing_axes_note, groups) if note is not None]
    for group in groups:
        members = list(group.axes.values())
        lines += narrowed_notes(
            members, group.t_min_c, group.t_max_c, f"the axes of {group.sensor}{group.instance}"
        )
    lines += untouched_sets_notes(groups)
    lines += ["#", "# Vehicle-Id Component-Id Name Value Type"]
    rows: list[tuple[str, float | int, int]] = []
    for sensor in PX4_PREFIX:
        given = [c for c in channels if c.channel.sensor == sensor]
        if given and all(c.identity for c in given):
            # TC_x_ENABLE switches every instance of the sensor type, including ones this file does not carry
            lines.insert(
                -2,
                f"# {sensor}: every model given is the identity (no compensation): zero coefficients; "
                f"{PX4_PREFIX[sensor]}_ENABLE, which switches every {sensor} instance, is left as the vehicle has it",
            )
        elif given:
            rows.append((f"{PX4_PREFIX[sensor]}_ENABLE", 1, MAV_PARAM_TYPE_INT32))
    for group in groups:
        rows += px4_values(group, keep_constant=keep_constant)
    for name, value, kind in rows:
        text = str(int(value)) if kind == MAV_PARAM_TYPE_INT32 else _number(float(value))
        lines.append(f"1\t1\t{name}\t{text}\t{kind}")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- ArduPilot


def render_ardupilot(channels: Sequence[ChannelCubic]) -> str:
    """An ArduPilot parameter file (``NAME VALUE`` lines) of INS_TCALn_* sets, as tempcal_IMU.py writes."""
    for c in channels:
        if c.ahrs_orientation:
            raise UserError(
                f"{c.name}: fitted on a DataFlash log with AHRS_ORIENTATION={c.ahrs_orientation}, whose IMU axes "
                "are the vehicle's, while INS_TCAL applies in the sensor frame: these coefficients would land on "
                "the wrong axes; log the calibration run with AHRS_ORIENTATION=0 (the C module and PX4 "
                "parameters take the model as it is)"
            )
    groups = group_by_instance(channels)
    imus: dict[int, dict[str, SensorSet]] = defaultdict(dict)
    for group in groups:
        if group.sensor not in ARDUPILOT_PREFIX:
            raise UserError(
                f"{group.sensor}{group.instance}: ArduPilot's INS_TCAL holds accelerometers and gyroscopes only"
            )
        if group.instance >= ARDUPILOT_INSTANCES:
            raise UserError(
                f"{group.sensor}{group.instance}: ArduPilot has INS_TCAL1..3 (IMU instances 0..2) only"
            )
        imus[group.instance][group.sensor] = group
    lines = [
        "# IMU temperature calibration (mems-tdc codegen export --format ardupilot-parm)",
        "# Applied by AP_InertialSensor_tempcal.cpp: P(d) = (C1 + (C2 + C3 d) d) d * 1e-6, d = clamp(T) - 35,",
        "# corrected = raw - P(T - 35) + P(CALTEMP - 35) (m/s^2, rad/s); the constant belongs to",
        "# INS_ACCOFFS_* (INS_ACC2OFFS_*, INS_ACC3OFFS_* for the second and third IMU), measured at INS_ACCn_CALTEMP.",
        "# ArduPilot hides INS_TCALn_* while INS_TCALn_ENABLE is 0, so a first load sets ENABLE and skips",
        "# the rest: refresh the parameters (or reboot), load this file again, reboot (ENABLE needs one),",
        "# then redo the accelerometer calibration.",
    ]
    lines += model_lines(channels)
    for instance, sensors in sorted(imus.items()):
        prefix = f"INS_TCAL{instance + 1}"
        members = [c for found in sensors.values() for c in found.axes.values()]
        lo, hi = shared_range(members)
        if not lo < hi:
            raise UserError(
                f"IMU {instance}: the accelerometer and gyroscope models' temperature ranges do not overlap"
            )
        lines += narrowed_notes(members, lo, hi, f"accel{instance} and gyro{instance}")
        declared_lo, declared_hi = ARDUPILOT_TEMP_RANGE_C
        if lo < declared_lo or hi > declared_hi:  # a ground station may refuse a value outside @Range
            clamped = max(lo, declared_lo), min(hi, declared_hi)
            lines.append(
                f"{NOTE}{prefix}_TMIN/TMAX: the models' range {lo:.2f} .. {hi:.2f} degC leaves ArduPilot's declared "
                f"{declared_lo:g} .. {declared_hi:g} degC; written as {clamped[0]:.2f} .. {clamped[1]:.2f}: beyond it "
                "ArduPilot holds the correction at the edge value"
            )
            lo, hi = clamped
        if all(c.identity for found in sensors.values() for c in found.axes.values()):
            lines.append(identity_set_note(prefix, instance))
        lines += [
            f"{prefix}_ENABLE 1",  # also for an identity set: its zeros must overwrite what the board holds
            f"{prefix}_TMIN {_number(lo)}",
            f"{prefix}_TMAX {_number(hi)}",
        ]
        for sensor, short in ARDUPILOT_PREFIX.items():
            axes = sensors[sensor].axes if sensor in sensors else {}
            note = f"# {sensor}{instance}: {NO_MODEL}" if not axes else missing_axes_note(sensors[sensor])
            if note is not None:
                lines.append(note)
            for order in (1, 2, 3):
                for axis in AXIS_INDEX:
                    cubic = axes.get(axis)
                    value = 0.0
                    if cubic is not None:
                        shifted = shift_polynomial(cubic.coefficients, cubic.t_ref_c, ARDUPILOT_TEMP_REF_C)
                        value = float(shifted[order]) * ARDUPILOT_SCALE
                    lines.append(f"{prefix}_{short}{order}_{axis.upper()} {_number(value)}")
    return "\n".join(lines) + "\n"


def identity_set_note(prefix: str, instance: int) -> str:
    """The note of an INS_TCALn set whose every model is the identity. It is written with ENABLE 1 and
    zero coefficients: with ENABLE 1 ArduPilot applies P = 0 (``correct_sensor`` subtracts P(T - 35)
    and adds P(CALTEMP - 35), both 0: no correction), and the zeros overwrite the coefficients of an
    earlier calibration. With ENABLE 0 (``correct_sensor`` returns at once) the set's other parameters
    are hidden, so a file could not load its zeros: the earlier coefficients would stay on the board
    and apply again whenever ENABLE is set to 1."""
    return (
        f"{NOTE}{prefix} (accel{instance}, gyro{instance}): every model given is the identity (no compensation): "
        f"written as {prefix}_ENABLE 1 with zero coefficients, which ArduPilot applies as no correction; "
        f"ENABLE 0 would hide the set, and the coefficients of an earlier calibration would stay on the board "
        f"(and apply again once ENABLE is 1): load the file twice as above to overwrite them with the zeros"
    )


def render(fmt: str, channels: Sequence[ChannelCubic], *, keep_constant: bool = False) -> str:
    if fmt == "px4-params":
        return render_px4(channels, keep_constant=keep_constant)
    if keep_constant:
        raise UserError("--keep-constant applies to px4-params only (ArduPilot has no constant term)")
    return render_ardupilot(channels)
