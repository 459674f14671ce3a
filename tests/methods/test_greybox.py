"""The physics compensator: streaming form against the catalogue's batch formula, parameter
recovery, power-on and saved state, structure selection, checkpoints and bad options."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from trainer.checkpoint import load_model, save_model
from trainer.cli import main
from trainer.errors import run_cli
from trainer.fitting import fit_compensator
from trainer.greybox.compensator import PhysicsCompensator
from trainer.greybox.stream import PhysicsModel, PhysicsStream
from trainer.physics.config import parse_config_text
from trainer.physics.effects import drift
from trainer.physics.simulate import simulate
from trainer.train_stats import TrainStats

# A short chamber cycle at 2 Hz: both branches over a common range, two ramp rates, holds.
CYCLE = """
[recording]
sample_rate_hz = 2.0
sensor = "greybox-test"
[protocol]
name = "custom"
start_c = -10.0
[[protocol.segments]]
label = "soak"
duration_s = 600.0
end_c = -10.0
[[protocol.segments]]
label = "ramp_up"
duration_s = 3600.0
end_c = 50.0
[[protocol.segments]]
label = "hold"
duration_s = 1200.0
end_c = 50.0
[[protocol.segments]]
label = "ramp_down"
duration_s = 1800.0
end_c = 0.0
[[protocol.segments]]
label = "hold"
duration_s = 900.0
end_c = 0.0
[[protocol.segments]]
label = "ramp_up"
duration_s = 1500.0
end_c = 30.0
[temperature]
case_tau_s = 150.0
temp_noise_c = 0.01
[effects.bias_poly]
c0_mg = 1.0
c1_mg_per_c = 0.15
c2_mg_per_c2 = 0.001
c3_mg_per_c3 = -5e-6
"""
NOISE = """
[noise.white_noise]
n_mg_rt_s = 0.02
"""


def config(effects: str, noise: bool = False) -> str:
    return CYCLE + effects + (NOISE if noise else "")


LAG_RATE_OFFSET = """
[effects.thermal_lag]
tau_s = 120.0
[effects.temp_rate]
k_mg_per_c_per_min = 0.3
tau_s = 60.0
[effects.hysteresis_offset]
amp_mg = 0.8
width_c = 6.0
"""
EVERY_TERM = (
    LAG_RATE_OFFSET.replace("hysteresis_offset", "hysteresis")
    + """
