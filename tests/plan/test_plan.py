"""``trainer plan``: chamber limits, the program's TOML through ``trainer simulate``, identification
against the paper's oven, priors, and one-line errors (docs/plan.md)."""

from __future__ import annotations

import json
import re
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tests.repo import REPO_ROOT
from trainer.checkpoint import save_model
from trainer.cli import main
from trainer.data.recording import Recording
from trainer.data.recording_io import read_recording, write_recording
from trainer.errors import UserError, run_cli
from trainer.fitting import fit_compensator
from trainer.greybox.compensator import PhysicsCompensator
from trainer.physics.config import load_config
from trainer.physics.effects import EffectConfig
from trainer.physics.profiles import PAPER_OVEN, SegmentSpec
from trainer.physics.simulate import simulate
from trainer.plan import outputs, priors
from trainer.plan.chamber import validation_program, violations
from trainer.plan.limits import ChamberLimits
from trainer.plan.montecarlo import DrawTask, run_draw, sensor
from trainer.plan.programs import Program, candidates
from trainer.plan.summary import Target, identified
from trainer.train_stats import TrainStats

REALISTIC = REPO_ROOT / "trainer" / "physics" / "realistic.toml"
LIMITS = (
    ChamberLimits(),
    ChamberLimits(-40.0, 85.0, 1.0, 600.0, 10 * 3600.0),
    ChamberLimits(0.0, 50.0, 3.0, 1800.0, 4 * 3600.0),
)


def _cli(*argv: str) -> int:
    return run_cli(main, list(argv))


def _setpoints(program: Program, t: np.ndarray) -> np.ndarray:
    """The set-point by hand: linear within each segment from the previous end (no library code)."""
    out = np.empty_like(t)
    clock, current = 0.0, program.start_c
    for spec in program.segments:
        inside = (t >= clock) & (t < clock + spec.duration_s)
        start = spec.end_c if spec.label in ("soak", "hold") else current
        out[inside] = start + (spec.end_c - start) * (t[inside] - clock) / spec.duration_s
        clock += spec.duration_s
        current = spec.end_c
    return out


@pytest.mark.parametrize("limits", LIMITS)
def test_every_candidate_respects_the_chamber_limits(limits: ChamberLimits) -> None:
    programs = candidates(limits)
    assert programs, "some design fits"
    assert [p.duration_s for p in programs] == sorted(p.duration_s for p in programs)
    for program in programs:
        assert not violations(program, limits), program.name
        t = np.linspace(0.0, program.duration_s, 20_001)[:-1]
        setpoint = _setpoints(program, t)
        assert limits.low_c - 1e-9 <= setpoint.min() and setpoint.max() <= limits.high_c + 1e-9
        rate = np.abs(np.diff(setpoint)) / np.diff(t) * 60.0
        assert rate.max() <= limits.max_rate_c_per_min * (1 + 1e-6)
        holds = [s.duration_s for s in program.segments if s.label in ("soak", "hold")]
        assert program.segments[0].label == "soak" and min(holds) >= limits.settling_s
        assert program.duration_s <= limits.max_duration_s


def test_violations_name_each_broken_limit() -> None:
    limits = ChamberLimits(-20.0, 70.0, 1.0, 600.0, 3600.0)
    bad = Program(
        "bad",
        -20.0,
        (
            SegmentSpec("soak", 300.0, -20.0),  # shorter than settling
            SegmentSpec("ramp_up", 60.0 * 45.0, 80.0),  # 100 degC in 45 min: 2.2 degC/min, above 70
            SegmentSpec("hold", 1200.0, 10.0),  # a set-point step
        ),
    )
    found = " | ".join(violations(bad, limits))
    for expected in (
        "shorter than the settling",
        "outside -20..70",
        "2.22222 degC/min > 1",
        "steps the set-point",
        "lasts",
    ):
        assert expected in found


