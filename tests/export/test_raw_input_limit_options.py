"""The raw-input limit is an option per channel unit: ``--accel-limit-g`` (g, default 16) for the
accelerometer channels, ``--gyro-limit-dps`` (deg/s, default 2000) for the gyroscope channels
(docs/codegen.md). A gyroscope module used to clamp at ``--accel-limit-g`` x 1000 deg/s, 16000 deg/s
by default. The expected limits here are the docs' figures, converted by hand (16000 LSB per unit);
what they mean is checked on the compiled C. An option that governs nothing in the export is
refused in one line and nothing is written.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from codegen.cli import main as codegen_main
from codegen.hostbuild import load_module
from codegen.imu_verify import manifest_raw_limits
from codegen.quantize import FLAG_INPUT_CLAMPED
from codegen.verify import verify
from tests import testmodels as tm
from tests.cli_capture import run_captured
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.errors import UserError

LSB_PER_UNIT = 16_000  # docs/codegen.md: one LSB is 1/16000 of the channel's unit
INSIDE_MDEGC = 20_000


@pytest.fixture(scope="module")
def models(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Small models of three channels: (method, channel) -> model.pt."""
    root = tmp_path_factory.mktemp("raw-limits")
    rec = tm.ramp_recording(6, "raw-limits")
    paths = {}
    for seed, (method, channel, unit) in enumerate(
        (
            ("dlstm", "gyro0_z", "dps"),
            ("pla", "gyro0_x", "dps"),
            ("dlstm", "accel0_z", "mg"),
            ("poly3", "accel0_x", "mg"),
        )
    ):
        checkpoint = tm.checkpoint_for(method, rec, hidden=4, layers=2, seed=seed)
        checkpoint["train_stats"] = {**checkpoint["train_stats"], "channel": channel, "unit": unit}
        paths[channel] = root / f"{channel}.pt"
        tm.save_checkpoint(checkpoint, paths[channel])
    return paths


def _clamped(out: Path, raw: int) -> bool:
    host = load_module(out, "lim", flags=("-O1",))
    state = host.new_state()
    host.run(state, np.full(20, raw, dtype=np.int32), np.full(20, INSIDE_MDEGC, dtype=np.int32))
    return bool(int(host.read_state(state)["flags"]) & FLAG_INPUT_CLAMPED)


