"""Physics configuration: TOML in, validated frozen dataclasses out, and back to TOML.

Every user mistake (unknown table or key, wrong type, out-of-range value) is a one-line
:class:`~trainer.errors.UserError` naming the file and the field, because a typo that passed
silently would simulate different physics from the one the user wrote down. ``load_config`` and
``save_config`` round-trip exactly: ``load_config(p) == cfg`` after ``save_config(cfg, p)``.
"""

from __future__ import annotations

import hashlib
import io
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

import tomli_w

from trainer.data.channels import sort_key
from trainer.data.flightlog import parse_channel
from trainer.errors import SWAPPED_HINT, UserError, atomic_output
from trainer.fields import TableFields, parse_toml, show
from trainer.physics.catalogue import EFFECT_PARAMETERS, EFFECTS, MULTI_INSTANCE, NOISE_PARAMETERS, excluded
from trainer.physics.catalogue.base import Param
from trainer.physics.catalogue.units import CATALOGUE_UNIT, channel_param_name
from trainer.physics.effects import EffectConfig
from trainer.physics.profiles import BUILTIN_PROTOCOLS, PROTOCOL_NAMES, SEGMENT_LABELS, SegmentSpec

INPUT_KINDS: tuple[str, ...] = ("zero", "constant", "steps", "motion")
DEFAULT_CONFIG_NAME = "default.toml"


@dataclass(frozen=True)
class RecordingConfig:
    """Sampling and labelling. ``duration_s`` (optional) time-compresses the protocol to it."""

    sample_rate_hz: float = 200.0
    sensor: str = "sim-tactical-accel-x"
    duration_s: float | None = None


@dataclass(frozen=True)
class ProtocolConfig:
    """``paper-oven``/``extended`` are built in; ``custom`` carries ``start_c`` and ``segments``."""

    name: str = "paper-oven"
    start_c: float | None = None
    segments: tuple[SegmentSpec, ...] = ()

    def resolved(self) -> tuple[float, tuple[SegmentSpec, ...]]:
        """``(start_c, segments)`` of this protocol, built-in or custom."""
        if self.name in BUILTIN_PROTOCOLS:
            return BUILTIN_PROTOCOLS[self.name]
        assert self.start_c is not None
        return self.start_c, self.segments


@dataclass(frozen=True)
class TemperatureConfig:
    """Package thermal time constant and thermometer white noise (1-sigma per sample)."""

    case_tau_s: float = 180.0
    temp_noise_c: float = 0.03


@dataclass(frozen=True)
class Tone:
    """One sinusoid of a ``motion`` input."""

    amp_mg: float
    freq_hz: float
    phase_rad: float = 0.0


@dataclass(frozen=True)
class InputConfig:
    """The true input ``g_in_mg``; only the fields of ``kind`` are meaningful (and written)."""

    kind: str = "zero"
    value_mg: float = 0.0
    steps: tuple[tuple[float, float], ...] = ()
    offset_mg: float = 0.0
    tones: tuple[Tone, ...] = ()
    singer_sigma_mg: float = 0.0
    singer_tau_s: float | None = None


@dataclass(frozen=True)
class NoiseConfig:
    """One noise term: a catalogue identifier and its coefficient."""

    identifier: str
    params: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class ChannelConfig:
    """A further output channel (a gyroscope axis, a barometer) beside ``accel_mg``.

    It shares the recording's temperature chain (``T_die``, ``temp_c``) and has its own effects
    and noise in its own unit, written in the TOML with the channel's parameter names
    (``amp_dps``) and held here with the catalogue's (``amp_mg``), so that one formula
    (:func:`trainer.physics.effects.drift`) serves every channel. Its true input is a static
    chamber test's (:data:`trainer.physics.simulate.STATIC_INPUT`).
    """

    name: str  # gyro0_x, baro0: the recording format's channel name
    effects: tuple[EffectConfig, ...] = ()
    noise: tuple[NoiseConfig, ...] = ()

    @property
    def unit(self) -> str:
        parsed = parse_channel(self.name)
        assert parsed is not None, "a ChannelConfig is only built from a channel name"
        return parsed.unit

    @property
    def column(self) -> str:
        return f"{self.name}_{self.unit}"


