"""Gyroscope and barometer channels: the catalogue's physics in the channel's own unit.

A simulated gyroscope channel (``[channels.gyro0_x]``) conceals a lag, a rate term and a branch
offset of the size measured on the bundled real run's gyro x; the finder must name each with its
parameters (in deg/s, named ``*_dps``) within 25 % of the simulator's, and the physics compensator
built from its augmented TOML must leave at most half the cubic's drift on another profile.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from trainer.baselines.poly3 import CubicPolynomial
from trainer.cli import main as trainer_main
from trainer.data.channels import channel_view, select_channels
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.diagnose import diagnose
from trainer.diagnose.blocks import build_blocks
from trainer.diagnose.document import document
from trainer.errors import UserError
from trainer.greybox.compensator import PhysicsCompensator
from trainer.physics.catalogue.temp_rate import FREED_MAX_S, freed_max_s
from trainer.physics.catalogue.units import channel_param_name
from trainer.physics.config import PhysicsConfig, load_config, parse_config_text, save_config, with_overrides
from trainer.physics.simulate import simulate

TOLERANCE = 0.25
BLOCKS = 300  # half the finder's default: the test runs in seconds; the finder is the same

# Real gyro x: k about -0.12 deg/s per degC/min, branch offsets near 0.05-0.3 deg/s, white
# 0.0099 deg/s/sqrt(Hz); a lag of 120 s (none resolved there) so that all three terms show.
GYRO_TOML = """
[recording]
sample_rate_hz = 1.0
[protocol]
name = "realistic-train"
[effects.bias_poly]
c1_mg_per_c = 0.1
[noise.white_noise]
n_mg_rt_s = 0.24
[channels.gyro0_x.effects.bias_poly]
c1_dps_per_c = 0.011
c2_dps_per_c2 = 0.0004
c3_dps_per_c3 = -2.4e-6
[channels.gyro0_x.effects.thermal_lag]
tau_s = 120.0
[channels.gyro0_x.effects.temp_rate]
k_dps_per_c_per_min = -0.12
[channels.gyro0_x.effects.hysteresis_offset]
amp_dps = -0.1
width_c = 30.0
[channels.gyro0_x.noise.white_noise]
n_dps_rt_s = 0.01
[channels.gyro0_x.noise.rate_random_walk]
k_dps_per_rt_s = 2e-5
"""
CONCEALED = ("thermal_lag", "temp_rate", "hysteresis_offset")


def _view(rec: Recording, name: str) -> Recording:
    return channel_view(rec, select_channels(rec, (name,))[0])


def _drift_left_rms(view: Recording, compensated: np.ndarray) -> float:
    """RMS of the true drift the compensated output still holds, about its mean (an offset is not drift)."""
    truth = view.truth("drift_mg")
    assert truth is not None, "the channel's own ground truth reaches its view"
    left = truth - (view.accel_mg - compensated)
    return float(np.sqrt(np.mean((left - left.mean()) ** 2)))


@pytest.fixture(scope="module")
def gyro_config() -> PhysicsConfig:
    return parse_config_text(GYRO_TOML, "gyro.toml")


def test_diagnose_names_the_concealed_gyro_physics_and_physics_halves_the_cubics_drift(
    gyro_config: PhysicsConfig, tmp_path: Path
) -> None:
    train = _view(simulate(gyro_config, 5), "gyro0_x")
    truth = {e.identifier: e.params for e in gyro_config.channels[0].effects}
    result = diagnose(train, holdout_fraction=0.0, max_blocks=BLOCKS)
    doc = document(result)
    assert doc["channel"]["unit"] == "dps"
    named = {e["effect"]: e["params"] for e in doc["left_out"]}
    assert set(CONCEALED) <= set(named), f"named {sorted(named)}"
    for identifier in CONCEALED:
        for name, true in truth[identifier].items():
            if true == 0.0:
                continue  # temp_rate's tau_s: the instantaneous rate, not a fitted value
            got = named[identifier][channel_param_name(name, "dps")]
            assert abs(got - true) <= TOLERANCE * abs(true), f"{identifier}.{name}: {got:.4g} vs {true:.4g}"

    augmented = tmp_path / "augmented.toml"
    save_config(result.augmented, augmented)
    assert "[channels.gyro0_x.effects.temp_rate]" in augmented.read_text()
    physics = PhysicsCompensator(from_sim=str(augmented)).fit(train.without_truth())
    cubic = CubicPolynomial().fit(train.without_truth())
    valid_cfg = with_overrides(gyro_config, protocol="realistic-valid")
    valid = _view(simulate(valid_cfg, 6), "gyro0_x")
    blind = valid.without_truth()
    left_physics = _drift_left_rms(valid, physics.compensate(blind))
    left_cubic = _drift_left_rms(valid, cubic.compensate(blind))
    assert left_physics <= 0.5 * left_cubic, f"physics {left_physics:.4g} vs cubic {left_cubic:.4g} deg/s"


REALISTIC = Path(__file__).resolve().parents[2] / "trainer" / "physics" / "realistic.toml"


def test_the_realistic_gyroscopes_rate_term_through_330_s_is_named_with_its_filter() -> None:
    """The main job's realistic gyroscope: a rate term through a 330 s filter beside a 60 s lag and a
    branch offset. Its holds after ramps (17-25 min) show the filtered rate decaying, so the finder
    searches the filter that far and names all three within 25 % (with the 120 s cap of a run without
    holds it named an implausible creep in the rate term's place)."""
    config = load_config(REALISTIC)
    rec = simulate(config, 11)  # the main job's realistic training run
    data = build_blocks(_view(rec, "gyro0_x").without_truth())
    assert freed_max_s(data.hold_after_ramp_s) > 1.25 * 330.0
    truth = {e.identifier: e.params for e in config.channels[0].effects}
    doc = document(diagnose(_view(rec, "gyro0_x"), holdout_fraction=0.0, max_blocks=BLOCKS))
    named = {e["effect"]: e["params"] for e in doc["left_out"]}
    assert set(CONCEALED) <= set(named), f"named {sorted(named)}"
    for identifier in CONCEALED:
        for name, true in truth[identifier].items():
            got = named[identifier][channel_param_name(name, "dps")]
            assert abs(got - true) <= TOLERANCE * abs(true), f"{identifier}.{name}: {got:.4g} vs {true:.4g}"


def test_without_a_hold_after_a_ramp_the_rate_filter_search_keeps_its_cap() -> None:
    """A run of continuous ramps (the bundled real run's kind) cannot tell a long rate filter from its
    own loop: the finder's freed filter stops at FREED_MAX_S there."""
    t = np.arange(0.0, 4200.0, 0.5)
    temp = 50.0 - 70.0 * np.abs((t / 1400.0) % 2.0 - 1.0)  # down, up, down at 3 degC/min: no hold
    noise = np.random.default_rng(3).normal(0.0, 0.01, t.size)
    data = build_blocks(Recording({"time_s": t, "temp_c": temp, "accel_mg": noise}, {}, "triangle"))
    assert data.hold_after_ramp_s == 0.0
    assert freed_max_s(data.hold_after_ramp_s) == FREED_MAX_S


def _cli_json(rec: Recording, channel: str, tmp_path: Path) -> dict:
    path = tmp_path / "rec.npz"
    write_recording(rec, path)
    assert trainer_main(["diagnose", str(path), "--channels", channel, "--holdout", "0",
                         "--json", str(tmp_path / "d.json")]) == 0  # fmt: skip
    return json.loads((tmp_path / f"d.{channel}.json").read_text())


def _one_loop(channel: str, unit: str, c0: float, c1: float, amp: float, n: float) -> PhysicsConfig:
    """A channel with a cubic and a branch offset, parameters named in its unit; a 40 min cycle
    at 0.2 Hz (a few seconds to diagnose)."""
    name = lambda catalogue: channel_param_name(catalogue, unit)  # noqa: E731
    toml = f"""
[recording]
sample_rate_hz = 1.0
[protocol]
name = "realistic-train"
[channels.{channel}.effects.bias_poly]
{name("c0_mg")} = {c0}
{name("c1_mg_per_c")} = {c1}
{name("c2_mg_per_c2")} = {c1 / 100}
[channels.{channel}.effects.hysteresis_offset]
{name("amp_mg")} = {amp}
width_c = 30.0
[channels.{channel}.noise.white_noise]
{name("n_mg_rt_s")} = {n}
"""
    return with_overrides(parse_config_text(toml, "loop.toml"), duration_s=2400.0, sample_rate_hz=0.2)


def test_a_deg_per_s_diagnosis_json_names_parameters_in_dps(tmp_path: Path) -> None:
    doc = _cli_json(simulate(_one_loop("gyro0_x", "dps", 0.5, 0.011, 0.1, 0.01), 7), "gyro0_x", tmp_path)
    assert doc["channel"] == {
        "name": "gyro0_x",
        "unit": "dps",
        "label": "deg/s",
        "cubic_drift_span": doc["channel"]["cubic_drift_span"],
    }
    text = json.dumps(doc)
    assert '"c1_dps_per_c"' in text and '"n_dps_rt_s"' in text and "_mg" not in text
    assert set(doc["baseline_calibrated"]["bias_poly"]) == {
        "c0_dps",
        "c1_dps_per_c",
        "c2_dps_per_c2",
        "c3_dps_per_c3",
    }
    named = {e["effect"]: e["params"] for e in doc["left_out"]}
    assert abs(named["hysteresis_offset"]["amp_dps"] - 0.1) <= TOLERANCE * 0.1


def test_a_pascal_channel_is_diagnosed_in_pa_with_ranges_from_its_own_drift(tmp_path: Path) -> None:
    # the simulator reads the standard atmosphere as a barometer's true input: c0 is its offset only
    doc = _cli_json(simulate(_one_loop("baro0", "pa", -20.0, 1.5, 6.0, 0.5), 8), "baro0", tmp_path)
    assert doc["channel"]["unit"] == "pa" and doc["channel"]["label"] == "Pa"
    named = {e["effect"]: e for e in doc["left_out"]}
    assert "hysteresis_offset" in named, f"named {sorted(named)}"
    entry = named["hysteresis_offset"]
    assert abs(entry["params"]["amp_pa"] - 6.0) <= TOLERANCE * 6.0
    # 6 Pa is judged against the channel's own cubic drift span (about 150 Pa), not the
    # catalogue's mg numbers: not flagged.
    assert doc["channel"]["cubic_drift_span"] > 6.0 and "flags" not in entry
    assert "_mg" not in json.dumps(doc)


def test_a_channel_table_round_trips_adds_its_column_and_leaves_accel_mg_alone(
    gyro_config: PhysicsConfig,
) -> None:
    from trainer.physics.config import config_to_toml

    assert parse_config_text(config_to_toml(gyro_config)) == gyro_config
    short = with_overrides(gyro_config, duration_s=600.0)
    with_gyro, without = simulate(short, 3), simulate(replace(short, channels=()), 3)
    assert np.array_equal(with_gyro.accel_mg, without.accel_mg)
    view = _view(with_gyro, "gyro0_x")
    noise, drift = view.truth("noise_mg"), view.truth("drift_mg")
    assert noise is not None and drift is not None
    assert np.allclose(view.accel_mg, drift + noise)


@pytest.mark.parametrize(
    ("toml", "message"),
    [
        ("[channels.gyro0_x.effects.bias_poly]\nc1_mg_per_c = 1", "unknown key 'c1_mg_per_c'"),
        ("[channels.gyro0_q.effects.bias_poly]\nc1_dps_per_c = 1", "not a channel name"),
        ("[channels.gyro0_x.effects.temp_quantization]\nlsb_c = 0.1", "shares"),
    ],
)
def test_bad_channel_tables_name_the_field(toml: str, message: str) -> None:
    with pytest.raises(UserError, match=message) as info:
        parse_config_text(toml, "cfg.toml")
    assert str(info.value).startswith("cfg.toml: [channels.")
