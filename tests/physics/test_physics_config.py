"""Physics configuration: defaults, exact TOML round trip, and one-line errors for bad input."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trainer.errors import UserError
from trainer.physics.catalogue import excluded
from trainer.physics.config import (
    InputConfig,
    NoiseConfig,
    PhysicsConfig,
    ProtocolConfig,
    RecordingConfig,
    TemperatureConfig,
    Tone,
    config_hash,
    load_config,
    parse_config_text,
    save_config,
    with_overrides,
)
from trainer.physics.effects import EFFECT_PARAMETERS, MULTI_INSTANCE, EffectConfig
from trainer.physics.noise import NOISE_PARAMETERS
from trainer.physics.profiles import SegmentSpec

CATALOGUE_EFFECTS = {
    "bias_poly": {"c0_mg", "c1_mg_per_c", "c2_mg_per_c2", "c3_mg_per_c3"},
    "thermal_lag": {"tau_s"},
    "temp_rate": {"k_mg_per_c_per_min", "tau_s"},
    "hysteresis": {"amp_mg", "width_c"},
    "hysteresis_offset": {"amp_mg", "width_c"},
    "stress_relaxation": {"gain_mg_per_c", "tau_s"},
    "warmup": {"amp_mg", "tau_s"},
    "periodic": {"amp_mg", "period_s", "phase_rad"},
    "bias_step": {"t_s", "step_mg"},
    "temp_quantization": {"lsb_c"},
    "scale_factor_tc": {"sf_ppm_per_c", "g_in_mg"},
}
CATALOGUE_NOISE = {
    "quantization_noise": {"q_mg"},
    "white_noise": {"n_mg_rt_s"},
    "bias_instability": {"b_mg"},
    "rate_random_walk": {"k_mg_per_rt_s"},
    "rate_ramp": {"r_mg_per_s"},
}


def write(tmp_path: Path, text: str, name: str = "cfg.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_identifiers_and_parameter_names_are_the_catalogues() -> None:
    assert {k: {p.name for p in v} for k, v in EFFECT_PARAMETERS.items()} == CATALOGUE_EFFECTS
    assert {k: {p.name for p in v} for k, v in NOISE_PARAMETERS.items()} == CATALOGUE_NOISE


# ----------------------------------------------------------------------------------- defaults


def test_default_config_matches_dataclass_defaults() -> None:
    cfg = load_config(None)
    assert cfg.recording == RecordingConfig()
    assert cfg.protocol == ProtocolConfig()
    assert cfg.temperature == TemperatureConfig()
    assert cfg.input == InputConfig()
    assert [e.identifier for e in cfg.effects] == ["bias_poly"]
    assert {n.identifier for n in cfg.noise} == {"white_noise", "bias_instability", "rate_random_walk"}


def test_default_drift_is_a_plausible_tactical_grade_curve() -> None:
    p = load_config(None).effects[0].params
    temps = np.linspace(-40.0, 80.0, 241)
    d = temps - 25.0
    bias = p["c0_mg"] + p["c1_mg_per_c"] * d + p["c2_mg_per_c2"] * d**2 + p["c3_mg_per_c3"] * d**3
    assert 1.0 <= np.ptp(bias) <= 50.0  # catalogue: drift of 1 to 50 mg over -40..80 degC
    residual = bias - np.polyval(np.polyfit(temps, bias, 1), temps)
    assert np.ptp(residual) > 0.5  # curved enough that a straight line is not the whole story


def test_a_user_file_stands_alone(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, "[effects.warmup]\namp_mg = 1.0\ntau_s = 60.0\n"))
    assert cfg.effects == (EffectConfig("warmup", {"amp_mg": 1.0, "tau_s": 60.0}),)
    assert cfg.noise == ()
    assert cfg.temperature == TemperatureConfig()


def test_parameter_defaults_are_filled_in() -> None:
    cfg = parse_config_text(
        "[effects.bias_poly]\nc1_mg_per_c = 0.1\n[effects.periodic]\namp_mg = 1\nperiod_s = 9"
    )
    assert cfg.effects[0].params == {
        "c0_mg": 0.0,
        "c1_mg_per_c": 0.1,
        "c2_mg_per_c2": 0.0,
        "c3_mg_per_c3": 0.0,
    }
    assert cfg.effects[1].params == {"amp_mg": 1.0, "period_s": 9.0, "phase_rad": 0.0}


def test_single_table_and_array_of_one_table_are_the_same() -> None:
    single = parse_config_text("[effects.periodic]\namp_mg = 1.0\nperiod_s = 60.0")
    array = parse_config_text("[[effects.periodic]]\namp_mg = 1.0\nperiod_s = 60.0")
    assert single == array


def test_custom_segments_resolve_rates_and_held_temperatures() -> None:
    cfg = parse_config_text(
        """[protocol]
