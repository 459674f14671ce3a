"""The channels of a multi-channel recording ("Several channels" of ``shared/specs/recording-format.md``).

A recording may carry accelerometer, gyroscope and barometer channels of several instances, each
with its own temperature. Every command works on one channel at a time through a *one-channel
view*: a :class:`~trainer.data.recording.Recording` whose ``accel_mg`` column holds the channel's
data in the channel's own unit and whose ``temp_c`` is the channel's temperature; the metadata
keys ``channel`` and ``unit`` say what the numbers are. So fitting, scoring and code generation
stay one-channel code, and the unit travels with the view (``channel_unit``) into reports and
generated headers.

``--channels all|LIST`` is parsed here (:func:`select_channels`); a bad name is one line that
names the available channels.
"""

from __future__ import annotations

import re
from collections.abc import Collection
from dataclasses import dataclass

import numpy as np

from trainer.data.flightlog import SENSOR_UNITS, parse_channel
from trainer.data.recording import Recording
from trainer.errors import UserError

ALL = "all"
# Column unit suffix -> (the unit as reports print it, the quantity it measures): the one place
# figures and tables take a channel's unit and axis wording from.
UNITS = {
    "mg": ("mg", "acceleration", "accelerometer"),
    "dps": ("deg/s", "angular rate", "gyroscope"),
    "pa": ("Pa", "pressure", "barometer"),
}
UNIT_LABELS = {suffix: label for suffix, (label, _, _) in UNITS.items()}  # what reports print
SENSOR_NAMES = {suffix: sensor for suffix, (_, _, sensor) in UNITS.items()}  # what a module's header names
DEFAULT_UNIT = "mg"  # a one-axis recording's accel_mg
ONE_AXIS_CHANNEL = "accel_mg"  # what figures call the channel of a one-axis recording (its column)
_DATA_COLUMN = re.compile(r"(accel|gyro)([0-9])_([xyz])_(mg|dps)|(baro)([0-9])_(pa)")
_LEGACY_AXIS = re.compile(r"accel_([xyz])_mg")  # the older spelling of accel0_<axis>_mg
# Columns a view keeps besides the channel (other channels are dropped: a view is one channel).
_KEPT = ("chamber_c",)


@dataclass(frozen=True)
class Channel:
    """One channel of a recording: its name, data column, temperature column and unit suffix."""

    name: str  # accel0_z, gyro1_x, baro0
    column: str  # accel0_z_mg
    temp_column: str  # accel0_temp_c, or temp_c when the instance has none
    unit: str  # mg | dps | pa

    @property
    def sensor(self) -> str:
        parsed = parse_channel(self.name)
        assert parsed is not None, "a Channel is only built from a parsed name"
        return parsed.sensor

    @property
    def label(self) -> str:
        """The unit as reports print it (mg, deg/s, Pa)."""
        return UNIT_LABELS[self.unit]


def recording_channels(rec: Recording) -> dict[str, Channel]:
    """Every channel a recording carries, in the order (sensor, instance, axis).

    ``accel_x_mg`` etc. count as ``accel0_x`` unless ``accel0_x_mg`` is present too, in which case the
    two spellings of one channel must hold the same data (a refusal names both otherwise).
    """
    for column in rec.columns:
        legacy = _LEGACY_AXIS.fullmatch(column)
        named = f"accel0_{legacy.group(1)}_mg" if legacy is not None else None
        if named in rec.columns and not np.array_equal(rec.columns[column], rec.columns[named]):
            raise UserError(
                f"{rec.source}: columns {column!r} and {named!r} are two spellings of one channel "
                f"({named} is the format's name, {column} the older one) with different data: "
                "keep one, or rename the other to another instance (accel1_...)"
            )
    return channels_in(rec.columns)


