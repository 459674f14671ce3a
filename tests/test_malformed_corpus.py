"""Every command on a corpus of malformed inputs: one line on stderr, exit 2, nothing written.

The corpus is made here from one small valid recording, model, module and TOML (truncated, one
row, no rows, NaN, text in a number column, wrong delimiter, swapped or missing columns, a bad
header, an empty file, binary garbage, .npz members that are not arrays, bad TOML, model files
that are not checkpoints or carry NaN coefficients, missing fields or ``train_stats = None``,
damaged flight logs, fleet manifests). Each case runs in-process through ``run_cli`` (the entry
points' own error handling) with the file descriptors captured, so that the prints of compiled
library code count too. A case fails on a traceback, an exit status other than 2, more than one
line on stderr, or any file left in the output directory or beside the inputs.
"""

from __future__ import annotations

import io
import shutil
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import torch

from codegen.cli import main as codegen_main
from tests.flightlogs import DataFlashWriter, imu_topic, write_ulog
from trainer.checkpoint import load_checkpoint
from trainer.cli import main as trainer_main
from trainer.errors import EXIT_USER_ERROR, run_cli

N_ROWS = 400  # 1 Hz: a cooling and a heating ramp of 50 degC
Main = Callable[[list[str] | None], int]


def _valid_lines() -> list[str]:
    rng = np.random.default_rng(0)
    temp = np.concatenate([np.linspace(40, -10, N_ROWS // 2), np.linspace(-10, 40, N_ROWS - N_ROWS // 2)])
    accel = 0.0002 * (temp - 15) ** 3 + 0.1 * (temp - 15) + rng.normal(0, 0.05, N_ROWS)
    return ["# sample_rate_hz=1", "time_s,temp_c,accel_mg"] + [
        f"{t:.3f},{c:.4f},{a:.5f}"
        for t, c, a in zip(np.arange(N_ROWS, dtype=float), temp, accel, strict=True)
    ]


def _npz(**arrays: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)  # type: ignore[arg-type]
    return buffer.getvalue()


def _with_member(data: bytes, name: str, content: bytes) -> bytes:
    buffer = io.BytesIO(data)
    with zipfile.ZipFile(buffer, "a") as archive:
        archive.writestr(name, content)
    return buffer.getvalue()


def _garbage(seed: int, size: int = 3000) -> bytes:
    return bytes(np.random.default_rng(seed).integers(0, 256, size, dtype=np.uint8))


def _recordings(lines: list[str]) -> dict[str, bytes | str]:
    """Malformed recordings, by file name (the extension picks the reader)."""
    text = "\n".join(lines) + "\n"
    meta, header, rows = lines[0], lines[1], lines[2:]
    ok = {k: np.arange(5.0) for k in ("time_s", "temp_c", "accel_mg")}
    return {
        "truncated.csv": text[: len(text) // 2 - 3],
        "one_row.csv": "\n".join([meta, header, rows[0]]) + "\n",
        "one_row_no_rate.csv": "\n".join([header, rows[0]]) + "\n",
        "zero_rows.csv": "\n".join([meta, header]) + "\n",
        "nan.csv": "\n".join([meta, header, *rows[:8], "8.000,nan,1.0", *rows[9:]]) + "\n",
        "text_in_number.csv": "\n".join([meta, header, *rows[:8], "8.000,abc,1.0", *rows[9:]]) + "\n",
        "semicolons.csv": text.replace(",", ";"),
        "swapped_columns.csv": "\n".join([meta, "temp_c,time_s,accel_mg", *rows]) + "\n",
        "missing_column.csv": "\n".join([meta, "time_s,temp_c", *(r.rsplit(",", 1)[0] for r in rows)]) + "\n",
        "bad_header.csv": "\n".join([meta, "time_s,time_s,accel_mg", *rows]) + "\n",
        "empty.csv": "",
        "garbage.csv": _garbage(1),
        "garbage.npz": _garbage(2),
        "one_row.npz": _npz(**{k: v[:1] for k, v in ok.items()}),
        "objects.npz": _npz(**{**ok, "accel_mg": np.array([{"a": 1}] * 5, dtype=object)}),
        "truncated.npz": _npz(**ok)[:-40],
        "member_not_an_array.npz": _with_member(_npz(**ok), "extra.npy", b"hello world"),
        "member_not_npy.npz": _with_member(_npz(**ok), "notes.txt", b"hello"),
        "member_forged_size.npz": _with_member(
            _npz(**ok),
            "huge.npy",
            b"\x93NUMPY\x01\x00\x46\x00{'descr': '<f8', 'fortran_order': False, 'shape': (10000000000,), }    \n",
        ),
    }


def _models(good: dict) -> dict[str, dict | bytes]:
    """Malformed checkpoints: a dict is saved with torch.save, bytes are written as they are."""

    def changed(**fields: object) -> dict:
        return {**good, **fields}

    def payload(**fields: object) -> dict:
        return changed(payload={**good["payload"], **fields})

    without_method = {k: v for k, v in good.items() if k != "method"}
    return {
        "nan_coefficients.pt": payload(coefficients_mg=torch.full((4,), float("nan"), dtype=torch.float64)),
        "two_coefficients.pt": payload(coefficients_mg=[1.0, 2.0]),
        "payload_key_missing.pt": {
            **good,
            "payload": {k: v for k, v in good["payload"].items() if k != "t_ref_c"},
        },
        "train_stats_none.pt": changed(train_stats=None),
        "train_stats_wrong_types.pt": changed(train_stats={"source": 5, "time_range_s": "all"}),
        "method_missing.pt": without_method,
        "payload_none.pt": changed(payload=None),
        "range_nan.pt": changed(valid_temp_range_c=[float("nan"), 3.0]),
        "range_one_number.pt": changed(valid_temp_range_c=[1.0]),
        "range_text.pt": changed(valid_temp_range_c="abc"),
        "range_reversed.pt": changed(valid_temp_range_c=[50.0, -10.0]),
        "offset_not_a_record.pt": changed(offset=5),
        "not_a_checkpoint.pt": _garbage(3),
        "empty.pt": b"",
    }


BAD_TOML = {
    "syntax.toml": "[thresholds\nx=1",
    "wrong_type.toml": "[thresholds]\nholdout_rms_mg = 'a'\n",
    "binary.toml": _garbage(4),
    "rate_text.toml": "[recording]\nsample_rate_hz = 'abc'\n",
    "rate_negative.toml": "[recording]\nsample_rate_hz = -5\n",
    "table_is_array.toml": "recording = [1, 2]\n",
}
BAD_JSON = {"not_json.json": "{not json", "wrong_field.json": '{"mismatches": "x"}'}
BAD_MANIFESTS = {
    "syntax.toml": "[[unit]\nid=1",
    "two_id_columns.csv": "id,recordings,id\nA,good.csv,B\n",
    "empty.csv": "",
    "binary.csv": _garbage(5),
    "id_not_text.toml": "[[unit]]\nid = 5\nrecordings = 'x'\n",
    "unknown_column.csv": "id,recordings,colour\nA,good.csv,red\n",
}


def _write(path: Path, content: object) -> Path:
    """``content`` as the file: a dict saved with torch.save, bytes or text as they are."""
    if isinstance(content, dict):
        buffer = io.BytesIO()
        torch.save(content, buffer)
        content = buffer.getvalue()
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(str(content))
    return path


def _flight_logs(root: Path) -> dict[str, Path]:
    """A ULog and a DataFlash log, valid, then damaged: a block of garbage, garbage after the header."""
    n = 600
    time_us = (1_000_000 + np.arange(n) * 5000).astype(np.int64)
    xyz = np.random.default_rng(6).normal(0, 0.1, (n, 3))
    temp = np.linspace(20.0, 40.0, n)
    gravity = np.array([0.0, 0.0, -9.8])  # m/s^2, a level board
    ulog = write_ulog(
        root / "valid.ulg",
        [
            imu_topic("sensor_accel", 0, 1, time_us, xyz + gravity, temp),
            imu_topic("sensor_gyro", 0, 2, time_us + 37, xyz, temp),
        ],
    ).read_bytes()
    writer = DataFlashWriter()
    for k in range(n):
        writer.imu(int(time_us[k]), 0, xyz[k], xyz[k] + gravity, temp[k])
    dataflash = writer.write(root / "valid.bin").read_bytes()
    logs = {}
    for suffix, data in ((".ulg", ulog), (".bin", dataflash)):
        third = len(data) // 3
        logs[f"garbage_block{suffix}"] = data[:third] + _garbage(7, 5000) + data[third + 5000 :]
        logs[f"garbage_after_header{suffix}"] = data[:400] + _garbage(8, 60_000)
    return {name: _write(root / name, content) for name, content in logs.items()}


@pytest.fixture(scope="module")
def corpus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("corpus")
    good = _write(root / "good.csv", "\n".join(_valid_lines()) + "\n")
    assert run_cli(trainer_main, ["fit", "--method", "poly3", str(good), "-o", str(root / "good.pt")]) == 0
    assert run_cli(codegen_main, ["export", str(root / "good.pt"), "-o", str(root / "module")]) == 0
    files = {"root": root, "good.csv": good, "good.pt": root / "good.pt", "module": root / "module"}
    bad = root / "bad"
    bad.mkdir()
    for name, content in {
        **_recordings(_valid_lines()),
        **_models(load_checkpoint(root / "good.pt")),
    }.items():
        files[name] = _write(bad / name, content)
    for prefix, table in (("toml", BAD_TOML), ("json", BAD_JSON), ("manifest", BAD_MANIFESTS)):
        for file_name, text in table.items():
            files[f"{prefix}:{file_name}"] = _write(bad / f"{prefix}_{file_name}", text)
    files.update(_flight_logs(bad))
    return files


RECORDINGS = list(_recordings(_valid_lines()))
MODELS = [
    "nan_coefficients.pt",
    "two_coefficients.pt",
    "payload_key_missing.pt",
    "train_stats_none.pt",
    "train_stats_wrong_types.pt",
    "method_missing.pt",
    "payload_none.pt",
    "range_nan.pt",
    "range_one_number.pt",
    "range_text.pt",
    "range_reversed.pt",
    "offset_not_a_record.pt",
    "not_a_checkpoint.pt",
    "empty.pt",
]
FLIGHT_LOGS = [f"garbage_{part}{suffix}" for part in ("block", "after_header") for suffix in (".ulg", ".bin")]


def _recording_cases() -> list[tuple[str, Main, Callable[[dict, Path, Path], list[str]]]]:
    """(command, main, argv(corpus, bad file, out dir)) of every command that reads a recording."""
    return [
        ("import", trainer_main, lambda c, f, o: ["import", str(f), "--delimiter", "comma", "--time", "time_s",
                                                  "--temp", "temp_c", "--accel", "accel_mg", "-o", str(o / "r.csv")]),
        ("fit", trainer_main, lambda c, f, o: ["fit", "--method", "poly3", str(f), "-o", str(o / "m.pt")]),
        ("fit --channels", trainer_main, lambda c, f, o: ["fit", "--method", "pla", str(f), "--channels", "all",
                                                          "-o", str(o / "fit")]),
        ("evaluate", trainer_main, lambda c, f, o: ["evaluate", str(c["good.pt"]), str(f), "--out-dir", str(o / "e")]),
        ("compare", trainer_main, lambda c, f, o: ["compare", str(f), "--methods", "poly3", "--out-dir", str(o / "c")]),
        ("compare VALID", trainer_main, lambda c, f, o: ["compare", str(c["good.csv"]), str(f), "--methods",
                                                         "poly3", "--out-dir", str(o / "c")]),
        ("diagnose", trainer_main, lambda c, f, o: ["diagnose", str(f), "--json", str(o / "d.json"),
                                                    "--report", str(o / "d")]),
        ("report", trainer_main, lambda c, f, o: ["report", str(c["good.pt"]), "--recording", str(f),
                                                  "-o", str(o / "s")]),
        ("codegen verify", codegen_main, lambda c, f, o: ["verify", str(c["good.pt"]), str(c["module"]), str(f),
                                                          "--json", str(o / "v.json")]),
    ]  # fmt: skip


def _model_cases() -> list[tuple[str, Main, Callable[[dict, Path, Path], list[str]]]]:
    return [
        ("evaluate", trainer_main, lambda c, f, o: ["evaluate", str(f), str(c["good.csv"]), "--out-dir", str(o / "e")]),
        ("report", trainer_main, lambda c, f, o: ["report", str(f), "--recording", str(c["good.csv"]),
                                                  "-o", str(o / "s")]),
        ("codegen export", codegen_main, lambda c, f, o: ["export", str(f), "-o", str(o / "c")]),
        ("codegen export px4", codegen_main, lambda c, f, o: ["export", str(f), "-o", str(o / "p"), "--format",
                                                              "px4-params"]),
        ("codegen verify", codegen_main, lambda c, f, o: ["verify", str(f), str(c["module"]), str(c["good.csv"]),
                                                          "--json", str(o / "v.json")]),
    ]  # fmt: skip


def _config_cases() -> list[tuple[str, Main, Callable[[dict, Path, Path], list[str]]]]:
    return [
        ("simulate", trainer_main, lambda c, f, o: ["simulate", "--seed", "1", "--config", str(f), "--duration",
                                                    "100", "-o", str(o / "s.csv")]),
        ("diagnose --sim", trainer_main, lambda c, f, o: ["diagnose", str(c["good.csv"]), "--sim", str(f),
                                                          "--json", str(o / "d.json")]),
        ("report --config", trainer_main, lambda c, f, o: ["report", str(c["good.pt"]), "--recording",
                                                           str(c["good.csv"]), "--config", str(f), "-o", str(o / "s")]),
    ]  # fmt: skip


CASES = (
    [(f"{cmd} <- {name}", main, argv, name) for cmd, main, argv in _recording_cases() for name in RECORDINGS]
    + [(f"{cmd} <- {name}", main, argv, name) for cmd, main, argv in _model_cases() for name in MODELS]
    + [(f"{cmd} <- {name}", main, argv, f"toml:{name}") for cmd, main, argv in _config_cases() for name in BAD_TOML]
    + [
        (f"report --verify <- {name}", trainer_main,
         lambda c, f, o: ["report", str(c["good.pt"]), "--recording", str(c["good.csv"]), "--verify", str(f),
                          "-o", str(o / "s")],
         f"json:{name}")
        for name in BAD_JSON
    ]
    + [
        (f"fleet <- {name}", trainer_main, lambda c, f, o: ["fleet", str(f), "-o", str(o / "f"), "--quiet"],
         f"manifest:{name}")
        for name in BAD_MANIFESTS
    ]
    + [
        (f"import <- {name}", trainer_main, lambda c, f, o: ["import", str(f), "-o", str(o / "r.csv")], name)
        for name in FLIGHT_LOGS
    ]
)  # fmt: skip


def _hidden_files(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.rglob(".*"))


@pytest.mark.parametrize(("label", "main", "argv", "name"), CASES, ids=[case[0] for case in CASES])
def test_a_malformed_input_is_one_line_exit_2_and_nothing_written(
    corpus: dict[str, Path],
    tmp_path: Path,
    capfd: pytest.CaptureFixture[str],
    label: str,
    main: Main,
    argv: Callable[[dict, Path, Path], list[str]],
    name: str,
) -> None:
    out = tmp_path / "out"
    out.mkdir()
    before = _hidden_files(corpus["root"])
    code = run_cli(main, argv(corpus, corpus[name], out))  # a traceback fails the test here
    err = capfd.readouterr().err
    assert code == EXIT_USER_ERROR, f"{label}: exit {code}, stderr {err!r}"
    assert err.startswith("error: ") and err.count("\n") == 1, (
        f"{label}: stderr is not one line: {err[:500]!r}"
    )
    assert str(corpus[name]) in err or name.split(":")[-1] in err or "--" in err, (
        f"{label}: names no file: {err!r}"
    )
    assert list(out.iterdir()) == [], f"{label}: left {sorted(p.name for p in out.iterdir())}"
    assert _hidden_files(corpus["root"]) == before, f"{label}: left temporary files beside the inputs"


def test_the_valid_inputs_pass(corpus: dict[str, Path], tmp_path: Path) -> None:
    """The corpus' mutations are what fails: the same commands accept the file they were made from."""
    good = corpus["good.csv"]
    assert (
        run_cli(
            trainer_main, ["evaluate", str(corpus["good.pt"]), str(good), "--out-dir", str(tmp_path / "e")]
        )
        == 0
    )
    assert (
        run_cli(
            codegen_main, ["verify", str(corpus["good.pt"]), str(corpus["module"]), str(good), "--no-table"]
        )
        == 0
    )
    shutil.copy(good, tmp_path / "copy.csv")
    argv = [
        "import",
        str(tmp_path / "copy.csv"),
        "--time",
        "time_s",
        "--temp",
        "temp_c",
        "--accel",
        "accel_mg",
    ]
    assert run_cli(trainer_main, [*argv, "-o", str(tmp_path / "r.csv")]) == 0
    for log in ("valid.ulg", "valid.bin"):
        assert (
            run_cli(
                trainer_main, ["import", str(corpus["root"] / "bad" / log), "-o", str(tmp_path / "l.csv")]
            )
            == 0
        )


def test_damaged_flight_log_warnings_are_summarised_in_one_line(
    corpus: dict[str, Path], tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """A DataFlash log with a run of bad bytes between messages imports; pymavlink's hundreds of
    lines (printed by its compiled indexer) become one note that counts them."""
    valid = (corpus["root"] / "bad" / "valid.bin").read_bytes()
    cut = valid.index(b"\xa3\x95", len(valid) // 2)  # a message boundary
    damaged = tmp_path / "gap.bin"
    damaged.write_bytes(valid[:cut] + b"\x11" * 300 + valid[cut:])
    capfd.readouterr()
    assert run_cli(trainer_main, ["import", str(damaged), "-o", str(tmp_path / "gap.csv")]) == 0
    captured = capfd.readouterr()
    assert captured.err == ""
    notes = [line for line in captured.out.splitlines() if "warning line" in line]
    assert len(notes) == 1 and str(damaged) in notes[0], captured.out
    count = int(notes[0].split("printed ")[1].split(" ")[0].replace(",", ""))
    assert count >= 2  # the run of 300 bad bytes is reported, as many lines as pymavlink printed