def test_a_gyroscope_network_clamps_at_2000_deg_s_by_default(
    models: dict[str, Path], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    out = tmp_path / "c"
    code, _, err = run_captured(
        codegen_main, capsys, "export", str(models["gyro0_z"]), "-o", str(out), "--name", "lim"
    )
    assert code == 0, err
    signal = json.loads((out / "lim.manifest.json").read_text())["input_limits"]["input"]
    assert signal["unit"] == "deg/s" and signal["clamped"] is True
    assert signal["range"] == [-2000.0, 2000.0]
    assert signal["lsb"] == [-2000 * 16_000, 2000 * 16_000]
    assert not _clamped(out, 2000 * LSB_PER_UNIT) and not _clamped(out, -2000 * LSB_PER_UNIT)
    assert _clamped(out, 2001 * LSB_PER_UNIT) and _clamped(out, -2001 * LSB_PER_UNIT)


def test_gyro_limit_dps_sets_the_gyroscope_clamp_in_deg_s(
    models: dict[str, Path], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    out = tmp_path / "c"
    argv = ["export", str(models["gyro0_z"]), "-o", str(out), "--name", "lim", "--gyro-limit-dps", "250.5"]
    code, _, err = run_captured(codegen_main, capsys, *argv)
    assert code == 0, err
    signal = json.loads((out / "lim.manifest.json").read_text())["input_limits"]["input"]
    assert signal["range"] == [-250.5, 250.5] and signal["lsb"] == [-4_008_000, 4_008_000]
    assert not _clamped(out, 4_008_000) and _clamped(out, 4_008_001)


def test_verify_reads_a_one_channel_gyroscope_module_s_limit_back(
    models: dict[str, Path], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """Exported at 500 deg/s, verified on a recording up to 800 deg/s: bit exact, and the samples
    beyond 500 deg/s are the ones compared apart as clamped."""
    out = tmp_path / "c"
    argv = ["export", str(models["gyro0_z"]), "-o", str(out), "--name", "lim", "--gyro-limit-dps", "500"]
    assert run_captured(codegen_main, capsys, *argv)[0] == 0
    n = 400
    rate = np.random.default_rng(3).uniform(-800.0, 800.0, n)
    columns = {"time_s": np.arange(n) / 5.0, "temp_c": np.linspace(0.0, 40.0, n), "gyro0_z_dps": rate}
    write_recording(Recording(columns, {"sample_rate_hz": "5"}, "fast-turns"), tmp_path / "turns.npz")
    result = verify(models["gyro0_z"], out, tmp_path / "turns.npz", table1=False)
    assert result.mismatches == 0 and result.state_equal
    beyond = int(np.count_nonzero(np.abs(np.rint(rate * LSB_PER_UNIT)) > 500 * LSB_PER_UNIT))
    assert beyond > 100
    assert result.budget.clamped is not None and result.budget.clamped.count == beyond


REFUSALS = [  # (models, options, what the one line says)
    (("gyro0_z",), ("--accel-limit-g", "4"), ("--accel-limit-g", "accelerometer", "--gyro-limit-dps")),
    (("accel0_z",), ("--gyro-limit-dps", "500"), ("--gyro-limit-dps", "gyroscope", "--accel-limit-g")),
    (("gyro0_x",), ("--gyro-limit-dps", "500"), ("--gyro-limit-dps", "pla", "never clamps")),
    (("accel0_x",), ("--accel-limit-g", "4"), ("--accel-limit-g", "poly3", "never clamps")),
    (("gyro0_z",), ("--gyro-limit-dps", "0"), ("--gyro-limit-dps must be in (0, 128000] deg/s, got 0",)),
    (("gyro0_z",), ("--gyro-limit-dps", "128001"), ("--gyro-limit-dps must be in (0, 128000] deg/s",)),
    (("gyro0_z",), ("--gyro-limit-dps", "nan"), ("--gyro-limit-dps must be in (0, 128000] deg/s",)),
    (("accel0_z",), ("--accel-limit-g", "128.5"), ("--accel-limit-g must be in (0, 128] g, got 128.5",)),
    # an IMU module: an option for a unit none of whose channels clamps its raw input
    (("accel0_x", "gyro0_z"), ("--accel-limit-g", "4"), ("--accel-limit-g", "accel0_x poly3", "clamps")),
    (("accel0_z", "gyro0_x"), ("--gyro-limit-dps", "500"), ("--gyro-limit-dps", "gyro0_x pla", "clamps")),
    (("accel0_z", "accel0_x"), ("--gyro-limit-dps", "500"), ("--gyro-limit-dps", "has none")),
    # parameter files never clamp
    (("accel0_x", "--format", "px4-params"), ("--accel-limit-g", "4"), ("--accel-limit-g", "--format c")),
]


@pytest.mark.parametrize(("given", "options", "said"), REFUSALS)
def test_an_option_that_governs_nothing_is_refused_in_one_line(
    given: tuple[str, ...],
    options: tuple[str, ...],
    said: tuple[str, ...],
    models: dict[str, Path],
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
) -> None:
    args = [str(models[g]) if g in models else g for g in given]
    out = tmp_path / "c"
    code, stdout, err = run_captured(codegen_main, capsys, "export", *args, "-o", str(out), *options)
    assert code == 2 and stdout == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    for text in said:
        assert text in lines[0], (text, lines[0])
    assert not out.exists()


def test_an_imu_module_takes_an_option_when_one_channel_of_its_unit_clamps(
    models: dict[str, Path], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """accel0_x poly3 and accel0_z dlstm: --accel-limit-g governs accel0_z; gyro0_x pla and gyro0_z
    dlstm: --gyro-limit-dps governs gyro0_z. Each channel's manifest entry is in its own unit."""
    paths = [str(models[c]) for c in ("accel0_x", "accel0_z", "gyro0_x", "gyro0_z")]
    out = tmp_path / "c"
    options = ("--accel-limit-g", "2.5", "--gyro-limit-dps", "300")
    code, _, err = run_captured(
        codegen_main, capsys, "export", *paths, "-o", str(out), "--name", "imu", *options
    )
    assert code == 0, err
    manifest = json.loads((out / "imu.manifest.json").read_text())
    ranges = {c["name"]: c["input_limits"]["input"].get("range") for c in manifest["channels"]}
    assert ranges == {
        "accel0_x": None,
        "accel0_z": [-2500.0, 2500.0],
        "gyro0_x": None,
        "gyro0_z": [-300.0, 300.0],
    }
    assert manifest_raw_limits(manifest, out / "imu.manifest.json") == {"mg": 2.5, "dps": 300.0}


def _entry(unit: str, limit: int | None) -> dict[str, object]:
    signal: dict[str, object] = {"unit": unit, "clamped": limit is not None}
    if limit is not None:
        signal["lsb"] = [-limit, limit]
    return {"input_limits": {"input": signal}}


def test_verify_reads_one_limit_per_unit_and_refuses_two_in_one_unit(tmp_path: Path) -> None:
    path = tmp_path / "imu.manifest.json"
    both = {"channels": [_entry("mg", 4000 * 16_000), _entry("deg/s", 500 * 16_000), _entry("mg", None)]}
    assert manifest_raw_limits(both, path) == {"mg": 4.0, "dps": 500.0}
    assert manifest_raw_limits({"channels": [_entry("deg/s", None)]}, path) == {}
    two = {"channels": [_entry("deg/s", 500 * 16_000), _entry("deg/s", 250 * 16_000)]}
    with pytest.raises(UserError, match=r"gyroscope channels clamp their raw inputs at different limits"):
        manifest_raw_limits(two, path)


def test_a_recursive_model_s_warning_names_what_it_removes_on_its_own_channel(
    models: dict[str, Path], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A recursive network removes any sustained input along with the drift: on a gyroscope a steady
    turn, not gravity, which its export said."""
    for channel, removes, not_said in (
        ("gyro0_z", "rotation rate", "gravity"),
        ("accel0_z", "gravity", "rotation"),
    ):
        code, out, err = run_captured(
            codegen_main,
            capsys,
            "export",
            str(models[channel]),
            "-o",
            str(tmp_path / channel),
            "--name",
            "rec",
        )
        assert code == 0, err
        note = next(line for line in out.splitlines() if "recursive method" in line)
        assert removes in note and not_said not in note, note