def test_validation_profile_is_mapped_onto_the_chamber() -> None:
    for limits in LIMITS:
        program = validation_program(limits)
        temps = [program.start_c, *(s.end_c for s in program.segments)]
        assert min(temps) == pytest.approx(limits.low_c) and max(temps) == pytest.approx(limits.high_c)
        assert not [
            v
            for v in violations(program, replace(limits, max_duration_s=1e9, settling_s=1.0))
            if "steps" not in v
        ]


def test_program_toml_runs_through_trainer_simulate(tmp_path: Path) -> None:
    program = candidates(ChamberLimits())[0]
    base = replace(load_config(REALISTIC), channels=())
    toml = tmp_path / "program.toml"
    toml.write_text(outputs.program_toml(base, priors.bundled(), program, 1.0), encoding="utf-8")
    assert load_config(toml).protocol == program.protocol
    rec_path = tmp_path / "run.csv"
    assert _cli("simulate", "--config", str(toml), "--seed", "3", "--rate", "0.1", "-o", str(rec_path)) == 0
    rec = read_recording(rec_path)
    t = np.asarray(rec.time_s)
    assert t[-1] + 10.0 == pytest.approx(program.duration_s)
    np.testing.assert_allclose(np.asarray(rec.columns["chamber_c"]), _setpoints(program, t), atol=1e-9)
    corners = np.loadtxt(_write(tmp_path, outputs.setpoints_csv(program)), delimiter=",", skiprows=1)
    np.testing.assert_allclose(np.interp(t, corners[:, 0], corners[:, 1]), _setpoints(program, t), atol=1e-9)
    effects = set(rec.meta["effects"].split(","))
    assert {"thermal_lag", "temp_rate", "hysteresis_offset", "bias_poly"} <= effects


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "setpoints.csv"
    path.write_text(text, encoding="utf-8")
    return path


def test_priors_draw_within_their_ranges_and_from_the_seed() -> None:
    targets = priors.parse_spec("thermal_lag:tau_s=90..150,hysteresis_offset:amp_mg=2..3:width_c=40")
    draws = [priors.draw_effects(targets, np.random.default_rng(7)) for _ in range(2)]
    assert draws[0] == draws[1]
    lag, offset = draws[0]
    assert 90.0 <= lag.params["tau_s"] <= 150.0 and offset.params["width_c"] == 40.0
    assert targets[1].checked == ("amp_mg", "width_c")
    assert priors.parse_spec("temp_rate")[0].ranges == priors.BUNDLED_RUN["temp_rate"]


def test_gyroscope_priors_take_channel_names_and_the_measured_gyro_sizes() -> None:
    targets = priors.parse_spec("hysteresis_offset:amp_dps=-0.08..-0.04:width_c=20,temp_rate", unit="dps")
    offset, rate = targets
    assert offset.ranges == {"amp_mg": (-0.08, -0.04), "width_c": (20.0, 20.0)}  # held under catalogue names
    assert offset.describe() == "hysteresis_offset amp_dps -0.08..-0.04, width_c 20"
    assert rate.ranges == priors.BUNDLED_GYRO["temp_rate"] and rate.unit == "dps"
    with pytest.raises(UserError, match="has no parameter 'amp_mg'"):
        priors.parse_spec("hysteresis_offset:amp_mg=1:width_c=3", unit="dps")
    with pytest.raises(UserError, match="no measured sizes for a pa channel"):
        priors.load(None, None, "pa")


def _physics_model(path: Path, effects: list[EffectConfig], stats: TrainStats) -> None:
    model = PhysicsCompensator()
    model.effects, model.temp_range_c = tuple(effects), (-20.0, 70.0)
    save_model(model, path, train_stats=stats, valid_temp_range_c=(-20.0, 70.0))