def channels_in(names: Collection[str]) -> dict[str, Channel]:
    """:func:`recording_channels` from the column names alone (a file's header, before its data)."""
    found: dict[str, Channel] = {}
    for column in names:
        match = _DATA_COLUMN.fullmatch(column)
        if match is not None:
            sensor = match.group(1) or match.group(5)
            instance = match.group(2) or match.group(6)
            axis = match.group(3)
            unit = match.group(4) or match.group(7)
            if unit != SENSOR_UNITS[sensor]:
                continue  # e.g. gyro0_x_mg: not a column of the contract
            name = f"{sensor}{instance}_{axis}" if axis else f"{sensor}{instance}"
        else:
            legacy = _LEGACY_AXIS.fullmatch(column)
            if legacy is None:
                continue
            sensor, instance, unit, name = "accel", "0", "mg", f"accel0_{legacy.group(1)}"
            if f"{name}_mg" in names:
                continue
        temp = own_temp_column(name)
        found[name] = Channel(name, column, temp if temp in names else "temp_c", unit)
    return dict(sorted(found.items(), key=lambda item: sort_key(item[0])))


def own_temp_column(channel: str) -> str:
    """The temperature column of a channel's instance (``gyro0_x`` -> ``gyro0_temp_c``)."""
    parsed = parse_channel(channel)
    assert parsed is not None, "only a parsed channel name has an instance temperature"
    return parsed.temp_column


def one_axis_left_out(rec: Recording, wanted: tuple[str, ...], channels: list[Channel]) -> str | None:
    """What ``--channels all`` (``wanted``) says when the file's own ``accel_mg`` is not one of its
    named channels (``channels``, what it selected); None for a list of names or no such column.

    A multi-channel recording may carry ``accel_mg`` as a copy of the axis a one-channel command
    compensates (``trainer import`` writes it so); a simulated IMU carries it as its accelerometer
    beside ``gyro0_x_dps``. In the second case ``all`` (named channels only) would drop it silently.
    """
    if wanted != (ALL,) or ONE_AXIS_CHANNEL not in rec.columns:
        return None
    data = rec.columns[ONE_AXIS_CHANNEL]
    if any(c.column in rec.columns and np.array_equal(rec.columns[c.column], data) for c in channels):
        return None
    return (
        f"note: {rec.source}: --channels all takes the named channels ({names_text([c.name for c in channels])}); "
        f"the file's own {ONE_AXIS_CHANNEL} column is none of them and is left out: run the command without "
        "--channels to take it (or name it accel0_<axis>_mg)"
    )


def shared_temperature_note(rec: Recording, channels: list[Channel]) -> str | None:
    """What a fit says when sensors of more than one device (IMU n: accel n and gyro n; a barometer)
    share the recording's ``temp_c`` for want of their own temperature column; None otherwise.

    A flight stack evaluates each sensor's set at that sensor's own temperature (PX4's TC_A1 at
    accel1's, TC_B0 at the barometer's), which can be degrees away from the shared one during a
    warm-up: a model fitted against another device's temperature is applied off by that much.
    """

    def device(channel: Channel) -> tuple[str, int]:
        parsed = parse_channel(channel.name)
        assert parsed is not None, "a Channel is only built from a parsed name"
        return ("baro" if parsed.sensor == "baro" else "imu", parsed.instance)

    if len({device(c) for c in channels}) < 2:
        return None
    shared = [c for c in channels if c.temp_column == "temp_c"]
    if not shared:
        return None
    missing = list(dict.fromkeys(own_temp_column(c.name) for c in shared))
    return (
        f"note: {rec.source}: {names_text([c.name for c in shared])}: fitted against temp_c, the "
        f"recording's shared temperature, for want of their own ({names_text(missing)}): a flight stack "
        "applies each sensor's set at that sensor's own temperature, which can be degrees away during a "
        "warm-up; record each sensor's temperature in its column if they differ"
    )


def parse_channels_option(text: str) -> tuple[str, ...]:
    """``all`` or a comma list of names; the names are checked against the recording (or model
    directory), so that a wrong one is reported with the channels that are there."""
    if text.strip() == ALL:
        return (ALL,)
    listed = [name.strip() for name in text.split(",")]
    if not all(listed):
        raise UserError(f"--channels {text!r}: an empty name (all, or a list such as accel0_z,gyro0_x)")
    # a name twice is a typo for another channel, not a request (an IMU export of accel0_x,accel0_x
    # wrote a module of one channel where two were asked for)
    if repeated := [n for n in dict.fromkeys(listed) if listed.count(n) > 1]:
        raise UserError(f"--channels {text!r}: {', '.join(repeated)} given twice: list each channel once")
    return tuple(listed)