@dataclass(frozen=True)
class PhysicsConfig:
    """Everything the simulator needs besides the seed. An effect is on iff it is listed."""

    recording: RecordingConfig = RecordingConfig()
    protocol: ProtocolConfig = ProtocolConfig()
    temperature: TemperatureConfig = TemperatureConfig()
    input: InputConfig = InputConfig()
    effects: tuple[EffectConfig, ...] = ()
    noise: tuple[NoiseConfig, ...] = ()
    channels: tuple[ChannelConfig, ...] = ()  # further output channels, each in its own unit
    source: str = field(default="<memory>", compare=False)

    def effect_instances(self, identifier: str) -> list[EffectConfig]:
        return [e for e in self.effects if e.identifier == identifier]

    def noise_term(self, identifier: str) -> NoiseConfig | None:
        return next((n for n in self.noise if n.identifier == identifier), None)

    def for_channel(self, name: str | None, unit: str) -> PhysicsConfig:
        """The physics of one channel as a one-channel configuration (its effects and noise at the
        top level), for the one-channel code that reads a recording's ``accel_mg`` view.

        A channel with a ``[channels.<name>]`` table gets that table; an mg channel without one the
        top-level physics (an accelerometer axis, as before); another unit without one is refused:
        the top-level physics is in mg.
        """
        own = next((c for c in self.channels if c.name == name), None)
        if own is not None:
            return replace(self, effects=own.effects, noise=own.noise, channels=())
        if unit == CATALOGUE_UNIT:
            return self
        raise UserError(
            f"{self.source}: no [channels.{name}] table: its [effects] and [noise] are the accelerometer's "
            f"(mg), not {name}'s ({unit})"
        )

    def with_channel(self, channel: ChannelConfig) -> PhysicsConfig:
        """This configuration with ``channel``'s table set (added or replaced)."""
        others = tuple(c for c in self.channels if c.name != channel.name)
        return replace(self, channels=tuple(sorted((*others, channel), key=lambda c: sort_key(c.name))))


# ----------------------------------------------------------------------------------- reading


def _read_params(table: TableFields, spec: tuple[Param, ...], unit: str = CATALOGUE_UNIT) -> dict[str, float]:
    """The parameters of one table, as the channel of ``unit`` names them, under catalogue names."""
    named = tuple(replace(p, name=channel_param_name(p.name, unit)) for p in spec)
    table.only(tuple(p.name for p in named))
    params: dict[str, float] = {}
    for param, catalogue_param in zip(named, spec, strict=True):
        if table.has(param.name) or not param.optional:
            params[catalogue_param.name] = table.number(param.name, param.rule, param.default)
    table.finish(tuple(p.name for p in named))
    return params


def _read_recording(source: str, data: Any) -> RecordingConfig:
    table = TableFields(source, data, "recording")
    table.only(("sample_rate_hz", "sensor", "duration_s"))
    sensor = table.string("sensor", default=RecordingConfig.sensor)
    if not sensor.strip() or any(c in sensor for c in "\r\n"):
        table.fail(f"sensor must be a non-empty single line, got {sensor!r}")
    duration = table.number("duration_s", "positive") if table.has("duration_s") else None
    cfg = RecordingConfig(
        table.number("sample_rate_hz", "positive", RecordingConfig.sample_rate_hz), sensor, duration
    )
    table.finish()
    return cfg


def _read_segment(source: str, index: int, data: Any, current_c: float) -> SegmentSpec:
    table = TableFields(source, data, f"protocol.segments #{index + 1}")
    label = table.string("label", SEGMENT_LABELS)
    keys = ("label", "duration_s", "rate_c_per_min", "end_c")
    table.only(keys)
    if label in ("soak", "hold"):
        duration = table.number("duration_s", "positive")
        end_c = table.number("end_c", default=current_c)
        if table.has("rate_c_per_min"):
            table.fail(f"rate_c_per_min is only for ramps, not {label}")
        table.finish(keys)
        return SegmentSpec(label, duration, end_c)
    end_c = table.number("end_c")
    if (end_c > current_c) != (label == "ramp_up") or end_c == current_c:
        direction = "above" if label == "ramp_up" else "below"
        table.fail(f"{label} end_c must be {direction} the previous set-point {current_c:g}, got {end_c:g}")
    if table.has("duration_s") == table.has("rate_c_per_min"):
        table.fail("give exactly one of duration_s and rate_c_per_min")
    if table.has("duration_s"):
        duration = table.number("duration_s", "positive")
    else:
        duration = abs(end_c - current_c) / table.number("rate_c_per_min", "positive") * 60.0
    table.finish(keys)
    return SegmentSpec(label, duration, end_c)


