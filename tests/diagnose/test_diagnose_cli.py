"""``trainer diagnose`` end to end: the JSON contract, the report directory, the augmented simulation,
ground truth never read, and errors that are one line, exit 2 and leave nothing behind."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tests.synthetic_chamber import chamber_recording
from trainer.cli import main
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.diagnose import diagnose
from trainer.diagnose.document import document
from trainer.diagnose.scenarios import make_scenario
from trainer.errors import run_cli
from trainer.physics.config import load_config, save_config
from trainer.physics.simulate import simulate

REGION_KEYS = {"t_start_s", "t_end_s", "segment", "temp_min_c", "temp_max_c", "branch", "significance"}


def cli(*argv: str) -> int:
    return run_cli(main, list(argv))


@pytest.fixture(scope="module")
def lag_case(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A concealed thermal lag (seed formula as in the concealed suite), written as files."""
    root = tmp_path_factory.mktemp("diag")
    scenario = make_scenario(["thermal_lag"], 801, rates=(5.0,))
    rec = scenario.recording()
    write_recording(rec, root / "rec.npz")
    save_config(scenario.sim, root / "sim.toml")
    out = root / "out.json"
    report = root / "report"
    assert (
        cli(
            "diagnose",
            str(root / "rec.npz"),
            "--sim",
            str(root / "sim.toml"),
            "--json",
            str(out),
            "--report",
            str(report),
        )
        == 0
    )
    return {"root": root, "json": out, "report": report, "tau": Path(str(scenario.hidden[0].params["tau_s"]))}


def test_json_contract(lag_case: dict[str, Path]) -> None:
    doc = json.loads(lag_case["json"].read_text())
    assert doc["baseline"] == ["bias_poly", "white_noise", "bias_instability", "rate_random_walk"]
    for key in ("mismatch", "left_out", "ambiguous", "not_identifiable", "fit", "unexplained"):
        assert key in doc
    assert doc["mismatch"] and all(set(r) >= REGION_KEYS for r in doc["mismatch"])
    assert all(r["branch"] in ("heating", "cooling", "hold", "mixed") for r in doc["mismatch"])
    (entry,) = doc["left_out"]
    assert entry["effect"] == "thermal_lag" and set(entry["params"]) == {"tau_s"}
    assert entry["params"]["tau_s"] == pytest.approx(float(str(lag_case["tau"])), rel=0.25)
    assert entry["evidence"]["delta_bic_when_added"] >= 10 and entry["where"]
    assert all(set(w) >= REGION_KEYS for w in entry["where"])
    for side in ("before", "after"):
        fit = doc["fit"][side]
        assert {"rms_mg", "bic", "per_segment"} <= set(fit)
        assert all("rms_mg" in seg and "segment" in seg for seg in fit["per_segment"])
    assert doc["fit"]["after"]["bic"] < doc["fit"]["before"]["bic"]
    assert "scale_factor_tc" in {n["effect"] for n in doc["not_identifiable"]}
    assert all(n["recommended_test"] for n in doc["not_identifiable"])