[effects.stress_relaxation]
gain_mg_per_c = 0.02
tau_s = 3000.0
[effects.warmup]
amp_mg = 0.5
tau_s = 300.0
"""
)


@pytest.mark.parametrize("effects", [LAG_RATE_OFFSET, EVERY_TERM], ids=["lag-rate-offset", "every-term"])
def test_stream_reproduces_the_batch_formula(effects: str) -> None:
    cfg = parse_config_text(config(effects))
    rec = simulate(cfg, 3)
    temp = rec.temp_c
    batch = drift(cfg.effects, rec.time_s - rec.time_s[0], temp).total
    model = PhysicsModel.from_effects(cfg.effects, (-100.0, 200.0))
    stream = PhysicsStream(model, 1.0 / rec.sample_rate_hz)
    streamed = np.array([stream.step(float(T)) for T in temp])
    assert np.max(np.abs(streamed - batch)) < 1e-9 * max(1.0, float(np.max(np.abs(batch))))


def test_a_saved_state_continues_exactly_and_a_cold_start_is_off_by_at_most_the_branch_amplitude() -> None:
    cfg = parse_config_text(config(LAG_RATE_OFFSET))
    rec = simulate(cfg, 4)
    model = PhysicsModel.from_effects(cfg.effects, (-100.0, 200.0))
    dt = 1.0 / rec.sample_rate_hz
    whole = PhysicsStream(model, dt)
    reference = np.array([whole.step(float(T)) for T in rec.temp_c])
    cut = len(rec) // 2
    first = PhysicsStream(model, dt)
    for T in rec.temp_c[:cut]:
        first.step(float(T))
    resumed = PhysicsStream(model, dt)
    resumed.restore(first.state)
    after = np.array([resumed.step(float(T)) for T in rec.temp_c[cut:]])
    assert np.array_equal(after, reference[cut:])
    # A cold start in the middle of the run: filters start settled, the play operator mid-branch.
    cold = PhysicsStream(model, dt)
    cold_out = np.array([cold.step(float(T)) for T in rec.temp_c[cut:]])
    settle = int(5 * 120.0 / dt)  # five lag time constants
    amp = 0.8
    filters_settled_mg = 0.05  # what is left of the rate filter's start-up after five lag constants
    assert np.max(np.abs(cold_out[settle:] - reference[cut + settle :])) <= amp + filters_settled_mg


@pytest.mark.parametrize("noisy", [False, True], ids=["noise-free", "noisy"])
def test_forced_structure_gives_back_the_parameters(noisy: bool) -> None:
    cfg = parse_config_text(config(LAG_RATE_OFFSET, noise=noisy))
    rec = simulate(cfg, 5)
    if not noisy:
        rec.columns["accel_mg"] = rec.columns["true_drift_mg"].copy()
    model = PhysicsCompensator(effects="thermal_lag,temp_rate,hysteresis_offset")
    model.fit(rec.without_truth())
    found = {e.identifier: e.params for e in model.effects}
    tolerance = 0.25 if noisy else 0.05
    for effect in cfg.effects:
        if effect.identifier == "bias_poly":
            continue
        for name, value in effect.params.items():
            assert found[effect.identifier][name] == pytest.approx(value, rel=tolerance), (
                effect.identifier,
                name,
            )
    drift_left = rec.columns["true_drift_mg"] - model.predict_drift(rec)
    assert np.sqrt(np.mean(drift_left**2)) < (0.01 if not noisy else 0.05) * np.ptp(
        rec.columns["true_drift_mg"]
    )


def test_relative_drift_leaves_the_offset_and_the_checkpoint_round_trips(tmp_path: Path) -> None:
    cfg = parse_config_text(config(LAG_RATE_OFFSET, noise=True))
    rec = simulate(cfg, 6)
    offset = 980.0  # gravity on the vertical axis
    rec.columns["accel_mg"] = rec.columns["accel_mg"] + offset
    model = fit_compensator("physics", rec, {"effects": "thermal_lag"})
    assert isinstance(model, PhysicsCompensator)
    compensated = model.compensate(rec)
    assert abs(np.mean(compensated) - offset) < 5.0  # the offset stays in the output
    path = tmp_path / "model.pt"
    save_model(model, path, train_stats=TrainStats(), valid_temp_range_c=model.temp_range_c)
    loaded, _ = load_model(path)
    assert isinstance(loaded, PhysicsCompensator)
    assert np.array_equal(loaded.predict_drift(rec), model.predict_drift(rec))


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--effects", "thermal_lag,bias_step"], "bias_step is not a drift the physics compensator models"),
        (["--effects", "thermal_lagg"], "unknown effect 'thermal_lagg'"),
        (["--effects", "hysteresis,hysteresis_offset"], "same physics twice"),
        (["--from-sim", "missing.toml"], "--from-sim: missing.toml: no such file"),
        (["--effects", "thermal_lag", "--from-sim", "a.toml"], "--effects and --from-sim both"),
    ],
)
def test_bad_structure_options_give_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    rec_path = tmp_path / "train.csv"
    from trainer.data.recording_io import write_recording

    write_recording(simulate(parse_config_text(config("", noise=True)), 1).without_truth(), rec_path)
    code = run_cli(main, ["fit", str(rec_path), "--method", "physics", *args, "-o", str(tmp_path / "m.pt")])
    err = capsys.readouterr().err.strip()
    assert code != 0 and message in err and "\n" not in err and "Traceback" not in err
    assert not (tmp_path / "m.pt").exists()


def test_auto_adds_nothing_on_a_monotone_ramp() -> None:
    ramp = CYCLE.split('[[protocol.segments]]\nlabel = "hold"')[0]  # soak and one ramp up
    cfg = parse_config_text(ramp + LAG_RATE_OFFSET.split("[effects.temp_rate]")[0] + NOISE)
    rec = simulate(cfg, 7)
    model = PhysicsCompensator().fit(rec.without_truth())
    assert [e.identifier for e in model.effects] == ["bias_poly"]


def test_auto_names_a_branch_offset_on_a_cycle() -> None:
    cfg = parse_config_text(
        config(
            LAG_RATE_OFFSET.split("[effects.thermal_lag]")[0]
            + """
[effects.hysteresis_offset]
amp_mg = 0.8
width_c = 6.0
""",
            noise=True,
        )
    )
    rec = simulate(replace(cfg, effects=tuple(e for e in cfg.effects if e.identifier != "temp_rate")), 8)
    model = PhysicsCompensator().fit(rec.without_truth())
    assert {e.identifier for e in model.effects} == {"bias_poly", "hysteresis_offset"}


@pytest.mark.parametrize("seed", [2, 3, 7])
def test_auto_adds_nothing_on_the_finders_clean_bench_recordings(seed: int) -> None:
    """Clean chamber cycles (white noise, flicker and a random walk, no temperature-history effect):
    the cross-validated stage alone added a term on these three; the noise-model test stops it."""
    from trainer.diagnose.scenarios import make_scenario

    rec = make_scenario([], seed).recording()
    model = PhysicsCompensator().fit(rec.without_truth())
    assert [e.identifier for e in model.effects] == ["bias_poly"]