def sort_key(name: str) -> tuple[int, str]:
    """Channels in the order sensor (accel, gyro, baro), instance, axis."""
    parsed = parse_channel(name)
    return (list(SENSOR_UNITS).index(parsed.sensor) if parsed else len(SENSOR_UNITS), name)


def names_text(channels: dict[str, Channel] | list[str]) -> str:
    names = list(channels)
    return ", ".join(names) if names else "(none)"


def other_channels_note(rec: Recording) -> str | None:
    """What a one-channel command on a multi-channel recording fits, when the recording carries other
    channels: an import of ``--channels gyro0_z`` still holds the preset's accelerometer axis in
    ``accel_mg`` (the format requires it), and a fit without ``--channels`` fitted that axis unsaid."""
    default = rec.meta.get("channel")
    others = [name for name in recording_channels(rec) if name != default]
    if not others or "accel_mg" not in rec.columns:  # without it, the command refuses and says so
        return None
    return (
        f"note: {rec.source}: fitting its one-channel column accel_mg ({default or 'no channel name'}); "
        f"it also carries {names_text(others)}: --channels NAME (or all) fits those"
    )


_SENSOR_PREFIXED = re.compile(r"(accel|gyro|baro)([0-9]+)_(.*)")  # a column named for a sensor instance


def misnamed_columns(names: Collection[str]) -> dict[str, str]:
    """``{column: why}`` for the columns named for a sensor instance (``gyro0_...``) that are neither
    one of its channels nor its temperature column: a typo the channel list would drop silently
    (``gyro0_x_dsp``, ``accel0_tmp_c``)."""
    channels = {c.column for c in channels_in(names).values()}
    out: dict[str, str] = {}
    for column in names:
        match = _SENSOR_PREFIXED.fullmatch(column)
        if match is None or column in channels:
            continue
        sensor, instance, rest = match.groups()
        if rest == "temp_c" and len(instance) == 1:
            continue
        unit = SENSOR_UNITS[sensor]
        data = f"{sensor}{instance[0]}_x_{unit}" if sensor != "baro" else f"baro{instance[0]}_{unit}"
        out[column] = (
            f"the format names a {sensor} instance's columns {data} (instance 0-9, unit {unit}) and "
            f"{sensor}{instance[0]}_temp_c"
        )
    return out


def select_channels(rec: Recording, wanted: tuple[str, ...]) -> list[Channel]:
    """The channels ``wanted`` (from :func:`parse_channels_option`) of ``rec``, in the order given.
    A column that looks like a channel or temperature of a wanted sensor instance but is not one of
    the format's names is refused: ``all`` would have left it out, and a typo in a temperature's
    name would have sent its channels to ``temp_c``."""
    available = recording_channels(rec)
    prefixes = None if wanted == (ALL,) else {name.split("_")[0] for name in wanted}
    for column, why in misnamed_columns(list(rec.columns)).items():
        match = _SENSOR_PREFIXED.fullmatch(column)
        assert match is not None
        if prefixes is None or f"{match.group(1)}{match.group(2)}" in prefixes:
            raise UserError(
                f"{rec.source}: column {column!r} is named for a sensor but is not a column of the format "
                f"({why}): rename it, or list the channels you want with --channels"
            )
    if not available:
        raise UserError(
            f"{rec.source}: --channels: the recording has no channel columns (accel0_x_mg, gyro0_x_dps, "
            f"baro0_pa, ...; columns: {', '.join(rec.columns)}); a one-axis recording needs no --channels"
        )
    if wanted == (ALL,):
        return list(available.values())
    missing = [name for name in wanted if name not in available]
    if missing:
        raise UserError(
            f"{rec.source}: --channels {missing[0]!r} is not in this recording; available: "
            f"{names_text(available)}"
        )
    return [available[name] for name in wanted]


