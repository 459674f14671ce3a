"""The rate contract (codegen/rate.py): ``codegen export --rate HZ`` re-derives a model with a time base
for the firmware's rate exactly (or refuses), every header declares its rate in millihertz with a
compile-time check, and the GNC example and the bench refuse a module built for another rate."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from codegen.cli import main as codegen_main
from codegen.hostbuild import STRICT_FLAGS
from codegen.verify import verify
from tests import testmodels as tm
from tests.repo import REPO_ROOT
from trainer.cli import main as trainer_main
from trainer.data.recording_io import read_recording
from trainer.errors import run_cli

ROOT = REPO_ROOT
TRAINED_HZ, TWICE_HZ = 50.0, 100.0
FRONTEND = tm.frontend_fields(TRAINED_HZ, run_s=0.5, temp_s=5.0, step_s=1.0)  # 25, 250, 50 samples


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Two minutes of the oven run at the training rate and at twice it (another seed)."""
    folder = tmp_path_factory.mktemp("runs")
    paths = {}
    for key, seed, rate in (("trained", "1", TRAINED_HZ), ("twice", "2", TWICE_HZ)):
        paths[key] = folder / f"{key}.npz"
        args = ["simulate", "--seed", seed, "--duration", "120", "--rate", f"{rate:g}", "-o", str(paths[key])]
        assert trainer_main(args) == 0
    return paths


def _checkpoint(method: str, runs: dict[str, Path], folder: Path) -> Path:
    rec = read_recording(runs["trained"])
    path = folder / f"{method}.pt"
    tm.save_checkpoint(tm.checkpoint_for(method, rec, frontend=dict(FRONTEND)), path)
    return path


def _export(model: Path, out: Path, *extra: str) -> int:
    return run_cli(codegen_main, ["export", str(model), "-o", str(out), "--name", "m", *extra])


@pytest.mark.parametrize("method", tm.representatives())
def test_export_at_twice_the_rate_is_bit_exact_at_that_rate(
    method: str, runs: dict[str, Path], tmp_path: Path
) -> None:
    model = _checkpoint(method, runs, tmp_path)
    assert _export(model, tmp_path / "out", "--rate", f"{TWICE_HZ:g}") == 0
    header = (tmp_path / "out" / "m.h").read_text()
    manifest = json.loads((tmp_path / "out" / "m.manifest.json").read_text())
    result = verify(model, tmp_path / "out", runs["twice"], table1=False)
    assert result.mismatches == 0 and result.state_equal
    time_based = method in ("dlstm", "dlstm-temp", "persistence", "physics")
    expected_millihz = round(TWICE_HZ * 1000) if time_based else 0
    assert f"#define M_SAMPLE_RATE_MILLIHZ {expected_millihz}u" in header
    assert manifest["rates"]["sample_rate_millihz"] == expected_millihz
    if "decimation" in manifest["rates"]:  # the same seconds in twice the samples
        assert manifest["rates"]["decimation"] == 2 * FRONTEND["decimation"]
        assert manifest["frontend"]["temp_window"] == 2 * FRONTEND["temp_window"]
        assert manifest["frontend"]["accel_window"] == 2 * FRONTEND["accel_window"]
        assert f"#define M_DECIMATION {2 * FRONTEND['decimation']}u" in header


def test_the_training_rate_given_as_rate_exports_the_same_bytes(
    runs: dict[str, Path], tmp_path: Path
) -> None:
    model = _checkpoint("dlstm-temp", runs, tmp_path)
    assert _export(model, tmp_path / "plain") == 0
    assert _export(model, tmp_path / "rated", "--rate", f"{TRAINED_HZ:g}") == 0
    for name in ("m.h", "m.c", "m.manifest.json"):
        assert (tmp_path / "plain" / name).read_bytes() == (tmp_path / "rated" / name).read_bytes()