def _read_protocol(source: str, data: Any) -> ProtocolConfig:
    table = TableFields(source, data, "protocol")
    table.only(("name", "start_c", "segments"))
    name = table.string("name", PROTOCOL_NAMES, default=ProtocolConfig.name)
    if name != "custom":
        for key in ("start_c", "segments"):
            if table.has(key):
                table.fail(f"{key} is only allowed with name = 'custom', not {name!r}")
        table.finish(("name",))
        return ProtocolConfig(name)
    start_c = table.number("start_c")
    raw = table.raw("segments") if table.has("segments") else None
    if not isinstance(raw, list) or not raw:
        table.fail("custom protocol needs at least one [[protocol.segments]] table")
    segments: list[SegmentSpec] = []
    current = start_c
    for index, item in enumerate(raw):
        segment = _read_segment(source, index, item, current)
        segments.append(segment)
        current = segment.end_c
    table.finish(("name", "start_c", "segments"))
    return ProtocolConfig(name, start_c, tuple(segments))


def _read_temperature(source: str, data: Any) -> TemperatureConfig:
    table = TableFields(source, data, "temperature")
    table.only(("case_tau_s", "temp_noise_c"))
    defaults = TemperatureConfig()
    cfg = TemperatureConfig(
        table.number("case_tau_s", "positive", defaults.case_tau_s),
        table.number("temp_noise_c", "nonnegative", defaults.temp_noise_c),
    )
    table.finish()
    return cfg


_INPUT_KEYS: dict[str, tuple[str, ...]] = {
    "zero": ("kind",),
    "constant": ("kind", "value_mg"),
    "steps": ("kind", "steps"),
    "motion": ("kind", "offset_mg", "tones", "singer_sigma_mg", "singer_tau_s"),
}


def _read_input(source: str, data: Any) -> InputConfig:
    table = TableFields(source, data, "input")
    table.only(tuple(dict.fromkeys(k for keys in _INPUT_KEYS.values() for k in keys)))
    kind = table.string("kind", INPUT_KINDS)
    for key in table.data:
        if key not in _INPUT_KEYS[kind]:
            table.fail(f"{key} is not used with kind = {kind!r} (allowed: {', '.join(_INPUT_KEYS[kind])})")
    cfg = InputConfig(kind)
    if kind == "constant":
        cfg = replace(cfg, value_mg=table.number("value_mg"))
    elif kind == "steps":
        cfg = replace(cfg, steps=_read_steps(table))
    elif kind == "motion":
        tones_raw = table.raw("tones") if table.has("tones") else []
        if not isinstance(tones_raw, list):
            table.fail("tones must be an array of tables [[input.tones]]")
        tones = []
        for index, item in enumerate(tones_raw):
            tone = TableFields(source, item, f"input.tones #{index + 1}")
            tone.only(("amp_mg", "freq_hz", "phase_rad"))
            tones.append(
                Tone(
                    tone.number("amp_mg"),
                    tone.number("freq_hz", "positive"),
                    tone.number("phase_rad", default=0.0),
                )
            )
            tone.finish(("amp_mg", "freq_hz", "phase_rad"))
        sigma = table.number("singer_sigma_mg", "nonnegative", 0.0)
        tau = table.number("singer_tau_s", "positive") if table.has("singer_tau_s") or sigma > 0 else None
        cfg = replace(
            cfg,
            offset_mg=table.number("offset_mg", default=0.0),
            tones=tuple(tones),
            singer_sigma_mg=sigma,
            singer_tau_s=tau,
        )
    table.finish(_INPUT_KEYS[kind])
    return cfg


