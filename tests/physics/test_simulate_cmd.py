"""``trainer simulate`` end to end: files, metadata, overrides, and errors that leave nothing."""

from __future__ import annotations

import itertools
import time
from pathlib import Path

import numpy as np
import pytest

from trainer.cli import main
from trainer.data.recording_io import read_recording
from trainer.errors import run_cli
from trainer.physics.config import config_hash, load_config, with_overrides
from trainer.physics.profiles import parse_segments
from trainer.physics.simulate import simulate

TRUE_COLUMNS = {"true_temp_c", "true_pm_temp_c", "true_accel_mg", "true_drift_mg", "true_noise_mg"}


def cli(*argv: str) -> int:
    return run_cli(main, list(argv))


def test_paper_oven_at_low_rate(tmp_path: Path) -> None:
    out = tmp_path / "rec.npz"
    assert cli("simulate", "--protocol", "paper-oven", "--seed", "4", "-o", str(out), "--rate", "1") == 0
    rec = read_recording(out)
    assert len(rec) == 7200  # the 2 h ramp, 1 Hz
    assert rec.meta["segments"] == "ramp_up:0:7200"
    assert rec.meta["protocol"] == "paper-oven" and rec.meta["seed"] == "4"
    assert float(rec.meta["sample_rate_hz"]) == 1.0
    assert {"time_s", "temp_c", "accel_mg", "chamber_c"} | TRUE_COLUMNS <= set(rec.columns)
    np.testing.assert_allclose(rec.columns["chamber_c"], -40.0 + rec.time_s / 60.0, atol=1e-9)  # 1 degC/min
    assert rec.columns["true_temp_c"][0] == -40.0  # soaked before the recording: in equilibrium
    c = rec.columns
    np.testing.assert_allclose(
        c["accel_mg"], c["true_accel_mg"] + c["true_drift_mg"] + c["true_noise_mg"], atol=1e-12
    )


def test_extended_protocol_time_compressed(tmp_path: Path) -> None:
    out = tmp_path / "ext.csv"
    assert (
        cli(
            "simulate",
            "--protocol",
            "extended",
            "--seed",
            "1",
            "-o",
            str(out),
            "--duration",
            "1770",
            "--rate",
            "2",
        )
        == 0
    )
    rec = read_recording(out)
    assert len(rec) == 1770 * 2
    segments = parse_segments(rec.meta["segments"])
    assert [s[0] for s in segments] == ["soak", "ramp_up", "hold", "ramp_down", "hold"]
    assert segments[0][1] == 0.0 and segments[-1][2] == pytest.approx(1770.0)
    assert all(a[2] == pytest.approx(b[1]) for a, b in itertools.pairwise(segments))
    assert float(rec.meta["time_scale"]) == pytest.approx(0.1)  # 17700 s protocol into 1770 s
    chamber, t = rec.columns["chamber_c"], rec.time_s
    for label, start, end in segments:
        inside = chamber[(t >= start) & (t < end)]
        if label in ("soak", "hold"):
            assert np.ptp(inside) == 0.0
        elif label == "ramp_up":
            assert np.all(np.diff(inside) > 0)
        else:
            assert np.all(np.diff(inside) < 0)
    assert chamber.max() == pytest.approx(80.0) and chamber[-1] == pytest.approx(25.0)


def test_protocol_option_overrides_the_config_and_hash_is_of_the_effective_config(tmp_path: Path) -> None:
    cfg_path = tmp_path / "cfg.toml"
    cfg_path.write_text(
        "[protocol]\nname = 'custom'\nstart_c = 0\n[[protocol.segments]]\nlabel = 'soak'\nduration_s = 10\n"
        "[effects.warmup]\namp_mg = 1.0\ntau_s = 100.0\n"
    )
    out = tmp_path / "rec.npz"
    argv = ["simulate", "--config", str(cfg_path), "--protocol", "extended", "--seed", "2", "-o", str(out)]
    assert cli(*argv, "--duration", "177", "--rate", "10") == 0
    rec = read_recording(out)
    assert rec.meta["protocol"] == "extended"
    assert rec.meta["effects"] == "warmup" and rec.meta["noise"] == "none"
    effective = with_overrides(
        load_config(cfg_path), protocol="extended", duration_s=177.0, sample_rate_hz=10.0
    )
    assert rec.meta["config_hash"] == config_hash(effective)
    np.testing.assert_allclose(rec.columns["true_drift_mg"], np.exp(-rec.time_s / 100.0), atol=1e-12)


def test_same_seed_gives_the_same_file(tmp_path: Path) -> None:
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    for path in (a, b):
        assert cli("simulate", "--seed", "9", "-o", str(path), "--duration", "300", "--rate", "5") == 0
    assert a.read_bytes() == b.read_bytes()
    assert read_recording(a).meta["sensor"] == "sim-tactical-accel-x"


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (["-o", "{tmp}/rec.txt"], "unsupported extension"),
        (["-o", "{tmp}/missing/rec.csv"], "does not exist"),
        (["-o", "{tmp}/rec.csv", "--protocol", "oven"], "argument --protocol"),
        (["-o", "{tmp}/rec.csv", "--seed", "-2"], "argument --seed"),
        (["-o", "{tmp}/rec.csv", "--rate", "0"], "argument --rate"),
        # a recording trainer fit and import would refuse as a time-unit mistake
        (["-o", "{tmp}/rec.csv", "--rate", "0.01"], "--rate 0.01 Hz is outside the 0.1 Hz .. 100 kHz"),
        (["-o", "{tmp}/rec.csv", "--duration", "nan"], "argument --duration"),
        (
            ["-o", "{tmp}/rec.csv", "--config", "{tmp}/bad.toml"],
            "bad.toml: [effects.warmup] tau_s must be > 0",
        ),
        (["-o", "{tmp}/rec.csv", "--config", "{tmp}/tone.toml"], "is not below the Nyquist frequency"),
        (["-o", "{tmp}/rec.csv", "--duration", "0.001"], "need at least 2"),
    ],
)
def test_errors_are_one_line_and_leave_no_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], expected: str
) -> None:
    (tmp_path / "bad.toml").write_text("[effects.warmup]\namp_mg = 1\ntau_s = -5\n")
    (tmp_path / "tone.toml").write_text(
        "[input]\nkind = 'motion'\n[[input.tones]]\namp_mg = 1\nfreq_hz = 0.6\n"
    )
    argv = ["simulate", "--seed", "1", "--rate", "1", "--duration", "100"]
    argv += [arg.replace("{tmp}", str(tmp_path)) for arg in extra]
    assert cli(*argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1
    assert expected in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml", "tone.toml"]


def test_missing_seed_is_an_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli("simulate", "-o", str(tmp_path / "r.csv")) == 2
    assert "--seed" in capsys.readouterr().err


@pytest.mark.slow
def test_full_paper_oven_recording(tmp_path: Path) -> None:
    started = time.perf_counter()
    rec = simulate(load_config(None), seed=1)
    elapsed = time.perf_counter() - started
    print(f"1.44M-row paper-oven simulation: {elapsed:.2f} s")
    assert len(rec) == 1_440_000
    assert rec.meta["segments"] == "ramp_up:0:7200"
    drift = rec.columns["true_drift_mg"]
    assert 1.0 <= np.ptp(drift) <= 50.0
    out = tmp_path / "full.npz"
    assert cli("simulate", "--seed", "1", "-o", str(out)) == 0
    assert np.array_equal(read_recording(out).accel_mg, rec.accel_mg)
