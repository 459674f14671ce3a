"""Sizes from the user are checked against the memory and time budget before anything is allocated.

Each case would ask for terabytes or days (far above any machine this runs on); the command must
stop with one line naming the option or field, exit 2 and write nothing.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest

from trainer import budget
from trainer.cli import main
from trainer.errors import UserError, run_cli
from trainer.fleet.manifest import load_manifest

TERA = 1e12


def one_line_refusal(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    assert run_cli(main, list(argv)) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    return err


@pytest.fixture(scope="module")
def small_recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rec") / "sim.npz"
    assert (
        run_cli(main, ["simulate", "--seed", "1", "--duration", "60", "--rate", "10", "-o", str(path)]) == 0
    )
    return path


@pytest.mark.parametrize(
    ("option", "value"), [("--duration", "1e308"), ("--duration", "1e12"), ("--rate", "90000")]
)
def test_simulate_size_options(
    option: str, value: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "a.npz"
    err = one_line_refusal(capsys, "simulate", "--seed", "1", option, value, "-o", str(out))
    assert "memory budget" in err and option in err
    assert list(tmp_path.iterdir()) == []


HOLD = """
[protocol]
name = "custom"
start_c = 20.0
[[protocol.segments]]
label = "hold"
duration_s = 1e12
"""


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (HOLD, "1e+12 s at 200 Hz"),
        ("[recording]\nsample_rate_hz = 90000.0\n", "at 9e+04 Hz"),  # within the rates fit takes: the budget
        ("[recording]\nsample_rate_hz = 1e9\n", "sample_rate_hz 1e+09 Hz is outside the 0.1 Hz .. 100 kHz"),
        (
            "[recording]\nduration_s = 60.0\n[effects.bias_poly]\nc0_mg = 1e308\nc1_mg_per_c = 1e308\n",
            "not finite",
        ),
        ("x = " + "[" * 5000 + "]" * 5000 + "\n", "nested deeper"),
    ],
)
def test_simulate_config_sizes(
    text: str, expected: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = tmp_path / "cfg.toml"
    config.write_text(text)
    out = tmp_path / "a.csv"
    err = one_line_refusal(capsys, "simulate", "--seed", "1", "--config", str(config), "-o", str(out))
    assert str(config) in err and expected in err
    assert not out.exists()


def test_pla_intervals_option(
    small_recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "m.pt"
    err = one_line_refusal(
        capsys, "fit", "--method", "pla", "--intervals", "1000000000", str(small_recording), "-o", str(out)
    )
    assert "--intervals 1000000000" in err and "memory budget" in err
    rows = 600  # 60 s at 10 Hz
    err = one_line_refusal(
        capsys, "fit", "--method", "pla", "--intervals", str(rows), str(small_recording), "-o", str(out)
    )
    assert f"half the {rows} training rows" in err
    assert not out.exists()


@pytest.mark.parametrize(
    ("options", "expected"),
    [
        (["--population", "100000000"], "memory budget"),
        (["--hidden", "1000000"], "memory budget"),
        (["--iterations", "1000000000"], "24 h budget"),
    ],
)
def test_dlstm_size_options(
    options: list[str],
    expected: str,
    small_recording: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    out = tmp_path / "m.pt"
    err = one_line_refusal(capsys, "fit", "--method", "dlstm", *options, str(small_recording), "-o", str(out))
    assert options[1] in err and expected in err
    assert not out.exists()


@pytest.mark.parametrize("command", ["fit", "compare"])
def test_a_search_over_one_network_is_refused_before_training(
    command: str, small_recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The sparrow search needs two networks: refused in one line before the gradient training (it
    was a traceback after it), while plain DLSTM, which has no search, takes one network."""
    out = tmp_path / "out"
    small = ["--population", "1", "--iterations", "1", "--cycles", "2", "--quiet"]
    if command == "fit":
        argv = ["fit", "--method", "dlstm-ssa", *small, str(small_recording), "-o", str(out)]
    else:
        argv = ["compare", str(small_recording), "--holdout", "0.5", "--methods", "dlstm,dlstm-issa", *small]
        argv += ["--out-dir", str(out)]
    err = one_line_refusal(capsys, *argv)
    assert "--population 1" in err and "at least 2" in err and "--method dlstm" in err
    assert not out.exists()
    one_network = ["fit", "--method", "dlstm", *small, str(small_recording), "-o", str(tmp_path / "m.pt")]
    assert run_cli(main, one_network) == 0


def test_manifest_options_use_the_budget(tmp_path: Path) -> None:
    manifest = tmp_path / "fleet.toml"
    manifest.write_text(
        '[fleet]\nmethod_options = { pla = "--intervals 1000000000" }\n'
        '[[unit]]\nid = "A"\nrecordings = ["a.npz"]\nmethods = ["pla"]\n'
    )
    with pytest.raises(UserError, match=r"--intervals 1000000000.*memory budget"):
        load_manifest(manifest)


def test_npz_sizes_come_from_headers(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A compressed member announcing 1e10 values is refused before it is inflated."""
    bomb = tmp_path / "bomb.npz"
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as archive:
        for name in ("time_s", "temp_c", "accel_mg"):
            with archive.open(f"{name}.npy", "w", force_zip64=True) as member:
                header = {"descr": "<f8", "fortran_order": False, "shape": (10**10,)}
                np.lib.format.write_array_header_1_0(member, header)
                member.write(bytes(1 << 16))
    assert bomb.stat().st_size < 1e6
    err = one_line_refusal(capsys, "fit", "--method", "poly3", str(bomb), "-o", str(tmp_path / "m.pt"))
    assert "bomb.npz: loading" in err and "memory budget" in err


def test_budget_scales_with_available_memory(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(budget, "available_memory_bytes", lambda: 4 * TERA)
    budget.check_memory(budget.MEMORY_SHARE * 4 * TERA, "fits", "")
    with pytest.raises(UserError, match=r"needs about 2\.01 TB"):
        budget.check_memory(2.01 * TERA, "x", "")
    with pytest.raises(UserError, match="unbounded memory"):
        budget.check_memory(float("inf"), "x", "")
    with pytest.raises(UserError, match="unbounded time"):
        budget.check_time(float("nan"), "x", "")