def _read_steps(table: TableFields) -> tuple[tuple[float, float], ...]:
    raw = table.raw("steps") if table.has("steps") else None
    if not isinstance(raw, list) or not raw:
        table.fail("steps must be a non-empty array of [t_s, value_mg] pairs")
    steps: list[tuple[float, float]] = []
    for index, pair in enumerate(raw):
        item = f"steps[{index}]"
        if not isinstance(pair, list) or len(pair) != 2:
            table.fail(f"{item} must be a [t_s, value_mg] pair, got {show(pair)}")
        t_s = table.check_number(f"{item} t_s", pair[0], "nonnegative")
        value = table.check_number(f"{item} value_mg", pair[1], "finite")
        if steps and t_s <= steps[-1][0]:
            table.fail(f"{item} t_s must increase, got {t_s:g} after {steps[-1][0]:g}")
        steps.append((t_s, value))
    return tuple(steps)


def _read_terms(
    source: str,
    section: str,
    data: Any,
    registry: dict[str, tuple[Param, ...]],
    multi: frozenset[str],
    unit: str = CATALOGUE_UNIT,
) -> list[tuple[str, dict[str, float]]]:
    if not isinstance(data, dict):
        raise UserError(f"{source}: [{section}] must be a table of [{section}.<identifier>] tables")
    terms: list[tuple[str, dict[str, float]]] = []
    for identifier, body in data.items():
        if identifier not in registry:
            raise UserError(
                f"{source}: [{section}] unknown identifier {identifier!r} (known: {', '.join(registry)})"
            )
        if isinstance(body, list):
            if identifier not in multi:
                raise UserError(
                    f"{source}: [[{section}.{identifier}]] may appear only once; use [{section}.{identifier}]"
                )
            if not body:
                raise UserError(f"{source}: [{section}.{identifier}] is an empty array")
            for index, item in enumerate(body):
                where = f"{section}.{identifier} #{index + 1}"
                terms.append(
                    (identifier, _read_params(TableFields(source, item, where), registry[identifier], unit))
                )
        else:
            table = TableFields(source, body, f"{section}.{identifier}")
            terms.append((identifier, _read_params(table, registry[identifier], unit)))
    order = list(registry)
    terms.sort(key=lambda term: order.index(term[0]))  # stable: instances keep file order
    return terms


_SECTIONS = ("recording", "protocol", "temperature", "input", "effects", "noise", "channels")
_CHANNEL_SECTIONS = ("effects", "noise")


def _check_exclusions(source: str, section: str, effects: Sequence[EffectConfig]) -> None:
    names = [e.identifier for e in effects]
    for i, first in enumerate(names):
        for second in names[i + 1 :]:
            if excluded(first, second):
                raise UserError(
                    f"{source}: [{section}.{first}] and [{section}.{second}] describe the same physics twice; "
                    "keep one"
                )


def _read_channels(source: str, data: Any) -> tuple[ChannelConfig, ...]:
    """``[channels.<name>.effects.<identifier>]`` and ``[channels.<name>.noise.<identifier>]``."""
    if not isinstance(data, dict):
        raise UserError(f"{source}: [channels] must be a table of [channels.<channel>] tables")
    channels = []
    for name, body in data.items():
        parsed = parse_channel(name)
        if parsed is None:
            raise UserError(
                f"{source}: [channels.{name}] is not a channel name of the recording format "
                "(gyro0_x, accel1_z, baro0, ...)"
            )
        if not isinstance(body, dict):
            raise UserError(f"{source}: [channels.{name}] must be a table")
        for key in body:
            if key not in _CHANNEL_SECTIONS:
                raise UserError(
                    f"{source}: [channels.{name}] unknown key {key!r} (expected tables: effects, noise)"
                )
        section = f"channels.{name}.effects"
        effects = tuple(
            EffectConfig(i, p)
            for i, p in _read_terms(
                source, section, body.get("effects", {}), EFFECT_PARAMETERS, MULTI_INSTANCE, parsed.unit
            )
        )
        for effect in effects:
            definition = EFFECTS[effect.identifier]
            if definition.thermometer is not None or definition.input_param is not None:
                raise UserError(
                    f"{source}: [{section}.{effect.identifier}] acts on the recording's thermometer or true "
                    "input, which a channel shares: give it in [effects]"
                )
        _check_exclusions(source, section, effects)
        noise = tuple(
            NoiseConfig(i, p)
            for i, p in _read_terms(
                source,
                f"channels.{name}.noise",
                body.get("noise", {}),
                NOISE_PARAMETERS,
                frozenset(),
                parsed.unit,
            )
        )
        channels.append(ChannelConfig(name, effects, noise))
    return tuple(sorted(channels, key=lambda c: sort_key(c.name)))


