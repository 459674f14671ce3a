"""``codegen export`` / ``verify`` as a user sees them: files, determinism, the C's hygiene (gcc and
clang, symbols), the manifest's sizes, and every error as one line with no partial output."""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from codegen.cli import main as codegen_main
from codegen.hostbuild import FIRMWARE_WARNINGS, STRICT_FLAGS, load_module
from tests import testmodels as tm
from tests.repo import REPO_ROOT
from trainer.checkpoint import load_checkpoint
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import read_recording, write_recording
from trainer.errors import run_cli

METHODS = ("dlstm-issa", "dlstm-temp", "persistence", "pla", "poly3")


def _subprocess(*args: str) -> subprocess.CompletedProcess[str]:
    """The real process: exit code and stderr exactly as a shell sees them."""
    env = dict(os.environ, PYTHONPATH=str(REPO_ROOT))
    return subprocess.run(
        [sys.executable, "-m", "codegen.cli", *args], capture_output=True, text=True, env=env, check=False
    )


_CAPTURE: list[pytest.CaptureFixture[str]] = []


@pytest.fixture(autouse=True)
def _capture(capsys: pytest.CaptureFixture[str]) -> Any:
    _CAPTURE.append(capsys)
    yield
    _CAPTURE.pop()


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    """In-process run of the CLI entry point (``run_cli(main)``), captured like a subprocess."""
    capsys = _CAPTURE[-1]
    capsys.readouterr()
    code = run_cli(codegen_main, list(args))
    out = capsys.readouterr()
    return subprocess.CompletedProcess(["codegen", *args], code, out.out, out.err)


def _assert_clean_failure(result: subprocess.CompletedProcess[str], *fragments: str) -> None:
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> tuple[Recording, Path]:
    path = tmp_path_factory.mktemp("rec") / "short.npz"
    assert trainer_main(["simulate", "--seed", "3", "--duration", "300", "-o", str(path)]) == 0
    return read_recording(path), path


@pytest.fixture(scope="module")
def models(tmp_path_factory: pytest.TempPathFactory, recording: tuple[Recording, Path]) -> dict[str, Path]:
    rec = recording[0]
    directory = tmp_path_factory.mktemp("models")
    paths = {}
    for method in METHODS:
        if method in ("pla", "poly3"):
            checkpoint = tm.baseline_checkpoint(method, rec)
        elif method == "persistence":
            checkpoint = tm.persistence_checkpoint(rec)
        else:
            checkpoint = tm.dlstm_checkpoint(method, rec, seed=3)
        paths[method] = directory / f"{method}.pt"
        tm.save_checkpoint(checkpoint, paths[method])
    return paths


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory, models: dict[str, Path]) -> dict[str, Path]:
    out = {}
    for method, path in models.items():
        out[method] = tmp_path_factory.mktemp("gen") / "out"
        assert codegen_main(["export", str(path), "-o", str(out[method])]) == 0
    return out


def _name(method: str) -> str:
    return "tdc_" + method.replace("-", "_")


def test_export_writes_header_source_and_manifest(models: dict[str, Path], exported: dict[str, Path]) -> None:
    for method, out in exported.items():
        name = _name(method)
        assert sorted(p.name for p in out.iterdir()) == sorted(
            [f"{name}.h", f"{name}.c", "tdc_kernels.h", f"{name}.manifest.json"]
        )
        shipped = (REPO_ROOT / "codegen" / "kernels" / "tdc_kernels.h").read_bytes()
        assert (out / "tdc_kernels.h").read_bytes() == shipped
        manifest = json.loads((out / f"{name}.manifest.json").read_text())
        digest = hashlib.sha256(models[method].read_bytes()).hexdigest()
        assert manifest["model"]["sha256"] == digest and manifest["method"] == method
        assert digest in (out / f"{name}.c").read_text() and digest in (out / f"{name}.h").read_text()
        host = load_module(out, name)
        assert host.model_id() == f"sha256:{digest}"
        assert host.sizeof_state() == manifest["sizes"]["ram_state_bytes"]  # layout computed = compiled