def test_report_directory_and_augmented_simulation(lag_case: dict[str, Path]) -> None:
    report = lag_case["report"]
    names = {p.name for p in report.iterdir()}
    assert {
        "report.md",
        "diagnosis.json",
        "augmented.toml",
        "residual_time.png",
        "residual_temperature.png",
        "allan.png",
    } <= names
    assert not [p for p in lag_case["root"].iterdir() if p.name.startswith(".")]  # no staging left
    text = (report / "report.md").read_text()
    assert "thermal_lag" in text and "Held-out" in text
    for png in ("residual_time.png", "residual_temperature.png", "allan.png"):
        assert (report / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    augmented = load_config(report / "augmented.toml")
    assert "thermal_lag" in [e.identifier for e in augmented.effects]
    out = lag_case["root"] / "rerun.npz"
    assert (
        cli(
            "simulate",
            "--config",
            str(report / "augmented.toml"),
            "--seed",
            "3",
            "-o",
            str(out),
            "--rate",
            "1",
        )
        == 0
    )
    # rerunning the report onto the same directory replaces it
    rec = lag_case["root"] / "rec.npz"
    assert (
        cli(
            "diagnose",
            str(rec),
            "--sim",
            str(lag_case["root"] / "sim.toml"),
            "--report",
            str(report),
            "--holdout",
            "0",
        )
        == 0
    )


def test_ground_truth_is_never_read() -> None:
    scenario = make_scenario(["warmup"], 802, rates=(2.0,))
    rec = scenario.recording()
    poisoned = dict(rec.columns)
    for name in list(poisoned):
        if name.startswith("true_"):
            poisoned[name] = np.full(len(rec), 1e9)
    # 150 blocks, not 600: what is compared is whether the truth columns change anything (27 s -> a few)
    a = document(diagnose(rec, scenario.sim, holdout_fraction=0.0, max_blocks=150))
    b = document(
        diagnose(
            Recording(poisoned, dict(rec.meta), rec.source),
            scenario.sim,
            holdout_fraction=0.0,
            max_blocks=150,
        )
    )
    for doc in (a, b):
        doc.pop("seconds")
    assert [e["effect"] for e in a["left_out"]] == ["warmup"]  # a diagnosis that finds something
    assert a == b


def test_without_sim_the_baseline_is_bias_poly_and_noise(tmp_path: Path) -> None:
    cfg = replace(load_config(None), recording=replace(load_config(None).recording, sample_rate_hz=2.0))
    write_recording(simulate(cfg, 5), tmp_path / "rec.csv")
    out = tmp_path / "d.json"
    assert cli("diagnose", str(tmp_path / "rec.csv"), "--json", str(out)) == 0
    doc = json.loads(out.read_text())
    assert doc["baseline"] == ["bias_poly", "white_noise", "bias_instability", "rate_random_walk"]
    assert doc["left_out"] == []  # the default physics is exactly bias_poly plus these noise terms
    not_identifiable = {n["effect"] for n in doc["not_identifiable"]}
    assert {"hysteresis", "stress_relaxation", "scale_factor_tc"} <= not_identifiable  # one ramp up


def test_errors_are_one_line_and_leave_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "d.json"
    report = tmp_path / "rep"
    assert cli("diagnose", str(tmp_path / "missing.csv"), "--json", str(out), "--report", str(report)) == 2
    bad = tmp_path / "bad.toml"
    bad.write_text("[effects.thermal_lag]\ntau_s = -3\n")
    cfg = replace(
        load_config(None),
        recording=replace(load_config(None).recording, sample_rate_hz=1.0, duration_s=600.0),
    )
    write_recording(simulate(cfg, 1), tmp_path / "rec.npz")
    assert cli("diagnose", str(tmp_path / "rec.npz"), "--sim", str(bad), "--json", str(out)) == 2
    keep = tmp_path / "keep"
    keep.mkdir()
    (keep / "precious.txt").write_text("x")
    # refused before the analysis: the JSON it writes before the report was left behind
    assert cli("diagnose", str(tmp_path / "rec.npz"), "--report", str(keep), "--json", str(out)) == 2
    assert cli("diagnose", str(tmp_path / "rec.npz"), "--json", str(tmp_path / "no" / "d.json")) == 2
    assert cli("diagnose", str(tmp_path / "rec.npz"), "--holdout", "0.9") == 2
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(lines) == 5 and "Traceback" not in err
    assert "bad.toml" in lines[1] and "tau_s" in lines[1]
    assert not out.exists() and not report.exists() and (keep / "precious.txt").read_text() == "x"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml", "keep", "rec.npz"]


def test_a_noise_free_channel_is_refused_and_a_slow_time_base_warned(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A channel that is a polynomial of the temperature to rounding, its time in ms written as s:
    one error line (no noise to weigh evidence against), after a warning on the 0.001 Hz rate."""
    t_s = np.arange(0.0, 3600.0, 1.0)
    temp_c = 25.0 + 20.0 * np.sin(t_s / 600.0)
    columns = {"time_s": 1000.0 * t_s, "temp_c": temp_c, "accel_mg": 1.0 + 0.1 * temp_c}
    path = tmp_path / "ms.csv"
    write_recording(Recording(columns, {}, "ms"), path)
    out = tmp_path / "d.json"
    assert cli("diagnose", str(path), "--json", str(out)) == 2
    err = capsys.readouterr().err
    assert "warning:" in err and "0.001 Hz" in err and "milliseconds read as seconds" in err
    errors = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "no sensor noise" in errors[0] and "ms.csv" in errors[0]
    assert not out.exists()


def test_a_channel_that_fails_leaves_no_output_of_the_channels_before_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--channels all``: the second channel is noise-free. One error line naming the user's file
    and the channel (not the temporary one-channel view), and neither the first channel's report
    nor its JSON is left behind."""
    rng = np.random.default_rng(3)
    t_s = np.arange(0.0, 4000.0, 10.0)  # 400 samples at 0.1 Hz: 400 blocks, a third of 600's Cholesky cost
    temp_c = 25.0 + 20.0 * np.sin(t_s / 900.0)
    columns = {
        "time_s": t_s,
        "temp_c": temp_c,
        "accel0_x_mg": 1.0 + 0.1 * temp_c + 0.3 * rng.standard_normal(t_s.size),
        "accel0_y_mg": 2.0 + 0.05 * temp_c,
    }
    path = tmp_path / "two.csv"
    write_recording(Recording(columns, {"sample_rate_hz": "0.1"}, "two"), path)
    report, out = tmp_path / "rep", tmp_path / "d.json"
    assert cli("diagnose", str(path), "--channels", "all", "--report", str(report), "--json", str(out)) == 2
    errors = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and f"{path} (channel accel0_y)" in errors[0] and "no sensor noise" in errors[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["two.csv"]


@pytest.mark.slow
def test_real_chamber_run(real_run: Path) -> None:
    """The real run: the one-sample jump visible in the raw data is found where it is, and the
    augmented model predicts the held-out tail better than the polynomial."""
    from trainer.data.importer import import_foreign, options_with_preset

    rec = import_foreign(real_run, options_with_preset("tofupilot"))
    t, a = rec.time_s, rec.accel_mg
    # independent look at the raw data: the largest jump between 20-sample means 10 s apart
    means = np.convolve(a, np.ones(20) / 20, mode="valid")
    jumps = means[20:] - means[:-20]
    k = int(np.argmax(np.abs(jumps[200:-200]))) + 200
    t_jump = float(t[k + 20])
    doc = document(diagnose(rec))
    steps = [e for e in doc["left_out"] if e["effect"] == "bias_step"]
    assert any(abs(e["params"]["t_s"] - t_jump) < 15.0 for e in steps)
    assert doc["holdout"]["improvement_percent"] > 0 and doc["holdout"]["improvement_percent_ols"] > 0
    assert doc["fit"]["after"]["bic"] < doc["fit"]["before"]["bic"]


def test_a_named_noise_trend_runs_through_every_output(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A run that drifts linearly in time (3e-3 mg/s) beside its temperature cycle: the finder names
    the noise term's trend ``rate_ramp``, which is a model column, not a catalogue effect. The
    terminal summary, the report and the JSON take it (the next-steps section once raised KeyError
    on it: the bundled run's gyro z with a 600 s periodic added), and the compensator it suggests
    leaves it out: a slow wander in time is not temperature drift."""
    rec = chamber_recording([], seed=5)
    columns = dict(rec.columns)
    columns["accel_mg"] = rec.accel_mg + 3e-3 * rec.time_s
    path = tmp_path / "trend.csv"
    write_recording(Recording(columns, dict(rec.meta), rec.source), path)
    out, report = tmp_path / "d.json", tmp_path / "report"
    assert cli("diagnose", str(path), "--json", str(out), "--report", str(report)) == 0
    printed = capsys.readouterr().out
    (trend,) = [e for e in json.loads(out.read_text())["left_out"] if e["effect"] == "rate_ramp"]
    assert trend["params"]["r_mg_per_s"] == pytest.approx(3e-3, rel=0.2)
    compensator = next(line for line in printed.splitlines() if line.startswith("next: physics compensator"))
    assert "rate_ramp" not in compensator
    assert "rate_ramp" in next(line for line in printed.splitlines() if "not for the compensator" in line)
    text = (report / "report.md").read_text()
    assert "rate_ramp" in text.split("## What to do next")[1]


@pytest.mark.slow  # 160 s: the search names several effects around the bump
def test_a_gyroscope_report_names_its_statistics_in_deg_per_s(tmp_path: Path) -> None:
    """A gyroscope channel (its own column, deg/s) with a local bump: the report's region lines name
    the statistics as the JSON does (``mean_residual_dps``), not ``mean_residual_mg``."""
    rec = chamber_recording([], seed=5)
    middle = rec.time_s[-1] / 2
    bump = 3.0 * np.exp(-0.5 * ((rec.time_s - middle) / 60.0) ** 2)  # a local residual, no catalogue shape
    columns = {"time_s": rec.time_s, "temp_c": rec.temp_c, "gyro0_x_dps": rec.accel_mg + bump}
    path = tmp_path / "gyro.csv"
    write_recording(Recording(columns, dict(rec.meta), rec.source), path)
    out, report = tmp_path / "d.json", tmp_path / "report"
    argv = ("diagnose", str(path), "--channels", "gyro0_x", "--json", str(out), "--report", str(report))
    assert cli(*argv) == 0
    out, report = tmp_path / "d.gyro0_x.json", report / "gyro0_x"
    document = out.read_text()
    assert "mean_residual_dps" in document and "mean_residual_mg" not in document
    text = (report / "report.md").read_text()
    assert "mean_residual_dps" in text and "mean_residual_mg" not in text


def _imu_recording(path: Path) -> Path:
    """An accelerometer and a gyroscope axis (200 samples at 0.05 Hz, a few seconds a channel) whose
    metadata name the accelerometer's channel and sensor, as ``trainer import --channels all`` writes
    them: the file's ``accel_mg`` is ``accel0_x``."""
    rng = np.random.default_rng(4)
    t_s = np.arange(0.0, 4000.0, 20.0)
    temp_c = 25.0 + 20.0 * np.sin(t_s / 900.0)
    accel = 1.0 + 0.1 * temp_c + 0.3 * rng.standard_normal(t_s.size)
    columns = {
        "time_s": t_s,
        "temp_c": temp_c,
        "accel_mg": accel,
        "accel0_x_mg": accel,
        "gyro0_x_dps": 0.2 - 0.01 * temp_c + 0.05 * rng.standard_normal(t_s.size),
    }
    meta = {"sample_rate_hz": "0.05", "sensor": "bench-accel-x", "channel": "accel0_x"}
    write_recording(Recording(columns, meta, "imu"), path)
    return path


def test_a_channels_json_is_said_on_the_terminal_and_names_its_channel(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--channels accel0_x --json d.json`` writes ``d.accel0_x.json``: the terminal says so (it said
    nothing), and the document names the channel (an accelerometer's had no ``channel``: ``null`` to
    a reader; a gyroscope's had it)."""
    path = _imu_recording(tmp_path / "imu.csv")
    out = tmp_path / "d.json"
    assert cli("diagnose", str(path), "--channels", "accel0_x", "--json", str(out), "--holdout", "0") == 0
    printed = capsys.readouterr().out.splitlines()
    written = tmp_path / "d.accel0_x.json"
    assert [line for line in printed if line.startswith("JSON written")] == [f"JSON written to {written}"]
    assert json.loads(written.read_text())["channel"] == {"name": "accel0_x", "unit": "mg", "label": "mg"}


def test_each_channels_augmented_simulation_names_its_own_sensor(tmp_path: Path) -> None:
    """The file's ``sensor`` metadata names the sensor of its ``accel_mg``, the channel its ``channel``
    metadata names (recording-format.md), and every channel view copies it: the gyroscope's
    augmented TOML said ``bench-accel-x``. It names its channel; the accelerometer keeps the file's
    name (read from a CSV's comments and an .npz's meta array)."""
    path = _imu_recording(tmp_path / "imu.csv")
    report = tmp_path / "rep"
    assert cli("diagnose", str(path), "--channels", "all", "--report", str(report), "--holdout", "0") == 0
    sensors = [
        load_config(report / name / "augmented.toml").recording.sensor for name in ("accel0_x", "gyro0_x")
    ]
    assert sensors == ["bench-accel-x", "gyro0_x"]
    npz = _imu_recording(tmp_path / "imu.npz")
    again = tmp_path / "again"
    assert cli("diagnose", str(npz), "--channels", "accel0_x", "--report", str(again), "--holdout", "0") == 0
    assert load_config(again / "accel0_x" / "augmented.toml").recording.sensor == "bench-accel-x"


def test_swapped_arguments_are_one_line_that_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A TOML given as the recording, a recording (CSV or .npz, by its suffix or, renamed, its
    contents) as --sim: one line that says the arguments look swapped, exit 2, nothing written (it
    said ``r.csv: invalid TOML (Expected '=' after a key ...)``)."""
    cfg = replace(
        load_config(None),
        recording=replace(load_config(None).recording, sample_rate_hz=1.0, duration_s=600.0),
    )
    rec = simulate(cfg, 1)
    write_recording(rec, tmp_path / "r.csv")
    write_recording(rec, tmp_path / "r.npz")
    (tmp_path / "r.data").write_bytes((tmp_path / "r.npz").read_bytes())  # an .npz under another name
    save_config(cfg, tmp_path / "u.toml")
    before = sorted(p.name for p in tmp_path.iterdir())
    outputs = ("--json", str(tmp_path / "d.json"), "--report", str(tmp_path / "rep"))
    for argv in (
        ("u.toml", "--sim", "r.csv"),
        ("u.toml", "--sim", "r.npz"),
        ("u.toml", "--sim", "r.data", "--channels", "all"),
        ("r.csv", "--sim", "r.npz"),
        ("u.toml",),
    ):
        paths = [str(tmp_path / a) if not a.startswith("--") and a != "all" else a for a in argv]
        assert cli("diagnose", *paths, *outputs) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith("error: ") and err.count("\n") == 1 and "swapped?" in err, (argv, err)
        assert "invalid TOML" not in err and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == before