def input_setters(effects: Sequence[EffectConfig]) -> list[tuple[EffectConfig, str]]:
    """Effect instances whose parameter sets the constant true input (``scale_factor_tc.g_in_mg``)."""
    out = []
    for effect in effects:
        name = EFFECTS[effect.identifier].input_param
        if name is not None and name in effect.params:
            out.append((effect, name))
    return out


def parse_config(data: dict[str, Any], source: str) -> PhysicsConfig:
    """Validate an already-parsed TOML document into a :class:`PhysicsConfig`."""
    for key, value in data.items():
        if key not in _SECTIONS:
            what = f"table [{key}]" if isinstance(value, dict | list) else f"top-level key {key!r}"
            raise UserError(f"{source}: unknown {what} (expected tables: {', '.join(_SECTIONS)})")
    effects = tuple(
        EffectConfig(i, p)
        for i, p in _read_terms(source, "effects", data.get("effects", {}), EFFECT_PARAMETERS, MULTI_INSTANCE)
    )
    noise = tuple(
        NoiseConfig(i, p)
        for i, p in _read_terms(source, "noise", data.get("noise", {}), NOISE_PARAMETERS, frozenset())
    )
    _check_exclusions(source, "effects", effects)
    sf_with_input = input_setters(effects)
    if sf_with_input and "input" in data:
        effect, name = sf_with_input[0]
        raise UserError(
            f"{source}: [effects.{effect.identifier}] {name} and [input] both set the true input; give only one"
        )
    return PhysicsConfig(
        recording=_read_recording(source, data.get("recording", {})),
        protocol=_read_protocol(source, data.get("protocol", {})),
        temperature=_read_temperature(source, data.get("temperature", {})),
        input=_read_input(source, data["input"]) if "input" in data else InputConfig(),
        effects=effects,
        noise=noise,
        channels=_read_channels(source, data["channels"]) if "channels" in data else (),
        source=source,
    )


def parse_config_text(text: str, source: str = "<string>") -> PhysicsConfig:
    return parse_config(parse_toml(text, source), source)


def default_config_text() -> str:
    return resources.files("trainer.physics").joinpath(DEFAULT_CONFIG_NAME).read_text(encoding="utf-8")


def load_config(path: str | Path | None = None) -> PhysicsConfig:
    """Load and validate ``path``; ``None`` loads the packaged ``default.toml``.

    A user file stands alone: sections it omits take the dataclass defaults (the same values as
    ``default.toml``), and effects or noise terms it omits are off.
    """
    if path is None:
        return parse_config_text(default_config_text(), DEFAULT_CONFIG_NAME)
    from trainer.data.recording_io import RECORDING_SUFFIXES

    swapped = f"where a physics TOML is expected ({SWAPPED_HINT})"
    if Path(path).suffix.lower() in RECORDING_SUFFIXES:
        raise UserError(f"{path}: a recording {swapped}")
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise UserError(f"{path}: cannot read config: {exc}") from None
    if zipfile.is_zipfile(io.BytesIO(data)):  # an .npz recording or a model file under another name
        raise UserError(f"{path}: a zip archive (an .npz recording or a model) {swapped}")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise UserError(f"{path}: cannot read config: {exc}") from None
    return parse_config_text(text, str(path))


# ----------------------------------------------------------------------------------- writing