def test_same_model_gives_byte_identical_files(
    models: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    for k, cwd in enumerate((tmp_path, tmp_path / "elsewhere")):
        cwd.mkdir(exist_ok=True)
        monkeypatch.chdir(cwd)
        assert _cli("export", str(models["dlstm-temp"]), "-o", f"run{k}", "--name", "unit_a").returncode == 0
    first, second = tmp_path / "run0", tmp_path / "elsewhere" / "run1"
    for file in sorted(first.iterdir()):
        assert file.read_bytes() == (second / file.name).read_bytes(), file.name


@pytest.mark.parametrize("compiler", ["gcc", "clang"])
def test_generated_c_is_warning_free(exported: dict[str, Path], compiler: str, tmp_path: Path) -> None:
    if shutil.which(compiler) is None:
        pytest.skip(f"{compiler} is not installed (run scripts/install_c_tools.sh)")
    for method, out in exported.items():
        for opt in ("-O0", "-O2", "-Os"):
            cmd = [
                compiler,
                *STRICT_FLAGS,
                *FIRMWARE_WARNINGS,
                opt,
                "-c",
                str(out / f"{_name(method)}.c"),
                "-o",
                str(tmp_path / "m.o"),
            ]
            result = subprocess.run(cmd, capture_output=True, text=True, check=False)
            assert result.returncode == 0 and not result.stderr, f"{method} {opt}: {result.stderr}"


def test_generated_c_has_no_libm_stdio_malloc_or_mutable_globals(
    exported: dict[str, Path], tmp_path: Path
) -> None:
    for method, out in exported.items():
        source = "".join(
            (out / f).read_text() for f in (f"{_name(method)}.c", f"{_name(method)}.h", "tdc_kernels.h")
        )
        source = re.sub(r"/\*.*?\*/", "", source, flags=re.S)  # code only, not the comments
        includes = set(re.findall(r"#include\s*[<\"]([^>\"]+)", source))
        # arm_acle.h: only on a core with the DSP extension (SMLAD)
        assert includes == {"stddef.h", "stdint.h", f"{_name(method)}.h", "tdc_kernels.h", "arm_acle.h"}
        assert not re.search(
            r"\b(float|double|malloc|free|printf|static\s+(?!const)\w+\s+\w+\s*[=;\[])", source
        )
        obj = tmp_path / "m.o"
        subprocess.run(
            ["gcc", "-std=c99", "-O2", "-c", str(out / f"{_name(method)}.c"), "-o", str(obj)], check=True
        )
        symbols = subprocess.run(
            ["nm", str(obj)], capture_output=True, text=True, check=True
        ).stdout.splitlines()
        undefined = {line.split()[-1] for line in symbols if line.split()[0] == "U"}
        assert undefined <= {"memset", "memcpy"}, undefined  # compilers may lower zeroing loops to memset
        kinds = {line.split()[-2] for line in symbols if len(line.split()) == 3}
        assert not kinds & set("DdBbCG"), kinds  # no writable data or bss: all state is the caller's


def test_manifest_documents_rates_ranges_bounds_and_sizes(exported: dict[str, Path]) -> None:
    manifest = json.loads((exported["dlstm-issa"] / "tdc_dlstm_issa.manifest.json").read_text())
    assert manifest["rates"] == {
        "sample_rate_hz": 200.0,
        "sample_rate_millihz": 200_000,
        "decimation": 200,
        "network_step_hz": 1.0,
    }
    assert manifest["architecture"] == {"input_size": 1, "hidden_size": 10, "num_layers": 2}
    assert manifest["macs_per_network_step"] == 4 * 10 * (1 + 10) + 4 * 10 * (10 + 10) + 10
    for index, layer in enumerate(manifest["quantisation"]["layers"]):
        assert layer["acc_bound"] <= layer["acc_limit"] == 2**31 - 1 and layer["acc_headroom_bits"] >= 0
        assert layer["acc_bound"] >= layer["w_x"]["acc_share_bound"] + layer["w_h"]["acc_share_bound"]
        # one accumulator format per layer: the Q12 input's weights carry 3 more bits than h's (Q15)
        assert layer["w_x"]["frac_bits"] - layer["w_h"]["frac_bits"] == (3 if index == 0 else 0)
        assert layer["w_h"]["storage"] == "int16" and layer["acc_frac_bits"] >= 16
    head = manifest["quantisation"]["head"]
    assert head["acc_bound"] < 2**62 and head["estimate_headroom_bits"] > 0
    tables = manifest["sizes"]["flash_tables"]
    # int16 weights padded to pairs: layer 0 reads (x, pad, h0), layer 1 (h0, h1); head int32
    assert tables["weights"] == 2 * (40 * 12 + 40 * 20) + 4 * 10
    assert tables["biases"] == 4 * 80 and tables["activation_table"] == 2 * 513  # knots of 512 segments
    assert manifest["sizes"]["flash_table_bytes"] == sum(tables.values())
    assert manifest["sizes"]["ram_state_bytes"] < 256
    assert manifest["activations"]["tanh"]["max_abs_error"] < 3 / 2**15
    assert manifest["activations"]["sigmoid"]["max_abs_error"] < 3 / 2**16
    lo, hi = manifest["valid_temp_range_c"]
    # rounded to the nearest mdegC, as the firmware reads the range's ends
    assert manifest["valid_temp_range_mdegc"] == [
        int(np.sign(v) * np.floor(abs(v) * 1000 + 0.5)) for v in (lo, hi)
    ]


def test_verify_reports_zero_mismatches(
    models: dict[str, Path], exported: dict[str, Path], recording: tuple[Recording, Path]
) -> None:
    result = _subprocess("verify", str(models["pla"]), str(exported["pla"]), str(recording[1]), "--no-table")
    assert result.returncode == 0, result.stderr
    assert f"samples compared: {len(recording[0])}" in result.stdout and "mismatches: 0\n" in result.stdout
    assert re.search(r"error budget .*RMS [0-9.e-]+ mg, max [0-9.e-]+ mg", result.stdout)


def tampered(exported: Path, out: Path, source: str, pattern: str, change: int) -> Path:
    """A copy of an exported module in ``out`` whose ``source`` has the integer of ``pattern``'s
    group 1 (its first match) changed by ``change``."""
    shutil.copytree(exported, out)
    path = out / source
    text = path.read_text()
    match = re.search(pattern, text)
    assert match
    path.write_text(text[: match.start(1)] + str(int(match.group(1)) + change) + text[match.end(1) :])
    return out


def test_verify_detects_a_tampered_module(
    models: dict[str, Path], exported: dict[str, Path], recording: tuple[Recording, Path], tmp_path: Path
) -> None:
    # change the first packed weight pair of layer 0 by 2**10 LSB of its first (int16) weight (one
    # LSB, 2**-15 of the input weight, may change no output sample: only the final state)
    weights = r"static const int32_t tdc_dlstm_issa_l0_w\[\d+\] = \{\n    (-?\d+)"
    out = tampered(exported["dlstm-issa"], tmp_path / "tampered", "tdc_dlstm_issa.c", weights, 1024)
    result = _cli("verify", str(models["dlstm-issa"]), str(out), str(recording[1]), "--no-table")
    assert result.returncode == 1 and "mismatches: 0\n" not in result.stdout
    assert "differs from the golden model" in result.stderr


def test_verify_says_the_final_state_differs_when_no_output_sample_does(
    models: dict[str, Path], exported: dict[str, Path], recording: tuple[Recording, Path], tmp_path: Path
) -> None:
    """A valid range narrowed by 1 degC in the C raises its out-of-range flag (the state) on this run's
    warmest samples and changes no output sample: the refusal says so, not "0 samples"."""
    out = tampered(exported["pla"], tmp_path / "narrowed", "tdc_pla.c", r"temp_mdegc > (-?\d+)\)", -1000)
    result = _cli("verify", str(models["pla"]), str(out), str(recording[1]), "--no-table")
    assert result.returncode == 1
    assert "mismatches: 0\n" in result.stdout and "final state identical: NO" in result.stdout
    assert result.stderr.strip().endswith("differs from the golden model (the final state)")


def test_verify_refuses_a_module_of_another_model(
    models: dict[str, Path], exported: dict[str, Path], recording: tuple[Recording, Path]
) -> None:
    result = _cli("verify", str(models["poly3"]), str(exported["pla"]), str(recording[1]))
    _assert_clean_failure(result, "generated from another model")


def test_verify_with_the_recording_and_the_module_swapped_says_so(
    models: dict[str, Path], exported: dict[str, Path], recording: tuple[Recording, Path]
) -> None:
    result = _cli("verify", str(models["pla"]), str(recording[1]), str(exported["pla"]))
    _assert_clean_failure(result, "a recording, not the generated module's directory", "arguments swapped")


def test_export_of_a_recording_says_it_is_not_a_model(
    recording: tuple[Recording, Path], tmp_path: Path
) -> None:
    result = _cli("export", str(recording[1]), "-o", str(tmp_path / "c"))
    _assert_clean_failure(result, "a recording", "not a model file", "arguments swapped")


# ------------------------------------------------------------------------------------- errors


# the kernel library's own file names: NAME.h / NAME.c would replace them (an export that did not build)
@pytest.mark.parametrize(
    "name",
    ["9lives", "my-model", "int", "_hidden", "a b", "x" * 23, "é", "tdc_kernels", "tdc_physics_kernels"],
)
def test_invalid_names_are_rejected(models: dict[str, Path], tmp_path: Path, name: str) -> None:
    result = _cli("export", str(models["pla"]), "-o", str(tmp_path / "out"), "--name", name)
    _assert_clean_failure(result, "--name")
    assert not (tmp_path / "out").exists()


def test_a_window_of_2_16_samples_or_more_is_refused(
    recording: tuple[Recording, Path], tmp_path: Path
) -> None:
    """The C divides a window's sum by its count with 32-bit divisions (fewer than 2**16 samples)."""
    rec = recording[0]
    fe = tm.frontend_fields(rec.sample_rate_hz, temp_s=65536 / rec.sample_rate_hz)
    path = tmp_path / "long.pt"
    tm.save_checkpoint(tm.dlstm_checkpoint("dlstm-temp", rec, seed=3, frontend=fe), path)
    result = _cli("export", str(path), "-o", str(tmp_path / "out"))
    _assert_clean_failure(result, "frontend.temp_window: 65536 samples", "at most 65535")
    assert not (tmp_path / "out").exists()
    fe = tm.frontend_fields(rec.sample_rate_hz, temp_s=65535 / rec.sample_rate_hz)
    tm.save_checkpoint(tm.dlstm_checkpoint("dlstm-temp", rec, seed=3, frontend=fe), path)
    assert _cli("export", str(path), "-o", str(tmp_path / "out")).returncode == 0
    # a recursive network averages the acceleration only: its long temperature window is not refused
    fe = tm.frontend_fields(rec.sample_rate_hz, temp_s=70000 / rec.sample_rate_hz)
    tm.save_checkpoint(tm.dlstm_checkpoint("dlstm", rec, seed=3, frontend=fe), path)
    assert _cli("export", str(path), "-o", str(tmp_path / "out2")).returncode == 0


def _damaged(kind: str, models: dict[str, Path], tmp_path: Path) -> Path:
    path = tmp_path / "model.pt"
    data = models["dlstm-issa"].read_bytes()
    if kind == "truncated":
        path.write_bytes(data[: len(data) // 2])
    elif kind == "corrupted":
        path.write_bytes(data[:100] + bytes(b ^ 0x5A for b in data[100:400]) + data[400:])
    elif kind == "foreign":
        torch.save({"state_dict": {"w": torch.zeros(3)}}, path)
    elif kind == "unknown-method":
        checkpoint: dict[str, Any] = load_checkpoint(models["pla"])
        checkpoint["method"] = "kalman"
        torch.save(checkpoint, path)
    elif kind == "malformed-payload":
        checkpoint = load_checkpoint(models["dlstm-issa"])
        checkpoint["payload"]["weights"]["w_h0"] = torch.zeros(40, 9)
        torch.save(checkpoint, path)
    elif kind == "non-finite":
        checkpoint = load_checkpoint(models["pla"])
        checkpoint["payload"]["slopes_mg_per_c"][3] = float("nan")
        torch.save(checkpoint, path)
    return path


@pytest.mark.parametrize(
    ("kind", "fragment"),
    [
        ("truncated", "not a readable model file"),
        ("corrupted", "model.pt"),
        ("foreign", "not a mems-tdc model"),
        ("unknown-method", "kalman"),
        ("malformed-payload", "payload.weights.w_h0"),
        ("non-finite", "NaN, inf"),
    ],
)
def test_bad_model_files_fail_cleanly_without_output(
    kind: str, fragment: str, models: dict[str, Path], tmp_path: Path
) -> None:
    result = (_subprocess if kind == "truncated" else _cli)(
        "export", str(_damaged(kind, models, tmp_path)), "-o", str(tmp_path / "out")
    )
    _assert_clean_failure(result, fragment)
    assert not (tmp_path / "out").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["model.pt"]  # no staging directory left behind


def test_unwritable_or_missing_output_directories(models: dict[str, Path], tmp_path: Path) -> None:
    _assert_clean_failure(
        _cli("export", str(models["pla"]), "-o", str(tmp_path / "no" / "such")), "does not exist"
    )
    blocker = tmp_path / "file"
    blocker.write_text("x")
    _assert_clean_failure(_cli("export", str(models["pla"]), "-o", str(blocker)), "not a directory")
    if Path("/proc/1").is_dir():  # not writable even for root
        _assert_clean_failure(
            _cli("export", str(models["pla"]), "-o", "/proc/1/generated"), "/proc/1/generated"
        )
    if os.geteuid() != 0:
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o555)
        _assert_clean_failure(_cli("export", str(models["pla"]), "-o", str(locked / "out")), "not writable")


def test_a_failure_while_writing_leaves_nothing_half_written(
    models: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    existing = tmp_path / "existing"
    existing.mkdir()
    (existing / "notes.txt").write_text("mine")
    original = Path.write_text
    calls = {"n": 0}

    def failing(self: Path, *args: Any, **kwargs: Any) -> int:
        calls["n"] += 1
        if calls["n"] == 2:
            raise OSError(28, "No space left on device")
        return original(self, *args, **kwargs)

    monkeypatch.setattr(Path, "write_text", failing)
    for target in (tmp_path / "fresh", existing):
        calls["n"] = 0
        _assert_clean_failure(_cli("export", str(models["pla"]), "-o", str(target)), "No space left")
    assert not (tmp_path / "fresh").exists()
    assert sorted(p.name for p in existing.iterdir()) == ["notes.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["existing"]


def test_verify_refuses_a_recording_at_another_rate(
    models: dict[str, Path], exported: dict[str, Path], recording: tuple[Recording, Path], tmp_path: Path
) -> None:
    rec = recording[0].slice(0, 4000)
    other = Recording({**rec.columns, "time_s": rec.time_s * 2.0}, {"sample_rate_hz": "100"}, "x")
    path = tmp_path / "slow.npz"
    write_recording(other, path)
    result = _cli("verify", str(models["dlstm-issa"]), str(exported["dlstm-issa"]), str(path))
    _assert_clean_failure(result, "100 Hz")