def truth_columns(name: str, unit: str) -> dict[str, str]:
    """``{one-channel truth column: the recording's column}`` of channel ``name``.

    The format's ``true_*`` columns describe the file's ``accel_mg``; a simulated channel's own
    ground truth is ``true_<channel>_drift_<unit>``, ``true_<channel>_noise_<unit>``,
    ``true_<channel>_<unit>`` (the true input) and ``true_<channel>_pm_temp_c``
    (``trainer simulate`` with ``[channels]``), which its view carries under the one-channel names.
    """
    return {
        "true_accel_mg": f"true_{name}_{unit}",
        "true_drift_mg": f"true_{name}_drift_{unit}",
        "true_noise_mg": f"true_{name}_noise_{unit}",
        "true_pm_temp_c": f"true_{name}_pm_temp_c",
    }


def channel_view(rec: Recording, channel: Channel) -> Recording:
    """The one-channel recording of ``channel``: its data as ``accel_mg`` (in its own unit), its
    temperature as ``temp_c``, metadata ``channel``/``unit``; other channels dropped, and the
    file's truth too (it describes ``accel_mg``) except the channel's own (:func:`truth_columns`)."""
    columns = {
        "time_s": rec.time_s,
        "temp_c": rec.columns[channel.temp_column],
        "accel_mg": rec.columns[channel.column],
    }
    columns.update((name, rec.columns[name]) for name in _KEPT if name in rec.columns)
    own_truth = {
        view: column
        for view, column in truth_columns(channel.name, channel.unit).items()
        if column in rec.columns
    }
    if own_truth and channel.temp_column == "temp_c" and "true_temp_c" in rec.columns:
        own_truth["true_temp_c"] = "true_temp_c"
    columns.update((view, rec.columns[column]) for view, column in own_truth.items())
    meta = dict(rec.meta)
    if "sensor" in meta and meta.get("channel") != channel.name:
        # the file's sensor name is its accel_mg's (the channel its metadata names): another channel's
        # view is named by its channel (the bundled run's gyro0_x said "tofupilot-imu-acc-z")
        meta["sensor"] = channel.name
    meta["channel"] = channel.name
    meta["unit"] = channel.unit
    return Recording(columns, meta, f"{rec.source}[{channel.name}]", rec.row_label, channel.column)


def channel_unit(rec: Recording) -> str:
    """The unit suffix of a (view) recording's ``accel_mg`` column: ``mg`` unless a view says so."""
    return rec.meta.get("unit", DEFAULT_UNIT)


@dataclass(frozen=True)
class Signal:
    """What a one-channel view's ``accel_mg`` holds, as figures and tables name it.

    Every figure title and data axis, and every table heading, is built from this, so a
    gyroscope's figure says "gyro0_z" and "angular rate (deg/s)" rather than the accelerometer's mg.
    """

    channel: str  # accel0_z, gyro1_x, baro0; ONE_AXIS_CHANNEL for a one-axis recording
    unit: str  # column unit suffix: mg | dps | pa

    @property
    def label(self) -> str:
        """The unit as printed (mg, deg/s, Pa)."""
        return UNIT_LABELS[self.unit]

    @property
    def quantity(self) -> str:
        """What the channel measures (acceleration, angular rate, pressure)."""
        return UNITS[self.unit][1]

    def axis(self, what: str | None = None) -> str:
        """A data axis label: ``acceleration (mg)``, or ``drift left (deg/s)`` for ``what``."""
        return f"{what or self.quantity} ({self.label})"

    def title(self, text: str) -> str:
        """A figure or table title naming the channel: ``gyro0_z (deg/s): text``."""
        return f"{self.heading}: {text}"

    @property
    def heading(self) -> str:
        """``gyro0_z (deg/s)``."""
        return f"{self.channel} ({self.label})"


def signal_of(rec: Recording, channel: str | None = None) -> Signal:
    """The :class:`Signal` of a (view) recording; ``channel`` (e.g. a model's) wins over its metadata."""
    return Signal(channel or rec.meta.get("channel") or ONE_AXIS_CHANNEL, channel_unit(rec))