def test_a_recording_of_the_training_rate_is_resampled_on_request(
    runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = _checkpoint("dlstm-temp", runs, tmp_path)
    assert _export(model, tmp_path / "out", "--rate", f"{TWICE_HZ:g}") == 0
    args = ["verify", str(model), str(tmp_path / "out"), str(runs["trained"]), "--no-table"]
    capsys.readouterr()
    assert run_cli(codegen_main, args) == 2
    err = capsys.readouterr().err.strip()
    assert "50 Hz" in err and "100 Hz" in err and "--resample" in err and "\n" not in err
    result = verify(model, tmp_path / "out", runs["trained"], table1=False, resample=True)
    assert result.mismatches == 0 and result.resampled_from_hz == pytest.approx(TRAINED_HZ)
    assert result.samples == pytest.approx(2 * len(read_recording(runs["trained"])), abs=2)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--rate", "75"], "multiples of 2 Hz, e.g. 72, 74, 76"),  # 25 samples at 50 Hz = 37.5 at 75 Hz
        (["--rate", "1.98"], "multiples of 2 Hz"),
        (["--rate", "20.0001"], "whole millihertz"),
        (["--rate", "0.0001"], "within 0.1 Hz .. 100 kHz"),  # a recording at that rate is refused at import
        (["--rate", "200000"], "within 0.1 Hz .. 100 kHz"),
        (["--rate", "200", "--format", "px4-params"], "--rate applies to the C module"),
    ],
)
def test_a_rate_that_cannot_be_met_is_refused_in_one_line(
    args: list[str], message: str, runs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = _checkpoint("dlstm-temp", runs, tmp_path)
    capsys.readouterr()
    assert _export(model, tmp_path / "never", *args) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err and "Traceback" not in err
    assert not (tmp_path / "never").exists()


def _compile(cc: str, module_dir: Path, check: str, work: Path) -> subprocess.CompletedProcess[str]:
    src = work / "caller.c"
    src.write_text(f'#include "m.h"\n{check};\n')
    return subprocess.run(
        [cc, *STRICT_FLAGS, f"-I{module_dir}", "-c", str(src), "-o", str(work / "caller.o")],
        capture_output=True,
        text=True,
        check=False,
    )


@pytest.mark.parametrize("cc", [c for c in ("gcc", "clang") if shutil.which(c)])
def test_the_check_macro_refuses_another_rate_at_compile_time(
    cc: str, runs: dict[str, Path], tmp_path: Path
) -> None:
    for method, accepted, refused in (("physics", 100_000, 200_000), ("poly3", 1_980, None)):
        model = _checkpoint(method, runs, tmp_path)
        out = tmp_path / method
        assert _export(model, out, "--rate", f"{TWICE_HZ:g}") == 0
        ok = _compile(cc, out, f"M_CHECK_SAMPLE_RATE_MILLIHZ({accepted}u)", tmp_path)
        assert ok.returncode == 0, ok.stderr
        if refused is not None:
            bad = _compile(cc, out, f"M_CHECK_SAMPLE_RATE_MILLIHZ({refused}u)", tmp_path)
            assert bad.returncode != 0 and "m_built_for_another_sample_rate" in bad.stderr


def _make(
    module_dir: Path, name: str, out: Path, *targets: str, **variables: str
) -> subprocess.CompletedProcess[str]:
    cmd = ["make", "--no-print-directory", "-C", str(ROOT / "firmware_c"), f"MODULE_DIR={module_dir}"]
    cmd += [f"NAME={name}", f"OUT={out}", *(f"{k}={v}" for k, v in variables.items()), *targets]
    return subprocess.run(cmd, capture_output=True, text=True, check=False)


def test_the_gnc_example_and_the_bench_refuse_a_module_of_another_rate(
    runs: dict[str, Path], tmp_path: Path
) -> None:
    """The example's task runs at 200 Hz: a module exported for 100 Hz stops its build; the same
    model exported with --rate 200 builds (host compiler; the bench on the Arm compiler if present)."""
    model = _checkpoint("dlstm-temp", runs, tmp_path)
    alt = _checkpoint("poly3", runs, tmp_path)
    assert run_cli(codegen_main, ["export", str(alt), "-o", str(tmp_path / "alt"), "--name", "alt_p"]) == 0
    alt_vars = {"ALT_MODULE_DIR": str(tmp_path / "alt"), "ALT_NAME": "alt_p"}
    for rate, ok in ((TWICE_HZ, False), (200.0, True)):
        out = tmp_path / f"m{rate:g}"
        assert _export(model, out, "--rate", f"{rate:g}") == 0
        built = _make(out, "m", tmp_path / f"build{rate:g}", "example-host", **alt_vars)
        assert (built.returncode == 0) == ok, built.stderr[-2000:]
        if not ok:
            assert "m_built_for_another_sample_rate" in built.stderr
        if shutil.which("arm-none-eabi-gcc"):
            bench = _make(out, "m", tmp_path / f"bench{rate:g}", "bench-app")
            assert (bench.returncode == 0) == ok, bench.stderr[-2000:]
            if not ok:
                assert "m_built_for_another_sample_rate" in bench.stderr


def test_a_physics_model_without_a_filter_is_exported_as_trained_at_any_rate(
    runs: dict[str, Path], tmp_path: Path
) -> None:
    # Nothing in it is built for a rate (the hysteresis branch is a function of the temperature), so
    # --rate changes no byte of the code or manifest, as for a cubic, and the header says so instead of
    # claiming filter coefficients re-derived for a module it declares for any rate.
    effects = {name: tm.PHYSICS_EFFECTS[name] for name in ("bias_poly", "hysteresis_offset")}
    model = tmp_path / "physics.pt"
    tm.save_checkpoint(tm.physics_checkpoint(read_recording(runs["trained"]), effects), model)
    assert _export(model, tmp_path / "plain") == 0
    assert _export(model, tmp_path / "rated", "--rate", f"{TWICE_HZ:g}") == 0
    for name in ("m.c", "m.manifest.json"):
        assert (tmp_path / "plain" / name).read_bytes() == (tmp_path / "rated" / name).read_bytes()
    plain = (tmp_path / "plain" / "m.h").read_text().splitlines()
    rated = (tmp_path / "rated" / "m.h").read_text().splitlines()
    added = " ".join(line.lstrip(" *") for line in rated if line not in plain)  # the header wraps it
    assert added == (
        "rate: --rate 100 Hz changes nothing: this model has no filter coefficients to re-derive "
        "(it runs at any rate)."
    )
    assert [line for line in plain if line not in rated] == []
    assert "#define M_SAMPLE_RATE_MILLIHZ 0u" in rated
    rates = json.loads((tmp_path / "plain" / "m.manifest.json").read_text())["rates"]
    assert rates["sample_rate_millihz"] == 0 and rates["sample_rate_hz"] is None  # as the header says