def test_a_fitted_gyroscope_model_gives_targets_around_its_sizes_on_its_channel(tmp_path: Path) -> None:
    poly = EffectConfig(
        "bias_poly", {"c0_mg": 0.0, "c1_mg_per_c": 0.01, "c2_mg_per_c2": 3e-4, "c3_mg_per_c3": -2e-6}
    )
    offset = EffectConfig("hysteresis_offset", {"amp_mg": -0.05, "width_c": 20.0})
    lag = EffectConfig("thermal_lag", {"tau_s": 100.0})
    path = tmp_path / "gyro.pt"
    _physics_model(path, [poly, lag, offset], TrainStats(channel="gyro0_x", unit="dps"))
    fitted = priors.from_model(path)
    assert (fitted.channel, fitted.unit, fitted.bias_poly) == ("gyro0_x", "dps", poly)
    by_name = {p.identifier: p for p in fitted.priors}
    assert set(by_name) == {"thermal_lag", "hysteresis_offset"} and by_name["thermal_lag"].unit == "dps"
    np.testing.assert_allclose(by_name["thermal_lag"].ranges["tau_s"], (70.0, 130.0))
    np.testing.assert_allclose(by_name["hysteresis_offset"].ranges["amp_mg"], (-0.065, -0.035))
    np.testing.assert_allclose(by_name["hysteresis_offset"].ranges["width_c"], (14.0, 26.0))


def test_a_gyroscope_draw_puts_the_targets_in_its_channel_and_scores_it_in_deg_per_s() -> None:
    """The accelerometer's physics stays; the drawn effects replace the gyro table's, and the fit sees
    the gyro's one-channel view (so its drift left is of the order of the gyro's, not the mg's)."""
    base = load_config(REALISTIC)
    program = candidates(ChamberLimits())[0]
    targets = priors.bundled("dps")
    drawn = priors.draw_effects(targets, np.random.default_rng(1))
    cfg = sensor(base, drawn, program, 0.05, "gyro0_x")
    assert cfg.effects == base.effects and [c.name for c in cfg.channels] == ["gyro0_x"]
    table = {e.identifier: e.params for e in cfg.channels[0].effects}
    assert all(table[e.identifier] == e.params for e in drawn) and "bias_poly" in table
    result = run_draw(
        DrawTask(base, targets, program, validation_program(ChamberLimits()), 3, 0, 0.05, "gyro0_x")
    )
    gyro_span = 0.0108 * 90 + 0.00039 * 90**2  # the gyro table's cubic over the range, deg/s
    assert 0 < result.drift_left["poly3"] < gyro_span and result.drift_left["poly3"] < 1.0


def test_diagnosis_json_targets_its_ambiguous_and_unidentifiable_compensable_effects(tmp_path: Path) -> None:
    doc = {
        "ambiguous": [
            {"effects": ["stress_relaxation", "thermal_lag", "temp_rate", "warmup", "hysteresis_offset"]}
        ],
        "not_identifiable": [{"effect": "scale_factor_tc"}, {"effect": "hysteresis"}],
    }
    path = tmp_path / "d.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    targets = priors.load(str(path), None)
    # warm-up needs a power-on clock, scale_factor_tc is not temperature drift, hysteresis excludes the offset form
    assert [p.identifier for p in targets] == [
        "stress_relaxation",
        "thermal_lag",
        "temp_rate",
        "hysteresis_offset",
    ]
    assert targets[1].ranges == priors.BUNDLED_RUN["thermal_lag"]
    assert all(lo < hi for lo, hi in targets[0].ranges.values())


