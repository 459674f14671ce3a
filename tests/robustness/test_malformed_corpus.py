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

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import torch

from codegen.cli import main as codegen_main
from tests.cli_corpus import (
    IMPORT_OWN_CSV,
    Main,
    config_cases,
    garbage,
    hidden_files,
    model_cases,
    npz_bytes,
    recording_cases,
    valid_files,
    valid_flight_logs,
    valid_lines,
    with_member,
    write_file,
)
from trainer.checkpoint import load_checkpoint
from trainer.cli import main as trainer_main
from trainer.errors import EXIT_USER_ERROR, run_cli


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
        "garbage.csv": garbage(1),
        "garbage.npz": garbage(2),
        "one_row.npz": npz_bytes(**{k: v[:1] for k, v in ok.items()}),
        "objects.npz": npz_bytes(**{**ok, "accel_mg": np.array([{"a": 1}] * 5, dtype=object)}),
        "truncated.npz": npz_bytes(**ok)[:-40],
        "member_not_an_array.npz": with_member(npz_bytes(**ok), "extra.npy", b"hello world"),
        "member_not_npy.npz": with_member(npz_bytes(**ok), "notes.txt", b"hello"),
        "member_forged_size.npz": with_member(
            npz_bytes(**ok),
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
        "degree_text.pt": payload(degree="3"),
        "remove_median_text.pt": payload(remove_median="yes"),
        "n_bins_zero.pt": payload(n_bins=0),
        "payload_range_reversed.pt": payload(temp_range_c=[45.0, -40.0]),
        "coefficients_2d.pt": payload(coefficients_mg=torch.zeros((2, 2), dtype=torch.float64)),
        "train_stats_none.pt": changed(train_stats=None),
        "train_stats_wrong_types.pt": changed(train_stats={"source": 5, "time_range_s": "all"}),
        "method_missing.pt": without_method,
        "payload_none.pt": changed(payload=None),
        "range_nan.pt": changed(valid_temp_range_c=[float("nan"), 3.0]),
        "range_one_number.pt": changed(valid_temp_range_c=[1.0]),
        "range_text.pt": changed(valid_temp_range_c="abc"),
        "range_reversed.pt": changed(valid_temp_range_c=[50.0, -10.0]),
        "offset_not_a_record.pt": changed(offset=5),
        "not_a_checkpoint.pt": garbage(3),
        "empty.pt": b"",
    }


BAD_TOML = {
    "syntax.toml": "[thresholds\nx=1",
    "wrong_type.toml": "[thresholds]\nholdout_rms_mg = 'a'\n",
    "binary.toml": garbage(4),
    "rate_text.toml": "[recording]\nsample_rate_hz = 'abc'\n",
    "rate_negative.toml": "[recording]\nsample_rate_hz = -5\n",
    "table_is_array.toml": "recording = [1, 2]\n",
}
BAD_JSON = {"not_json.json": "{not json", "wrong_field.json": '{"mismatches": "x"}'}
BAD_MANIFESTS = {
    "syntax.toml": "[[unit]\nid=1",
    "two_id_columns.csv": "id,recordings,id\nA,good.csv,B\n",
    "empty.csv": "",
    "binary.csv": garbage(5),
    "id_not_text.toml": "[[unit]]\nid = 5\nrecordings = 'x'\n",
    "unknown_column.csv": "id,recordings,colour\nA,good.csv,red\n",
}


def _flight_logs(root: Path) -> dict[str, Path]:
    """The valid ULog and DataFlash log, damaged: a block of garbage, garbage after the header."""
    logs = {}
    for suffix, data in valid_flight_logs(root).items():
        third = len(data) // 3
        logs[f"garbage_block{suffix}"] = data[:third] + garbage(7, 5000) + data[third + 5000 :]
        logs[f"garbage_after_header{suffix}"] = data[:400] + garbage(8, 60_000)
    return {name: write_file(root / name, content) for name, content in logs.items()}


@pytest.fixture(scope="module")
def corpus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("corpus")
    files = valid_files(root)
    bad = root / "bad"
    bad.mkdir()
    for name, content in {
        **_recordings(valid_lines()),
        **_models(load_checkpoint(root / "good.pt")),
    }.items():
        files[name] = write_file(bad / name, content)
    for prefix, table in (("toml", BAD_TOML), ("json", BAD_JSON), ("manifest", BAD_MANIFESTS)):
        for file_name, text in table.items():
            files[f"{prefix}:{file_name}"] = write_file(bad / f"{prefix}_{file_name}", text)
    files.update(_flight_logs(bad))
    return files


RECORDINGS = list(_recordings(valid_lines()))
MODELS = [
    "nan_coefficients.pt",
    "two_coefficients.pt",
    "payload_key_missing.pt",
    "degree_text.pt",
    "remove_median_text.pt",
    "n_bins_zero.pt",
    "payload_range_reversed.pt",
    "coefficients_2d.pt",
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


CASES = (
    [(f"{cmd} <- {name}", main, argv, name) for cmd, main, argv in recording_cases() for name in RECORDINGS]
    + [(f"{cmd} <- {name}", main, argv, name) for cmd, main, argv in model_cases() for name in MODELS]
    + [(f"{cmd} <- {name}", main, argv, f"toml:{name}") for cmd, main, argv in config_cases() for name in BAD_TOML]
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
    before = hidden_files(corpus["root"])
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
    assert hidden_files(corpus["root"]) == before, f"{label}: left temporary files beside the inputs"


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
    argv = ["import", str(tmp_path / "copy.csv"), *IMPORT_OWN_CSV]
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
