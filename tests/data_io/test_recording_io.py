"""Reading and writing recordings: round trips, the spec's error rules, atomic output."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trainer.data import csv_table, recording_io
from trainer.data.recording import MIN_ROWS, Recording
from trainer.data.recording_io import read_recording, write_recording
from trainer.errors import UserError

# A valid 200 Hz file; error cases below replace one line (line numbers are 1-based file lines).
BASE_LINES = [
    "# sample_rate_hz=200",  # line 1
    "# sensor=unit-test",  # line 2
    "time_s,temp_c,accel_mg",  # line 3
    "0.000,20.0,1.0",  # line 4
    "0.005,20.0,1.1",  # line 5
    "0.010,20.1,1.2",  # line 6
    "0.015,20.1,1.3",  # line 7
]


def make_recording(n: int = 64, rate_hz: float = 200.0, seed: int = 0) -> Recording:
    rng = np.random.default_rng(seed)
    columns = {
        "time_s": np.arange(n) / rate_hz,
        "temp_c": np.linspace(-40.0, 85.0, n) + rng.normal(0, 0.01, n),
        "accel_mg": -980.0 + rng.normal(0, 2.0, n),
        "accel_x_mg": rng.normal(0, 1e-3, n),  # small magnitudes exercise %g exponents
        "true_drift_mg": rng.normal(0, 5e4, n),
        "board_counter": np.arange(n, dtype=np.float64) * 1e12,  # an unknown column: kept
    }
    return Recording(columns, {"sensor": "S-1", "note": "a=b c", "sample_rate_hz": f"{rate_hz:g}"}, "mem")


def write_lines(path: Path, lines: list[str], newline: str = "\n") -> Path:
    path.write_text(newline.join(lines) + newline, encoding="utf-8")
    return path


def read_error(path: Path) -> str:
    with pytest.raises(UserError) as caught:
        read_recording(path)
    message = str(caught.value)
    assert "\n" not in message
    assert str(path) in message
    return message


def files_in(directory: Path) -> set[str]:
    return {p.name for p in directory.iterdir()}


# --------------------------------------------------------------------------- round trips


def test_csv_round_trip_within_documented_precision(tmp_path: Path) -> None:
    rec = make_recording()
    write_recording(rec, tmp_path / "r.csv")
    back = read_recording(tmp_path / "r.csv")
    assert list(back.columns) == list(rec.columns)
    assert back.meta == rec.meta
    assert back.source == str(tmp_path / "r.csv")
    np.testing.assert_allclose(back.time_s, rec.time_s, rtol=0, atol=0.5e-6 + 1e-12)
    for name in rec.columns:
        if name != "time_s":  # 10 significant digits: half a unit in the 10th digit
            np.testing.assert_allclose(back.columns[name], rec.columns[name], rtol=5e-10, atol=0)


def test_npz_round_trip_is_exact(tmp_path: Path) -> None:
    rec = make_recording()
    write_recording(rec, tmp_path / "r.npz")
    back = read_recording(tmp_path / "r.npz")
    assert list(back.columns) == list(rec.columns)
    assert back.meta == rec.meta
    for name, values in rec.columns.items():
        np.testing.assert_array_equal(back.columns[name], values)


def test_csv_to_npz_to_csv_gives_the_same_bytes(tmp_path: Path) -> None:
    write_recording(make_recording(seed=5), tmp_path / "a.csv")
    write_recording(read_recording(tmp_path / "a.csv"), tmp_path / "b.npz")
    write_recording(read_recording(tmp_path / "b.npz"), tmp_path / "c.csv")
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "c.csv").read_bytes()


def test_written_csv_puts_sample_rate_first_then_header(tmp_path: Path) -> None:
    write_recording(make_recording(n=3), tmp_path / "r.csv")
    lines = (tmp_path / "r.csv").read_text().splitlines()
    assert lines[:4] == [
        "# sample_rate_hz=200",
        "# sensor=S-1",
        "# note=a=b c",
        ",".join(make_recording().columns),
    ]
    assert lines[4].startswith("0.000000,")
    assert len(lines) == 4 + 3


def test_fast_rate_keeps_more_time_decimals(tmp_path: Path) -> None:
    rec = make_recording(n=50, rate_hz=20_000.0)  # 50 us period: 6 decimals would be 1 % jitter
    write_recording(rec, tmp_path / "r.csv")
    back = read_recording(tmp_path / "r.csv")
    np.testing.assert_allclose(np.diff(back.time_s), 50e-6, rtol=1e-3)


def test_reads_the_spec_example_and_foreign_line_endings(tmp_path: Path) -> None:
    lines = [
        "# sample_rate_hz=200",
        "# sensor=GNC-module-accel-x",
        "# a plain comment, not metadata",
        "accel_mg , time_s,temp_c",  # column order is free, spaces around names are trimmed
        "1.2034,0.000,-39.982",
        "",
        "# mid-data comment=yes",
        " 1.1987 ,0.005,-39.982",
        "+1.2e0,.010,-4.0e1",
    ]
    path = tmp_path / "r.csv"
    path.write_bytes(b"\xef\xbb\xbf" + "\r\n".join(lines).encode())  # BOM, CRLF, no final newline
    rec = read_recording(path)
    assert list(rec.columns) == ["accel_mg", "time_s", "temp_c"]
    np.testing.assert_array_equal(rec.accel_mg, [1.2034, 1.1987, 1.2])
    np.testing.assert_array_equal(rec.time_s, [0.0, 0.005, 0.01])
    np.testing.assert_array_equal(rec.temp_c, [-39.982, -39.982, -40.0])
    # "# mid-data comment=yes" has a space in its key, so it is a plain comment
    assert rec.meta == {"sample_rate_hz": "200", "sensor": "GNC-module-accel-x"}


def test_mid_data_metadata_comment_is_metadata(tmp_path: Path) -> None:
    path = write_lines(tmp_path / "r.csv", [*BASE_LINES[:5], "# operator=ann", *BASE_LINES[5:]])
    assert read_recording(path).meta["operator"] == "ann"


def test_unknown_columns_survive_a_copy(tmp_path: Path) -> None:
    lines = ["time_s,temp_c,accel_mg,board_raw,true_temp_c", "0,1,2,3,4", "1,1,2,3,4"]
    write_recording(read_recording(write_lines(tmp_path / "a.csv", lines)), tmp_path / "b.npz")
    back = read_recording(tmp_path / "b.npz")
    assert list(back.columns) == ["time_s", "temp_c", "accel_mg", "board_raw", "true_temp_c"]
    np.testing.assert_array_equal(back.columns["board_raw"], [3, 3])


def count_row_scans(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Record the first line of every chunk that falls back to the Python row scan."""
    calls: list[int] = []
    original = csv_table._scan_chunk

    def spy(chunk: bytes, first_line: int, *args: object) -> tuple[np.ndarray, np.ndarray]:
        calls.append(first_line)
        return original(chunk, first_line, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(csv_table, "_scan_chunk", spy)
    return calls


def test_fast_and_slow_parsers_agree_bit_for_bit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """numpy's parser (clean file) and the Python row scan (a comment forces it) give equal floats."""
    rng = np.random.default_rng(7)
    n = 300
    values = rng.normal(0, 1, (n, 2)) * 10.0 ** rng.integers(-8, 8, (n, 2))
    rows = [f"{i / 200!r},{float(a)!r},{float(b)!r}" for i, (a, b) in enumerate(values)]
    scans = count_row_scans(monkeypatch)
    clean = read_recording(write_lines(tmp_path / "clean.csv", ["time_s,temp_c,accel_mg", *rows]))
    assert scans == []
    commented = read_recording(write_lines(tmp_path / "slow.csv", ["time_s,temp_c,accel_mg", "# x", *rows]))
    assert scans == [2]
    for name in clean.columns:
        np.testing.assert_array_equal(clean.columns[name], commented.columns[name])
    np.testing.assert_array_equal(clean.temp_c, values[:, 0])


@st.composite
def messy_files(draw: st.DrawFn) -> tuple[list[str], np.ndarray, int | None]:
    """Valid rows with comments and blank lines sprinkled in, maybe one bad cell; its line if any."""
    n = draw(st.integers(MIN_ROWS, 40))  # fewer is refused (test_malformed_corpus.py)
    values = np.array(draw(st.lists(st.integers(-999, 999), min_size=2 * n, max_size=2 * n)), float).reshape(
        n, 2
    )
    lines = ["# sample_rate_hz=10", "time_s,temp_c,accel_mg"]
    for i in range(n):
        for _ in range(draw(st.integers(0, 2))):
            lines.append(draw(st.sampled_from(["", "# note", "   ", "# k=v"])))
        lines.append(f"{i / 10},{values[i, 0]:g},{values[i, 1]:g}")
    bad_line = None
    if draw(st.booleans()):
        data_lines = [k for k, text in enumerate(lines) if text and text[0].isdigit()]
        k = draw(st.sampled_from(data_lines))
        lines[k] = lines[k].rsplit(",", 1)[0] + "," + draw(st.sampled_from(["nan", "x", "", "1e", "--1"]))
        bad_line = k + 1
    return lines, values, bad_line


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(case=messy_files(), chunk_bytes=st.sampled_from([1, 7, 40, 1 << 20]))
def test_any_chunking_gives_the_same_rows_and_error_lines(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    case: tuple[list[str], np.ndarray, int | None],
    chunk_bytes: int,
) -> None:
    lines, values, bad_line = case
    monkeypatch.setattr(csv_table, "CHUNK_BYTES", chunk_bytes)
    path = write_lines(tmp_path / "m.csv", lines)
    if bad_line is None:
        rec = read_recording(path)
        np.testing.assert_array_equal(rec.temp_c, values[:, 0])
        np.testing.assert_array_equal(rec.accel_mg, values[:, 1])
    else:
        message = read_error(path)
        assert f"line {bad_line}, column 'accel_mg'" in message


# --------------------------------------------------------------------------- CSV error rules


CSV_ERRORS = {
    # id: (line replacements, expected fragments)
    "nan": ({6: "0.010,20.1,nan"}, ["line 6", "column 'accel_mg'", "nan"]),
    "inf": ({5: "0.005,inf,1.1"}, ["line 5", "column 'temp_c'", "inf"]),
    "minus-infinity": ({7: "0.015,20.1,-Infinity"}, ["line 7", "column 'accel_mg'", "-Infinity"]),
    "overflow-to-inf": (
        {6: "0.010,1e999,1.2"},
        ["line 6", "column 'temp_c'", "'1e999' is out of the float64 range"],
    ),
    "empty-field": ({5: "0.005,,1.1"}, ["line 5", "column 'temp_c'", "empty field"]),
    "blank-last-field": ({7: "0.015,20.1,"}, ["line 7", "column 'accel_mg'", "empty field"]),
    "too-few-fields": ({6: "0.010,20.1"}, ["line 6", "column 'accel_mg'", "missing field"]),
    "too-many-fields": ({4: "0.000,20.0,1.0,9"}, ["line 4", "column 4", "extra field"]),
    "text": ({7: "0.015,abc,1.3"}, ["line 7", "column 'temp_c'", "'abc' is not a number"]),
    "hex": ({5: "0x05,20.0,1.1"}, ["line 5", "column 'time_s'", "not a number"]),
    "underscore": ({6: "0.010,20.1,1_000"}, ["line 6", "column 'accel_mg'", "not a number"]),
    "quoted": ({6: '0.010,"20.1",1.2'}, ["line 6", "column 'temp_c'", "not a number"]),
    "decimal-comma": ({6: "0.010,20;1,1.2"}, ["line 6", "column 'temp_c'", "not a number"]),
    "semicolon-delimited": (
        {3: "time_s;temp_c;accel_mg"},
        ["line 3 (header)", "semicolon-delimited", "import"],
    ),
    "tab-delimited": ({3: "time_s\ttemp_c\taccel_mg"}, ["line 3 (header)", "tab-delimited", "import"]),
    "duplicate-header": ({3: "time_s,temp_c,time_s"}, ["line 3", "column 3", "duplicate", "'time_s'"]),
    "empty-header-name": ({3: "time_s,,accel_mg"}, ["line 3", "column 2", "empty column name"]),
    "missing-required": (
        {3: "time_s,temp_c,acc_mg"},  # accel_x_mg would be a channel (accel0_x), which needs no accel_mg
        ["line 3", "column 'accel_mg'", "missing required"],
    ),
    "time-repeats": ({6: "0.005,20.1,1.2"}, ["line 6", "column 'time_s'", "not greater"]),
    "time-goes-back": ({7: "0.001,20.1,1.3"}, ["line 7", "column 'time_s'", "not greater"]),
    # 3 % of a period late: the step is 3 % long, the row 1.5 % off the closest uniform grid
    "jitter": (
        {6: "0.01015,20.1,1.2"},
        ["line 6", "column 'time_s'", "3.00 %", "1.50 %", "nominal period 0.005"],
    ),
    "rate-not-a-number": ({1: "# sample_rate_hz=fast"}, ["line 1", "'sample_rate_hz'", "'fast'"]),
    "rate-negative": ({1: "# sample_rate_hz=-200"}, ["line 1", "'sample_rate_hz'", "positive"]),
    "rate-zero": ({1: "# sample_rate_hz=0"}, ["line 1", "'sample_rate_hz'", "positive"]),
    "rate-nan": ({1: "# sample_rate_hz=nan"}, ["line 1", "'sample_rate_hz'", "positive"]),
    "rate-disagrees": ({2: "# sample_rate_hz=100"}, ["line 2", "'sample_rate_hz'", "100 Hz", "200 Hz"]),
}


@pytest.mark.parametrize("case", list(CSV_ERRORS), ids=list(CSV_ERRORS))
def test_csv_error_names_line_and_column(tmp_path: Path, case: str) -> None:
    replacements, fragments = CSV_ERRORS[case]
    lines = [replacements.get(number, text) for number, text in enumerate(BASE_LINES, start=1)]
    message = read_error(write_lines(tmp_path / "rec.csv", lines))
    for fragment in fragments:
        assert fragment in message


def test_base_lines_are_valid(tmp_path: Path) -> None:
    """The error cases above differ from this valid file by exactly one line."""
    rec = read_recording(write_lines(tmp_path / "rec.csv", BASE_LINES))
    assert len(rec) == 4
    assert rec.sample_rate_hz == 200.0


def test_jitter_under_one_percent_is_accepted(tmp_path: Path) -> None:
    lines = [*BASE_LINES[:5], "0.01004,20.1,1.2", "0.01504,20.1,1.3"]  # steps 0.8 % long then on time
    assert len(read_recording(write_lines(tmp_path / "rec.csv", lines))) == 4


def test_jitter_is_judged_against_the_median_without_sample_rate(tmp_path: Path) -> None:
    lines = ["time_s,temp_c,accel_mg"] + [f"{t},0,0" for t in (0.0, 0.1, 0.2, 0.3, 0.402, 0.5)]
    message = read_error(write_lines(tmp_path / "rec.csv", lines))
    assert "line 6, column 'time_s'" in message  # the row at 0.402 s comes 2 % late
    assert "nominal period 0.1 s" in message


def _clock_read_late(jitter: float, seed: int, rows: int = 4000, period_s: float = 0.01) -> np.ndarray:
    """A free-running 100 Hz clock whose every timestamp is read up to ``jitter`` of a period off
    its tick (uniformly): the timestamps stay within ``jitter`` of the grid, the steps within 2x."""
    ticks = np.arange(rows) * period_s
    return ticks + np.random.default_rng(seed).uniform(-jitter, jitter, rows) * period_s


def _file_with_time(path: Path, time: np.ndarray) -> Path:
    lines = ["# sample_rate_hz=100", "time_s,temp_c,accel_mg", *(f"{t:.7f},20.0,1.0" for t in time)]
    return write_lines(path, lines)


@pytest.mark.parametrize("seed", [1, 2])
def test_timestamps_within_one_percent_of_the_grid_are_accepted_although_steps_differ_more(
    tmp_path: Path, seed: int
) -> None:
    """recording-format.md: "jitter up to 1 % of the period is accepted". A clock read late by up to
    0.9 % of a period (the grid's sense of jitter) makes steps up to 1.8 % off nominal."""
    time = _clock_read_late(0.0099, seed)
    steps_off = np.abs(np.diff(time) / 0.01 - 1.0)
    assert steps_off.max() > 0.012  # the file would break a rule on steps alone
    assert len(read_recording(_file_with_time(tmp_path / "late.csv", time))) == time.size


def test_a_clock_read_late_by_more_than_one_percent_is_refused_at_the_first_row_that_breaks_both(
    tmp_path: Path,
) -> None:
    time = _clock_read_late(0.02, 3)
    period = 0.01
    step_off = np.abs(np.diff(time) - period) > 0.01 * period
    grid_off = np.abs(time - np.arange(time.size) * period) > 0.01 * period  # the clock's own ticks
    first_row = int(np.flatnonzero(step_off & (grid_off[1:] | grid_off[:-1]))[0]) + 1
    message = read_error(_file_with_time(tmp_path / "late.csv", time))
    assert f"line {first_row + 3}, column 'time_s'" in message  # two header lines, rows from 0
    assert "uniform grid" in message and "limit 1 %" in message


def test_no_data_rows(tmp_path: Path) -> None:
    message = read_error(write_lines(tmp_path / "rec.csv", [*BASE_LINES[:3], "# only a comment", ""]))
    assert "no data rows" in message
    assert "line 3" in message


@pytest.mark.parametrize("lines", [[], ["# sample_rate_hz=200", "", "# nothing else"]])
def test_no_header(tmp_path: Path, lines: list[str]) -> None:
    path = tmp_path / "rec.csv"
    path.write_text("\n".join(lines))
    assert "no header line" in read_error(path)


def test_header_that_is_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "rec.csv"
    path.write_bytes(b"# sample_rate_hz=200\ntime_s,temp_\xe9,accel_mg\n0,1,2\n")
    assert "line 2: not UTF-8" in read_error(path)


def test_non_utf8_cell_is_named(tmp_path: Path) -> None:
    path = tmp_path / "rec.csv"
    path.write_bytes(b"time_s,temp_c,accel_mg\n0,1,2\n0.1,1\xe9,2\n")
    message = read_error(path)
    assert "line 3, column 'temp_c'" in message


def test_error_in_the_last_row_only_rescans_the_last_chunk(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    n = 50_000
    body = "\n".join(f"{t:.3f},1,2" for t in np.arange(n) / 200)
    path = tmp_path / "rec.csv"
    path.write_text("time_s,temp_c,accel_mg\n" + body + "\n0.0,x,2\n")
    monkeypatch.setattr(csv_table, "CHUNK_BYTES", 1 << 16)  # about 12 chunks
    scans = count_row_scans(monkeypatch)
    assert f"line {n + 2}, column 'temp_c'" in read_error(path)
    assert len(scans) == 1


# --------------------------------------------------------------------------- NPZ error rules


def save_npz(path: Path, **arrays: object) -> Path:
    with open(path, "wb") as out:
        np.savez(out, **arrays)
    return path


def good_arrays(n: int = 5) -> dict[str, np.ndarray]:
    return {"time_s": np.arange(n) / 200.0, "temp_c": np.zeros(n), "accel_mg": np.ones(n)}


NPZ_ERRORS = {
    "unequal-length": ({"accel_mg": np.ones(4)}, ["column 'accel_mg'", "4 rows", "5"]),
    "two-dimensional": ({"temp_c": np.zeros((5, 2))}, ["column 'temp_c'", "1-D"]),
    "strings": ({"temp_c": np.array(["a"] * 5)}, ["column 'temp_c'", "not a real number"]),
    "booleans": ({"temp_c": np.zeros(5, bool)}, ["column 'temp_c'", "not a real number"]),
    "complex": ({"temp_c": np.zeros(5, complex)}, ["column 'temp_c'", "not a real number"]),
    "objects": ({"temp_c": np.array([1, "a", None, 2, 3], dtype=object)}, ["column 'temp_c'", "objects"]),
    "nan": ({"accel_mg": np.array([1, 1, np.nan, 1, 1.0])}, ["row 3", "column 'accel_mg'", "nan"]),
    "time-repeats": ({"time_s": np.array([0, 1, 2, 2, 3.0])}, ["row 4", "column 'time_s'", "not greater"]),
    "jitter": ({"time_s": np.array([0, 1, 2, 3.5, 4.0])}, ["row 4", "column 'time_s'", "deviates"]),
    "meta-not-scalar": ({"meta": np.array(["a=b", "c=d"])}, ["'meta'", "0-d string"]),
    "meta-not-key-value": ({"meta": np.array("sensor=x\nnonsense")}, ["'meta'", "line 2", "key=value"]),
    "bad-rate": ({"meta": np.array("sample_rate_hz=-1")}, ["'meta'", "'sample_rate_hz'", "positive"]),
}


@pytest.mark.parametrize("case", list(NPZ_ERRORS), ids=list(NPZ_ERRORS))
def test_npz_error_names_column_and_row(tmp_path: Path, case: str) -> None:
    changes, fragments = NPZ_ERRORS[case]
    message = read_error(save_npz(tmp_path / "rec.npz", **{**good_arrays(), **changes}))
    for fragment in fragments:
        assert fragment in message


def test_npz_missing_column(tmp_path: Path) -> None:
    arrays = good_arrays()
    del arrays["temp_c"]
    assert "column 'temp_c': missing required" in read_error(save_npz(tmp_path / "rec.npz", **arrays))


def test_npz_that_is_not_an_archive(tmp_path: Path) -> None:
    path = tmp_path / "rec.npz"
    path.write_text("time_s,temp_c,accel_mg\n")
    assert "not a readable .npz" in read_error(
        path
    ) and "a CSV recording takes the .csv extension" in read_error(path)
    cut = tmp_path / "cut.npz"
    np.savez(cut, time_s=np.arange(10.0), temp_c=np.zeros(10), accel_mg=np.zeros(10))
    cut.write_bytes(cut.read_bytes()[:200])
    assert "not a readable .npz" in read_error(cut) and "truncated or damaged" in read_error(cut)


def test_npz_good_arrays_are_valid(tmp_path: Path) -> None:
    rec = read_recording(save_npz(tmp_path / "rec.npz", **good_arrays(), meta=np.array("# sensor = x\n\n")))
    assert len(rec) == 5
    assert rec.meta == {"sensor": "x"}


# --------------------------------------------------------------------------- paths


def test_a_model_file_given_as_the_recording_is_named_as_swapped_arguments(tmp_path: Path) -> None:
    """trainer report MODEL --recording REC with the two swapped said "unsupported extension '.pt'"."""
    message = read_error(write_lines(tmp_path / "m.pt", BASE_LINES))
    assert "a model file (.pt) where a recording" in message and "arguments swapped?" in message


@pytest.mark.parametrize("name", ["rec.txt", "rec", "rec.csv.gz"])
def test_unsupported_extension(tmp_path: Path, name: str) -> None:
    path = write_lines(tmp_path / name, BASE_LINES)
    assert "unsupported extension" in read_error(path)
    with pytest.raises(UserError, match="unsupported extension"):
        write_recording(make_recording(), tmp_path / "out.txt")
    assert "out.txt" not in files_in(tmp_path)


@pytest.mark.parametrize("name", ["missing.csv", "missing.npz"])
def test_missing_file(tmp_path: Path, name: str) -> None:
    assert "no such file" in read_error(tmp_path / name)


def test_uppercase_extension_is_accepted(tmp_path: Path) -> None:
    assert len(read_recording(write_lines(tmp_path / "REC.CSV", BASE_LINES))) == 4


# --------------------------------------------------------------------------- writing


@pytest.mark.parametrize("name", ["out.csv", "out.npz"])
def test_failed_write_leaves_nothing_and_keeps_the_old_file(tmp_path: Path, name: str) -> None:
    rec = make_recording()
    rec.columns["accel_mg"][10] = np.nan
    with pytest.raises(ValueError, match="not finite"):
        write_recording(rec, tmp_path / name)
    assert files_in(tmp_path) == set()

    (tmp_path / name).write_bytes(b"old")
    with pytest.raises(ValueError):
        write_recording(rec, tmp_path / name)
    assert files_in(tmp_path) == {name}
    assert (tmp_path / name).read_bytes() == b"old"


def test_write_failing_midway_leaves_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def explode(rec: Recording, tmp: Path) -> None:
        tmp.write_text("partial")
        raise OSError("disk full")

    monkeypatch.setattr(recording_io, "_write_csv", explode)
    with pytest.raises(OSError, match="disk full"):
        write_recording(make_recording(), tmp_path / "out.csv")
    assert files_in(tmp_path) == set()


def test_npz_cannot_hold_a_column_named_meta(tmp_path: Path) -> None:
    rec = make_recording()
    rec.columns["meta"] = np.zeros(len(rec))
    with pytest.raises(UserError, match="'meta' is reserved"):
        write_recording(rec, tmp_path / "out.npz")
    assert files_in(tmp_path) == set()


@pytest.mark.parametrize(
    "bad",
    [
        {"columns": {"time_s": np.arange(3.0), "temp_c": np.zeros(3)}},
        {
            "columns": {
                "time_s": np.arange(3.0),
                "temp_c": np.zeros(3),
                "accel_mg": np.zeros(3),
                "a,b": np.zeros(3),
            }
        },
        {"meta": {"sensor": "two\nlines"}},
        {"meta": {"bad key": "x"}},
    ],
)
def test_unwritable_recordings_are_rejected(tmp_path: Path, bad: dict) -> None:
    columns = bad.get("columns", {"time_s": np.arange(3.0), "temp_c": np.zeros(3), "accel_mg": np.zeros(3)})
    rec = Recording(columns, bad.get("meta", {}))
    with pytest.raises(ValueError):
        write_recording(rec, tmp_path / "out.csv")
    assert files_in(tmp_path) == set()


def test_output_directory_must_exist(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="does not exist"):
        write_recording(make_recording(), tmp_path / "nope" / "out.csv")


@pytest.mark.parametrize("unit", ["dps", "pa"])
def test_accel_mg_is_milli_g_whatever_other_metadata_say(unit: str, tmp_path: Path) -> None:
    """The format: `accel_mg` is milli-g and `sample_rate_hz` the only key a reader may rely on. A file
    of another writer with `unit=dps` (or `pa`) beside a bare `accel_mg` was read as deg/s (or refused
    as an impossible pressure); now as milli-g. A gyroscope's own column with the same metadata (what
    this tool writes for a gyroscope's view) still reads as that channel."""
    from trainer.data.channels import channel_unit

    n = 200
    rows = "".join(f"{i},{-10 + 0.3 * i},{0.05 * i - 3:.3f}\n" for i in range(n))
    other = tmp_path / "other.csv"
    other.write_text(f"# sample_rate_hz=1\n# unit={unit}\n# channel=gyro0_x\ntime_s,temp_c,accel_mg\n{rows}")
    rec = read_recording(other)
    assert channel_unit(rec) == "mg" and "channel" not in rec.meta
    np.testing.assert_allclose(rec.accel_mg, [0.05 * i - 3 for i in range(n)], atol=1e-9)
    own = tmp_path / "own.csv"
    own.write_text(f"# sample_rate_hz=1\n# unit=dps\n# channel=gyro0_x\ntime_s,temp_c,gyro0_x_dps\n{rows}")
    mine = read_recording(own)
    assert channel_unit(mine) == "dps" and mine.meta["channel"] == "gyro0_x"
    np.testing.assert_allclose(mine.accel_mg, [0.05 * i - 3 for i in range(n)], atol=1e-9)