def config_to_dict(cfg: PhysicsConfig) -> dict[str, Any]:
    """The TOML document of ``cfg`` (every parameter written explicitly, catalogue order)."""
    recording: dict[str, Any] = {
        "sample_rate_hz": cfg.recording.sample_rate_hz,
        "sensor": cfg.recording.sensor,
    }
    if cfg.recording.duration_s is not None:
        recording["duration_s"] = cfg.recording.duration_s
    protocol: dict[str, Any] = {"name": cfg.protocol.name}
    if cfg.protocol.name == "custom":
        protocol["start_c"] = cfg.protocol.start_c
        protocol["segments"] = [
            {"label": s.label, "duration_s": s.duration_s, "end_c": s.end_c} for s in cfg.protocol.segments
        ]
    doc: dict[str, Any] = {
        "recording": recording,
        "protocol": protocol,
        "temperature": {
            "case_tau_s": cfg.temperature.case_tau_s,
            "temp_noise_c": cfg.temperature.temp_noise_c,
        },
    }
    sf_sets_input = bool(input_setters(cfg.effects))
    if not (sf_sets_input and cfg.input.kind == "zero"):
        doc["input"] = _input_to_dict(cfg.input)
    doc.update(_terms_to_dict(cfg.effects, cfg.noise, CATALOGUE_UNIT))
    if cfg.channels:
        doc["channels"] = {c.name: _terms_to_dict(c.effects, c.noise, c.unit) for c in cfg.channels}
    return doc


def _terms_to_dict(
    effects: Sequence[EffectConfig], noise: Sequence[NoiseConfig], unit: str
) -> dict[str, Any]:
    """``effects`` and ``noise`` tables, parameters named as a channel of ``unit`` names them."""
    doc: dict[str, Any] = {}
    tables: dict[str, Any] = {}
    for effect in effects:
        params = {channel_param_name(k, unit): float(v) for k, v in effect.params.items()}
        if effect.identifier in MULTI_INSTANCE:
            tables.setdefault(effect.identifier, []).append(params)
        else:
            tables[effect.identifier] = params
    if tables:
        doc["effects"] = tables
    if noise:
        doc["noise"] = {
            n.identifier: {channel_param_name(k, unit): float(v) for k, v in n.params.items()} for n in noise
        }
    return doc


def _input_to_dict(cfg: InputConfig) -> dict[str, Any]:
    out: dict[str, Any] = {"kind": cfg.kind}
    if cfg.kind == "constant":
        out["value_mg"] = cfg.value_mg
    elif cfg.kind == "steps":
        out["steps"] = [[float(t), float(v)] for t, v in cfg.steps]
    elif cfg.kind == "motion":
        out["offset_mg"] = cfg.offset_mg
        out["singer_sigma_mg"] = cfg.singer_sigma_mg
        if cfg.singer_tau_s is not None:
            out["singer_tau_s"] = cfg.singer_tau_s
        if cfg.tones:
            out["tones"] = [
                {"amp_mg": t.amp_mg, "freq_hz": t.freq_hz, "phase_rad": t.phase_rad} for t in cfg.tones
            ]
    return out


def config_to_toml(cfg: PhysicsConfig) -> str:
    return "# mems-tdc physics configuration (docs/simulator.md)\n" + tomli_w.dumps(config_to_dict(cfg))


def config_hash(cfg: PhysicsConfig) -> str:
    """First 16 hex digits of the SHA-256 of the canonical TOML: identifies the physics used."""
    return hashlib.sha256(config_to_toml(cfg).encode("utf-8")).hexdigest()[:16]


def save_config(cfg: PhysicsConfig, path: str | Path) -> None:
    """Write ``cfg`` as TOML atomically (no partial file on failure)."""
    with atomic_output(path) as tmp:
        tmp.write_text(config_to_toml(cfg), encoding="utf-8")


def with_overrides(
    cfg: PhysicsConfig,
    *,
    protocol: str | None = None,
    duration_s: float | None = None,
    sample_rate_hz: float | None = None,
) -> PhysicsConfig:
    """Command-line overrides: a built-in protocol replaces the configured one entirely."""
    if protocol is not None:
        if protocol not in BUILTIN_PROTOCOLS:
            raise ValueError(
                f"protocol override must be one of {', '.join(BUILTIN_PROTOCOLS)}, got {protocol!r}"
            )
        cfg = replace(cfg, protocol=ProtocolConfig(protocol))
    recording = cfg.recording
    if duration_s is not None:
        recording = replace(recording, duration_s=float(duration_s))
    if sample_rate_hz is not None:
        recording = replace(recording, sample_rate_hz=float(sample_rate_hz))
    return replace(cfg, recording=recording)