def test_a_gyroscope_diagnosis_plans_for_its_gyroscope_not_the_accelerometer(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    doc = {
        "channel": {"name": "gyro0_x", "unit": "dps", "label": "deg/s"},
        "ambiguous": [{"effects": ["thermal_lag", "temp_rate"]}],
        "not_identifiable": [],
    }
    path = tmp_path / "d.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    assert priors.diagnosis_channel(path) == "gyro0_x"  # the default --channel
    code = run_cli(main, ["plan", "--targets", str(path), "--channel", "accel0_z", "-o", str(tmp_path / "p")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert "--channel accel0_z but the --targets diagnosis was made on gyro0_x" in err
    assert not (tmp_path / "p").exists()
    path.write_text(json.dumps({k: v for k, v in doc.items() if k != "channel"}), encoding="utf-8")
    assert priors.diagnosis_channel(path) is None  # an accelerometer's document names none


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--effects", "bias_step:t_s=1"], "not a drift the physics compensator models"),
        (["--effects", "thermal_lag:tau_s=150..90"], "thermal_lag.tau_s range 150..90"),
        (["--effects", "thermal_lag:tau_s=-5..3"], "tau_s must be positive"),
        (["--effects", "thermal_lag:tua_s=3"], "has no parameter 'tua_s'"),
        (
            ["--effects", "hysteresis:amp_mg=1:width_c=3,hysteresis_offset:amp_mg=1:width_c=3"],
            "same physics twice",
        ),
        (["--range", "70", "-20"], "--range: high -20 must be above low 70 degC (swapped?"),
        (["--max-hours", "1"], "no candidate program fits"),
        (["--targets", "missing.toml"], "no such file"),
        (["--draws", "0"], "--draws must be >= 1"),
        (["--draws", "2", "--screen-draws", "5"], "--screen-draws 5 is more than --draws 2"),
        (["--seed", "-1"], "--seed: '-1' is not a non-negative integer"),
        (["--range", "-300", "70"], "--range: low -300 degC is outside -60 .. 150 degC"),
        (["--range", "nan", "70"], "--range: low nan degC is outside"),
        (["--max-rate", "inf"], "--max-rate must be a finite number > 0, got inf"),
        (["--channel", "gyro9_x"], "has no [channels.gyro9_x] table"),
        (["--channel", "gyro_q"], "not a channel name"),
        (["--targets", "poly3.pt"], "has no catalogue effects to plan for"),
        (["--channel", "gyro0_x", "--targets", "physics.pt"], "the --targets model's effects are in mg"),
        (["--noise-from", "baro.npz"], "--noise-from"),
    ],
)
def test_bad_input_is_one_line_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    inputs = tmp_path / "in"
    inputs.mkdir()
    if "poly3.pt" in argv:
        rec = simulate(replace(load_config(REALISTIC), channels=()), 1)
        save_model(
            fit_compensator("poly3", rec),
            inputs / "poly3.pt",
            train_stats=TrainStats(),
            valid_temp_range_c=(0.0, 1.0),
        )
    if "physics.pt" in argv:  # a reference model of a one-axis accelerometer (mg)
        shutil.copy(REPO_ROOT / "tests" / "data" / "ref" / "physics.pt", inputs / "physics.pt")
    if "baro.npz" in argv:  # a barometer's recording, for an accelerometer's plan
        temp = np.linspace(-10.0, 50.0, 600)
        columns = {"time_s": np.arange(600.0), "temp_c": temp, "baro0_pa": 101325.0 + 2.0 * temp}
        write_recording(Recording(columns, {"channel": "baro0", "unit": "pa"}, "baro"), inputs / "baro.npz")
        message = "its data are in Pa (baro0), the planned channel's in mg"
    argv = [str(inputs / a) if a in ("poly3.pt", "physics.pt", "baro.npz") else a for a in argv]
    out = tmp_path / "plan"
    assert _cli("plan", "-o", str(out), *argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and "\n" not in err and message in err, err
    assert not out.exists() and [p.name for p in tmp_path.iterdir()] == ["in"]


def test_toml_targets_errors_name_the_file(tmp_path: Path) -> None:
    path = tmp_path / "t.toml"
    path.write_text("[thermal_lag]\ntau_s = [1, 2, 3]\n", encoding="utf-8")
    with pytest.raises(UserError, match=r"t.toml: \[thermal_lag\] tau_s: expected a number or \[low, high\]"):
        priors.load(str(path), None)


@pytest.mark.slow
def test_planned_program_identifies_what_the_paper_oven_cannot() -> None:
    """One seeded draw each (0.2 Hz): the shortest design names lag, rate and branch offset within 25 %
    and leaves less than half the cubic's drift; the paper's single ramp names none of them."""
    base = replace(load_config(REALISTIC), channels=())
    limits, target = ChamberLimits(), Target()
    valid = validation_program(limits)
    planned, oven = candidates(limits)[0], Program("paper oven", *PAPER_OVEN)
    results = {
        p.name: run_draw(DrawTask(base, priors.bundled(), p, valid, 5, 0, 0.2)) for p in (planned, oven)
    }
    assert identified(results[planned.name], target) and results[planned.name].ratio <= target.vs_cubic
    assert all(e == np.inf for e in results[oven.name].error.values())
    assert results[planned.name].ratio < results[oven.name].ratio


@pytest.mark.parametrize("draws", [1, 2, 5, 20, 59])
def test_the_rate_bound_of_a_clean_sweep_is_the_rule_of_three(draws: int) -> None:
    """n of n draws identified: the one-sided 95 % Clopper-Pearson bound is 0.05**(1/n) exactly (22 % at
    2 draws, 86 % at 20, 95 % first at 59), what the report now prints beside "meets the target"."""
    from trainer.plan.summary import rate_lower_bound

    assert rate_lower_bound(draws, draws) == pytest.approx(0.05 ** (1.0 / draws), rel=1e-9)
    assert rate_lower_bound(0, draws) == 0.0
    assert rate_lower_bound(draws - 1, draws) < rate_lower_bound(draws, draws)


@pytest.mark.parametrize(("draws", "shown"), [(1, False), (2, False), (59, True)])
def test_a_target_met_in_too_few_draws_to_show_it_is_not_called_met(draws: int, shown: bool) -> None:
    """Every draw identified every effect: with 1 or 2 draws the one-sided 95 % bound (5 %, 22 %) is
    below the 95 % asked, and the verdict says so instead of "meets the target"; 59 of 59 show it."""
    from trainer.plan.design import Choice
    from trainer.plan.summary import Summary

    program = candidates(ChamberLimits())[0]
    summary = Summary(
        program.name, program.duration_s, draws, {"thermal_lag": 1.0}, {"thermal_lag": 0.01}, {}, 0.2, 0.3
    )
    choice = Choice(program, summary, ())
    target = Target()
    assert choice.met(target)  # the point estimate: every draw
    text = summary.verdict_text(target)
    assert text.startswith("meets the target") is shown, text
    assert ("too few to show the target" in text) is not shown, text
    bound = 100 * 0.05 ** (1.0 / draws)
    assert f"lower bound of {bound:.0f} %" in text, text


def test_a_plan_of_too_few_draws_says_nowhere_that_the_target_is_met(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The user's ``--draws 3 --screen-draws 2`` run, every draw identifying every effect within 1 % with
    physics at 0.2x the cubic (a stand-in runner): the point estimates reach the target, but 3 of 3
    bound the rate at 37 %. The headline, the table's target column and the candidate log, on the
    terminal (stdout, stderr) and in report.md alike, say what was measured, not that it is met."""
    from collections.abc import Iterator
    from contextlib import contextmanager

    from trainer.plan import montecarlo
    from trainer.plan.montecarlo import CUBIC, PHYSICS, DrawResult

    class Runner:
        width = 2

        def map(self, tasks: list[DrawTask], desc: str) -> list[DrawResult]:
            left = {PHYSICS: 0.2, CUBIC: 1.0}
            return [DrawResult(t.index, {}, {}, {p.identifier: 0.01 for p in t.priors}, left) for t in tasks]

    @contextmanager
    def runner(workers: int, scheduler: str | None, progress: bool) -> Iterator[Runner]:
        yield Runner()

    monkeypatch.setattr(montecarlo, "runner", runner)
    out = tmp_path / "plan"
    argv = ["-o", str(out), "--max-hours", "3", "--draws", "3", "--screen-draws", "2", "--rate", "0.2"]
    assert _cli("plan", *argv, "--no-standard", "--no-progress") == 0
    captured = capsys.readouterr()
    texts = {"stdout": captured.out, "stderr": captured.err, "report.md": (out / "report.md").read_text()}
    for where, text in texts.items():
        said_met = re.findall(r"meets the target|(?<!not )\bmet\b", text)
        assert not said_met, (where, said_met, text)
        assert "not shown, too few draws (lower bound 37 %)" in text, (where, text)  # column or log
    for where in ("stdout", "report.md"):  # the headline
        assert "3 draws, too few to show the target" in texts[where], texts[where]
        assert "identified in 100 % of them and physics left 0.20x the cubic" in texts[where]