def unit_of_channel_name(name: str | None) -> str:
    """The unit suffix of a channel name (``mg`` for None or an unknown name: a one-axis model)."""
    parsed = parse_channel(name) if name else None
    return parsed.unit if parsed is not None else DEFAULT_UNIT


def method_refusal(method_name: str, family: str, channel: Channel) -> str | None:
    """Why ``method`` makes no sense on ``channel`` (one line), or None.

    Temperature-driven and memoryless methods (pla, poly3, physics, dlstm-temp) model a drift of
    the temperature and fit any sensor in its own unit. A recursive method predicts the drift from
    the signal's own past and removes whatever is sustained: on an accelerometer or gyroscope at
    rest in a chamber that is the drift, but a barometer's sustained signal *is* the measurement
    (altitude and weather change slowly), so the recursive methods are refused on a barometer.
    """
    if family == "recursive" and channel.sensor == "baro":
        return (
            f"{channel.name}: method {method_name!r} is recursive: it removes every slow change of the "
            f"signal, and a barometer's slow changes are altitude and weather; use a temperature-driven "
            f"method (poly3, pla, physics, dlstm-temp)"
        )
    return None


# A known second input at several temperatures, by the channel's unit suffix: what separates a
# scale-factor change from a bias change (scale_factor_tc's test, a diagnosis' generic profile); text
# written for milli-g names the accelerometer's, which relabel_units swaps for the channel's own
SECOND_INPUT = {
    "mg": "the accelerometer flipped 180 degrees, +1 g / -1 g, or tumbled",
    "dps": "the gyroscope on a rate table, two rates",
    "pa": "the barometer at a second pressure",
}
_UNIT_TOKEN = re.compile(r"\bmg\b")  # the unit word; column names (accel_mg, true_drift_mg) never match
_SENSOR_WORD = re.compile(r"\baccelerometer\b")  # the sensor the mg text was written for


def relabel_units(text: str, unit: str) -> str:
    """Text written for milli-g with the unit word replaced by ``unit``'s label (deg/s, Pa) and the
    word accelerometer by the unit's sensor (gyro, baro).

    The scoring and report code is one-channel code that says "mg"; a one-channel view of a
    gyroscope holds deg/s in the same column, so its reports are relabelled rather than the
    scoring code made unit-generic. Column names keep their spelling (``accel_mg``).
    """
    if unit == DEFAULT_UNIT:
        return text
    sensor = next(name for name, suffix in SENSOR_UNITS.items() if suffix == unit)
    text = text.replace(SECOND_INPUT[DEFAULT_UNIT], SECOND_INPUT[unit])  # not "the gyro flipped"
    text = re.sub(r"\b([Aa])n accelerometer", rf"\1 {sensor}", text)  # not "an gyro"
    return _SENSOR_WORD.sub(sensor, _UNIT_TOKEN.sub(UNIT_LABELS[unit], text))


def model_view(rec: Recording, channel: str | None, model_path: object) -> Recording:
    """The part of ``rec`` the model compensates: the recording itself (``accel_mg``) when the model
    has no channel, the recording has no channel columns or its ``accel_mg`` is the model's channel
    (metadata ``channel``: a one-axis import), else the channel's one-channel view; a missing
    channel, or a one-axis recording whose metadata names another channel, is a UserError."""
    available = recording_channels(rec)
    if channel and available and rec.meta.get("channel") != channel:
        if channel not in available:
            raise UserError(
                f"{rec.source}: no channel {channel!r} (the channel of model {model_path}); available: "
                f"{names_text(available)}"
            )
        (found,) = select_channels(rec, (channel,))
        return channel_view(rec, found)
    held = rec.meta.get("channel")
    if channel and held and held != channel:
        raise UserError(
            f"{rec.source}: its accel_mg is channel {held} (metadata channel={held}), but model {model_path} "
            f"is of {channel}: score it on a recording of {channel} (trainer import --channels {channel})"
        )
    if channel and unit_of_channel_name(channel) != channel_unit(rec):
        raise UserError(
            f"{rec.source}: no channel {channel!r} (the channel of model {model_path}); the recording holds "
            f"one channel in {channel_unit(rec)} (accel_mg)"
        )
    return rec