name = "custom"
start_c = -20.0
[[protocol.segments]]
label = "soak"
duration_s = 600
[[protocol.segments]]
label = "ramp_up"
rate_c_per_min = 2.0
end_c = 40.0
[[protocol.segments]]
label = "hold"
duration_s = 300
end_c = 50.0
"""
    )
    assert cfg.protocol.segments == (
        SegmentSpec("soak", 600.0, -20.0),
        SegmentSpec("ramp_up", 60.0 / 2.0 * 60.0, 40.0),
        SegmentSpec("hold", 300.0, 50.0),  # a set-point step at the start of the hold
    )


# --------------------------------------------------------------------------------- round trip

EVERYTHING = """
[recording]
sample_rate_hz = 100
sensor = "unit-7"
duration_s = 900.5
[protocol]
name = "custom"
start_c = -40
[[protocol.segments]]
label = "soak"
duration_s = 1800
[[protocol.segments]]
label = "ramp_up"
rate_c_per_min = 1.5
end_c = 85
[[protocol.segments]]
label = "ramp_down"
duration_s = 3000
end_c = 25
[temperature]
case_tau_s = 240
temp_noise_c = 0.0
[input]
kind = "motion"
offset_mg = -3.5
singer_sigma_mg = 12.0
singer_tau_s = 4.0
[[input.tones]]
amp_mg = 5.0
freq_hz = 1.5
[[input.tones]]
amp_mg = 0.5
freq_hz = 12.0
phase_rad = -1.0
[effects.scale_factor_tc]
sf_ppm_per_c = 80
[[effects.periodic]]
amp_mg = 0.1
period_s = 600
[[effects.bias_step]]
t_s = 0
step_mg = 1
[[effects.periodic]]
amp_mg = 0.2
period_s = 30
phase_rad = 1
[effects.hysteresis]
amp_mg = 0.3
width_c = 8
[effects.bias_poly]
c2_mg_per_c2 = 1e-3
[effects.thermal_lag]
tau_s = 45
[effects.temp_rate]
k_mg_per_c_per_min = -0.3
[effects.stress_relaxation]
gain_mg_per_c = 0.01
tau_s = 5000
[effects.warmup]
amp_mg = 0.8
tau_s = 400
[effects.temp_quantization]
lsb_c = 0.0625
[noise.rate_ramp]
r_mg_per_s = -1e-6
[noise.quantization_noise]
q_mg = 0.001
[noise.white_noise]
n_mg_rt_s = 0.03
[noise.bias_instability]
b_mg = 0.01
[noise.rate_random_walk]
k_mg_per_rt_s = 1e-4
"""

ROUND_TRIP_TEXTS = {
    "everything": EVERYTHING,
    "steps": "[input]\nkind = 'steps'\nsteps = [[0, 0], [10.5, 1000], [20, -1000]]",
    "constant": "[input]\nkind = 'constant'\nvalue_mg = 17.25\n[effects.scale_factor_tc]\nsf_ppm_per_c = 50",
    "sf_input": "[effects.scale_factor_tc]\nsf_ppm_per_c = 50\ng_in_mg = 1000",
    "extended": "[protocol]\nname = 'extended'",
    "empty": "",
}


@pytest.mark.parametrize("name", sorted(ROUND_TRIP_TEXTS))
def test_save_then_load_gives_the_same_config(tmp_path: Path, name: str) -> None:
    cfg = parse_config_text(ROUND_TRIP_TEXTS[name], "x.toml")
    path = tmp_path / "out.toml"
    save_config(cfg, path)
    assert load_config(path) == cfg
    save_config(load_config(path), tmp_path / "again.toml")
    assert (tmp_path / "again.toml").read_text() == path.read_text()  # canonical text


def test_effects_keep_catalogue_order_and_instance_order() -> None:
    cfg = parse_config_text(EVERYTHING)
    names = [e.identifier for e in cfg.effects]
    assert names == sorted(names, key=list(CATALOGUE_EFFECTS).index)
    assert [e.params["period_s"] for e in cfg.effect_instances("periodic")] == [600.0, 30.0]


def test_default_round_trips(tmp_path: Path) -> None:
    cfg = load_config(None)
    save_config(cfg, tmp_path / "d.toml")
    assert load_config(tmp_path / "d.toml") == cfg


finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
positive = st.floats(1e-3, 1e4, allow_nan=False)


def _value(rule: str) -> st.SearchStrategy[float]:
    return {"finite": finite, "positive": positive, "nonnegative": st.floats(0.0, 1e3)}[rule]


@st.composite
def effect_strategy(draw: st.DrawFn, identifier: str) -> EffectConfig:
    params = {}
    for param in EFFECT_PARAMETERS[identifier]:
        if param.optional:
            continue  # scale_factor_tc g_in_mg is covered by the parametrised round trips
        params[param.name] = draw(_value(param.rule))
    return EffectConfig(identifier, params)


@st.composite
def config_strategy(draw: st.DrawFn) -> PhysicsConfig:
    effects: list[EffectConfig] = []
    for identifier in EFFECT_PARAMETERS:
        if any(excluded(identifier, e.identifier) for e in effects):
            continue  # the same physics twice is refused (tested on its own)
        count = draw(st.integers(0, 2 if identifier in MULTI_INSTANCE else 1))
        effects += [draw(effect_strategy(identifier)) for _ in range(count)]
    noise = []
    for identifier, spec in NOISE_PARAMETERS.items():
        if draw(st.booleans()):
            noise.append(NoiseConfig(identifier, {p.name: draw(_value(p.rule)) for p in spec}))
    kind = draw(st.sampled_from(["zero", "constant", "steps", "motion"]))
    inp = InputConfig(kind)
    if kind == "constant":
        inp = InputConfig(kind, value_mg=draw(finite))
    elif kind == "steps":
        times = sorted(set(draw(st.lists(st.floats(0, 1e4), min_size=1, max_size=4))))
        inp = InputConfig(kind, steps=tuple((t, draw(finite)) for t in times))
    elif kind == "motion":
        tones = tuple(
            Tone(draw(finite), draw(positive), draw(finite)) for _ in range(draw(st.integers(0, 2)))
        )
        sigma = draw(st.floats(0.0, 100.0))
        tau = draw(positive) if sigma > 0 or draw(st.booleans()) else None
        inp = InputConfig(kind, offset_mg=draw(finite), tones=tones, singer_sigma_mg=sigma, singer_tau_s=tau)
    name = draw(st.sampled_from(["paper-oven", "extended", "custom"]))
    protocol = ProtocolConfig(name)
    if name == "custom":
        start = draw(st.floats(-60, 100))
        segments, current = [], start
        for label in draw(
            st.lists(st.sampled_from(["soak", "ramp_up", "hold", "ramp_down"]), min_size=1, max_size=5)
        ):
            if label in ("soak", "hold"):
                current = draw(st.floats(-60, 100))
            else:
                current += draw(st.floats(0.5, 50)) * (1 if label == "ramp_up" else -1)
            segments.append(SegmentSpec(label, draw(positive), current))
        protocol = ProtocolConfig(name, start, tuple(segments))
    duration = draw(st.none() | positive)
    return PhysicsConfig(
        recording=RecordingConfig(draw(positive), draw(st.sampled_from(["a", "GNC x-axis #2"])), duration),
        protocol=protocol,
        temperature=TemperatureConfig(draw(positive), draw(st.floats(0, 1))),
        input=inp,
        effects=tuple(effects),
        noise=tuple(noise),
    )


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cfg=config_strategy())
def test_round_trip_property(tmp_path: Path, cfg: PhysicsConfig) -> None:
    path = tmp_path / "prop.toml"
    save_config(cfg, path)
    assert load_config(path) == cfg


# ------------------------------------------------------------------------------ hash/overrides


def test_config_hash_identifies_the_physics() -> None:
    a = parse_config_text("[effects.warmup]\namp_mg = 1\ntau_s = 60", "a.toml")
    b = parse_config_text("[effects.warmup]\namp_mg = 1.0\ntau_s = 60.0", "b.toml")
    c = parse_config_text("[effects.warmup]\namp_mg = 1.5\ntau_s = 60.0", "c.toml")
    assert config_hash(a) == config_hash(b) != config_hash(c)
    assert len(config_hash(a)) == 16 and int(config_hash(a), 16) >= 0


def test_overrides() -> None:
    cfg = parse_config_text(EVERYTHING)
    out = with_overrides(cfg, protocol="paper-oven", duration_s=60.0, sample_rate_hz=5.0)
    assert out.protocol == ProtocolConfig("paper-oven")
    assert (out.recording.duration_s, out.recording.sample_rate_hz) == (60.0, 5.0)
    assert out.effects == cfg.effects and out.recording.sensor == "unit-7"
    assert with_overrides(cfg) == cfg


# ------------------------------------------------------------------------------------- errors

CUSTOM_20 = "[protocol]\nname = 'custom'\nstart_c = 20\n[[protocol.segments]]\n"
BAD = [
    ("[effects.thermal_lag]\ntau_s = -3", "cfg.toml: [effects.thermal_lag] tau_s must be > 0, got -3"),
    ("[effect.bias_poly]\nc0_mg = 1", "cfg.toml: unknown table [effect]"),
    ("seed = 3", "cfg.toml: unknown top-level key 'seed'"),
    ("[effects.thermal_lagg]\ntau_s = 3", "cfg.toml: [effects] unknown identifier 'thermal_lagg'"),
    ("[effects.warmup]\namp_mg = 1\ntau = 3", "cfg.toml: [effects.warmup] unknown key 'tau'"),
    ("[effects.warmup]\namp_mg = 1", "cfg.toml: [effects.warmup] missing tau_s"),
    ("[effects.warmup]\namp_mg = 1\ntau_s = '3'", "[effects.warmup] tau_s must be a number, got '3'"),
    ("[effects.warmup]\namp_mg = true\ntau_s = 3", "[effects.warmup] amp_mg must be a number, got True"),
    ("[effects.warmup]\namp_mg = nan\ntau_s = 3", "[effects.warmup] amp_mg must be finite, got nan"),
    ("[[effects.thermal_lag]]\ntau_s = 3", "[[effects.thermal_lag]] may appear only once"),
    ("effects = 3", "cfg.toml: [effects] must be a table"),
    (
        "[[effects.periodic]]\namp_mg = 1\nperiod_s = 5\n[[effects.periodic]]\namp_mg = 1\nperiod_s = 0",
        "[effects.periodic #2] period_s must be > 0, got 0",
    ),
    ("[effects.bias_step]\nt_s = -1\nstep_mg = 1", "[effects.bias_step] t_s must be >= 0, got -1"),
    ("[noise.white_noise]\nn_mg_rt_s = -1", "cfg.toml: [noise.white_noise] n_mg_rt_s must be >= 0, got -1"),
    ("[noise.pink_noise]\nx = 1", "cfg.toml: [noise] unknown identifier 'pink_noise'"),
    ("[[noise.white_noise]]\nn_mg_rt_s = 1", "[[noise.white_noise]] may appear only once"),
    ("[recording]\nsample_rate_hz = 0", "cfg.toml: [recording] sample_rate_hz must be > 0, got 0"),
    ("[recording]\nrate_hz = 10", "cfg.toml: [recording] unknown key 'rate_hz'"),
    ("[recording]\nsensor = ''", "[recording] sensor must be a non-empty single line"),
    ("[temperature]\ncase_tau = 3", "cfg.toml: [temperature] unknown key 'case_tau'"),
    ("[temperature]\ncase_tau_s = 0", "[temperature] case_tau_s must be > 0, got 0"),
    (
        "[protocol]\nname = 'oven'",
        "[protocol] name must be one of paper-oven, extended, realistic-train, realistic-valid, custom, got 'oven'",
    ),
    (
        "[protocol]\nname = 'paper-oven'\nstart_c = 3",
        "[protocol] start_c is only allowed with name = 'custom'",
    ),
    ("[protocol]\nname = 'custom'\nstart_c = 3", "[protocol] custom protocol needs at least one"),
    (
        "[protocol]\nname = 'custom'\n[[protocol.segments]]\nlabel = 'soak'\nduration_s = 5",
        "[protocol] missing start_c",
    ),
    (
        CUSTOM_20 + "label = 'ramp_up'\nend_c = 10\nduration_s = 5",
        "[protocol.segments #1] ramp_up end_c must be above the previous set-point 20, got 10",
    ),
    (
        "[protocol]\nname = 'custom'\nstart_c = 20\n[[protocol.segments]]\nlabel = 'ramp_down'\nend_c = 10",
        "[protocol.segments #1] give exactly one of duration_s and rate_c_per_min",
    ),
    (
        "[protocol]\nname = 'custom'\nstart_c = 20\n[[protocol.segments]]\nlabel = 'cool'\nduration_s = 5",
        "[protocol.segments #1] label must be one of soak, ramp_up, hold, ramp_down, got 'cool'",
    ),
    (
        CUSTOM_20 + "label = 'soak'\nduration_s = 5\nrate_c_per_min = 1",
        "[protocol.segments #1] rate_c_per_min is only for ramps, not soak",
    ),
    (
        "[input]\nkind = 'sine'",
        "cfg.toml: [input] kind must be one of zero, constant, steps, motion, got 'sine'",
    ),
    ("[input]\nvalue_mg = 3", "cfg.toml: [input] missing kind"),
    (
        "[input]\nkind = 'constant'\nvalue_mg = 1\nsteps = [[0, 1]]",
        "[input] steps is not used with kind = 'constant'",
    ),
    ("[input]\nkind = 'constant'\nvalu_mg = 1", "[input] unknown key 'valu_mg'"),
    ("[input]\nkind = 'zero'\nvalu_mg = 1", "[input] unknown key 'valu_mg'"),
    (
        "[input]\nkind = 'steps'\nsteps = [[5, 1], [5, 2]]",
        "[input] steps[1] t_s must increase, got 5 after 5",
    ),
    ("[input]\nkind = 'steps'\nsteps = [[5, 1, 3]]", "[input] steps[0] must be a [t_s, value_mg] pair"),
    ("[input]\nkind = 'motion'\ntones = 3", "[input] tones must be an array of tables"),
    ("[input]\nkind = 'motion'\nsinger_sigma_mg = 3", "[input] missing singer_tau_s"),
    (
        "[input]\nkind = 'motion'\n[[input.tones]]\namp_mg = 1\nfreq_hz = -2",
        "[input.tones #1] freq_hz must be > 0",
    ),
    (
        "[input]\nkind = 'constant'\nvalue_mg = 1\n[effects.scale_factor_tc]\nsf_ppm_per_c = 1\ng_in_mg = 9",
        "cfg.toml: [effects.scale_factor_tc] g_in_mg and [input] both set the true input; give only one",
    ),
    ("[effects.warmup\namp_mg = 1", "cfg.toml: invalid TOML ("),
]


@pytest.mark.parametrize(("text", "expected"), BAD)
def test_bad_config_is_a_one_line_user_error(tmp_path: Path, text: str, expected: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(UserError) as info:
        load_config(path)
    message = str(info.value)
    assert expected.replace("cfg.toml", str(path)) in message
    assert message.startswith(str(path))
    assert "\n" not in message


def test_missing_file_is_a_user_error(tmp_path: Path) -> None:
    with pytest.raises(UserError, match=r"nope\.toml: cannot read config"):
        load_config(tmp_path / "nope.toml")


def test_save_into_a_missing_directory_leaves_nothing(tmp_path: Path) -> None:
    with pytest.raises(UserError):
        save_config(load_config(None), tmp_path / "missing" / "cfg.toml")
    assert not (tmp_path / "missing").exists()


def test_rounding_free_float_text() -> None:
    cfg = parse_config_text("[effects.bias_poly]\nc3_mg_per_c3 = 4.000000000000001e-6")
    assert cfg.effects[0].params["c3_mg_per_c3"] == 4.000000000000001e-6
    assert math.isfinite(cfg.effects[0].params["c3_mg_per_c3"])


def test_effects_describing_the_same_physics_twice_are_refused(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        "[effects.hysteresis]\namp_mg = 0.1\nwidth_c = 4.0\n"
        "[effects.hysteresis_offset]\namp_mg = 0.1\nwidth_c = 4.0\n",
    )
    with pytest.raises(UserError, match=r"hysteresis.*hysteresis_offset.*same physics"):
        load_config(path)
