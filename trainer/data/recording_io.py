"""Read and write recordings in the formats of ``shared/specs/recording-format.md``.

Recordings reach 1.44 million rows, so CSV text is parsed by numpy's C parser in chunks of a
few MB. A chunk the fast path cannot take (a character that is not part of a plain number, a
comment or blank line, a field numpy rejects) is scanned row by row in Python: that scan is the
authority on what is valid and exists to name the exact line and column in the error message.
Both paths accept exactly the same numbers (plain decimal or scientific notation, surrounding
spaces allowed), so which one ran never changes the result.

CSV output keeps enough digits for the tool, not every bit: ``time_s`` with 6 decimals (more
when the sampling period is under 1 ms, so rounding stays below 0.1 % of a period) and every
other column with 10 significant digits (relative error <= 5e-10, far below any sensor's
resolution). NPZ output is exact. Reading a CSV written here and writing it again gives the
same bytes.
"""

from __future__ import annotations

import io
import math
import re
import warnings
import zipfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, NamedTuple

import numpy as np

from trainer.data.recording import REQUIRED_COLUMNS, Recording
from trainer.errors import UserError, atomic_output

RecordingFormat = Literal["csv", "npz"]

JITTER_LIMIT = 0.01  # largest accepted |step - nominal period| / nominal period
TIME_DECIMALS = 6  # minimum decimals of time_s in CSV output
VALUE_DIGITS = 10  # significant digits of every other CSV column
NPZ_META = "meta"  # name of the optional 0-d string array in .npz files
CHUNK_BYTES = 8 << 20  # CSV text handed to numpy's parser at once
WRITE_CHUNK_ROWS = 10_000  # rows formatted per string operation when writing CSV

_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_META_COMMENT = re.compile(r"#\s*([A-Za-z_][A-Za-z0-9_.\-]*)\s*=(.*)")
_META_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]*")
_NUMERIC_BYTES = b"0123456789.eE+- \t\r\n"  # all a chunk of plain numbers can contain
_NON_FINITE_WORDS = {"nan", "inf", "infinity"}


def _quote(text: str, limit: int = 40) -> str:
    """``repr`` of a cell for a message, shortened so the message stays one readable line."""
    return repr(text if len(text) <= limit else text[: limit - 3] + "...")


# --------------------------------------------------------------------------- delimited text


@dataclass
class Table:
    """Numeric columns of a delimited text file, with the file line each row came from.

    Shared by :func:`read_recording` and the importer of foreign files, so both name lines the
    same way: ``lines[i]`` is the 1-based line number of row ``i``.
    """

    source: str
    names: list[str]
    header_line: int
    columns: dict[str, np.ndarray]
    lines: np.ndarray
    meta: dict[str, str]
    meta_lines: dict[str, int]

    def __len__(self) -> int:
        return len(self.lines)

    def row_label(self, row: int) -> str:
        return f"line {int(self.lines[row])}"


class _Preamble(NamedTuple):
    header_line: int
    names: list[str]
    body_start: int


def _read_bytes(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise UserError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise UserError(f"{path}: is a directory, not a file") from None
    except OSError as exc:
        raise UserError(f"{path}: cannot read ({exc.strerror})") from None


def _note_comment(text: str, line: int, meta: dict[str, str], meta_lines: dict[str, int]) -> None:
    match = _META_COMMENT.fullmatch(text)
    if match:
        meta[match.group(1)] = match.group(2).strip()
        meta_lines[match.group(1)] = line


def _read_preamble(
    data: bytes, source: str, delimiter: str, meta: dict[str, str], meta_lines: dict[str, int]
) -> _Preamble:
    """Collect comment metadata up to the header line and split the header into names."""
    pos, line = 0, 1
    while pos < len(data):
        end = data.find(b"\n", pos)
        end = len(data) if end < 0 else end
        try:
            text = data[pos:end].decode("utf-8-sig" if pos == 0 else "utf-8")
        except UnicodeDecodeError:
            raise UserError(f"{source}: line {line}: not UTF-8 text") from None
        stripped = text.strip()
        if stripped.startswith("#"):
            _note_comment(stripped, line, meta, meta_lines)
        elif stripped:
            return _Preamble(line, [name.strip() for name in text.split(delimiter)], end + 1)
        pos, line = end + 1, line + 1
    raise UserError(f"{source}: no header line (the file is empty or holds only comments)")


def _select_columns(source: str, preamble: _Preamble, wanted: Sequence[str] | None) -> list[int]:
    """Indices of the columns to parse; header problems in them are errors."""
    names, where = preamble.names, f"line {preamble.header_line} (header)"
    if wanted is None:
        for position, name in enumerate(names):
            if not name:
                raise UserError(f"{source}: {where}, column {position + 1}: empty column name")
            first = names.index(name)
            if first != position:
                raise UserError(
                    f"{source}: {where}, column {position + 1}: duplicate column name {name!r} "
                    f"(also column {first + 1})"
                )
        return list(range(len(names)))
    indices: list[int] = []
    for name in dict.fromkeys(wanted):
        positions = [i for i, candidate in enumerate(names) if candidate == name]
        if not positions:
            available = ", ".join(repr(n) for n in names if n)
            raise UserError(f"{source}: {where}: no column {name!r}; available: {available}")
        if len(positions) > 1:
            columns = " and ".join(str(i + 1) for i in positions)
            raise UserError(f"{source}: {where}: column name {name!r} is ambiguous (columns {columns})")
        indices.append(positions[0])
    return indices


def _parse_cell(cell: str, source: str, line: int, column: str) -> float:
    """One field by the format's rules; the message names line and column."""
    text = cell.strip()
    where = f"{source}: line {line}, column {column!r}"
    if not text:
        raise UserError(f"{where}: empty field")
    if _NUMBER.fullmatch(text):
        value = float(text)
        if not math.isfinite(value):
            raise UserError(f"{where}: {_quote(text)} is out of the float64 range")
        return value
    if text.lower().lstrip("+-") in _NON_FINITE_WORDS:
        raise UserError(f"{where}: {_quote(text)} is not allowed (nan and inf are errors)")
    raise UserError(f"{where}: {_quote(text)} is not a number")


def _parse_chunk_fast(
    chunk: bytes, n_lines: int, n_columns: int, allowed: bytes, delimiter: str
) -> np.ndarray | None:
    """numpy's C parser on a chunk of plain numbers, one row per line; None when it cannot."""
    if chunk.translate(None, allowed):
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "input contained no data" for a blank chunk
            block = np.loadtxt(
                io.BytesIO(chunk),
                delimiter=delimiter,
                comments=None,
                dtype=np.float64,
                ndmin=2,
                encoding="ascii",
            )
    except ValueError:
        return None
    return block if block.shape == (n_lines, n_columns) else None


def _scan_chunk(
    chunk: bytes,
    first_line: int,
    names: list[str],
    used: list[int],
    delimiter: str,
    source: str,
    meta: dict[str, str],
    meta_lines: dict[str, int],
) -> tuple[np.ndarray, np.ndarray]:
    """Row-by-row parse of a chunk: skips comments and blank lines, raises on the first bad cell."""
    rows: list[list[float]] = []
    lines: list[int] = []
    pieces = chunk.split(b"\n")
    if chunk.endswith(b"\n"):
        pieces.pop()
    for offset, raw in enumerate(pieces):
        line = first_line + offset
        text = raw.decode("utf-8", errors="replace").removesuffix("\r")
        stripped = text.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            _note_comment(stripped, line, meta, meta_lines)
            continue
        fields = text.split(delimiter)
        if len(fields) < len(names):
            raise UserError(
                f"{source}: line {line}, column {names[len(fields)]!r}: missing field "
                f"(found {len(fields)} of {len(names)} fields)"
            )
        if len(fields) > len(names):
            raise UserError(
                f"{source}: line {line}, column {len(names) + 1}: unexpected extra field "
                f"(found {len(fields)} fields, the header has {len(names)})"
            )
        rows.append([_parse_cell(fields[j], source, line, names[j]) for j in used])
        lines.append(line)
    return np.array(rows, dtype=np.float64).reshape(len(rows), len(used)), np.array(lines, dtype=np.int64)


def read_table(path: str | Path, *, delimiter: str = ",", columns: Sequence[str] | None = None) -> Table:
    """Parse a delimited text file with a header into float64 columns.

    ``columns=None`` parses every column (and requires every header name to be present and
    unique); otherwise only the named ones, so unused columns may hold anything but must still
    have a field on every row. Lines starting with ``#`` are comments (``# key=value`` ones land
    in ``meta``), blank lines are skipped. Values are not checked for being finite here beyond
    the text (``nan``/``inf`` words are rejected; an overflow such as ``1e999`` is not).
    """
    source = str(path)
    data = _read_bytes(Path(path))
    meta: dict[str, str] = {}
    meta_lines: dict[str, int] = {}
    preamble = _read_preamble(data, source, delimiter, meta, meta_lines)
    used = _select_columns(source, preamble, columns)
    names = preamble.names
    allowed = _NUMERIC_BYTES + delimiter.encode()

    blocks: list[np.ndarray] = []
    line_blocks: list[np.ndarray] = []
    pos, line = preamble.body_start, preamble.header_line + 1
    while pos < len(data):
        end = data.find(b"\n", pos + CHUNK_BYTES - 1)
        end = len(data) if end < 0 else end + 1
        chunk = data[pos:end]
        n_lines = chunk.count(b"\n") + (not chunk.endswith(b"\n"))
        block = _parse_chunk_fast(chunk, n_lines, len(names), allowed, delimiter)
        if block is not None:
            blocks.append(block[:, used])
            line_blocks.append(np.arange(line, line + n_lines, dtype=np.int64))
        else:
            values, lines = _scan_chunk(chunk, line, names, used, delimiter, source, meta, meta_lines)
            blocks.append(values)
            line_blocks.append(lines)
        pos, line = end, line + n_lines

    values = np.concatenate(blocks) if blocks else np.empty((0, len(used)))
    lines = np.concatenate(line_blocks) if line_blocks else np.empty(0, dtype=np.int64)
    parsed = {names[j]: np.ascontiguousarray(values[:, k]) for k, j in enumerate(used)}
    return Table(source, names, preamble.header_line, parsed, lines, meta, meta_lines)


# --------------------------------------------------------------------------- validation


class TimeProblem(NamedTuple):
    """The first row of a time axis that breaks the contract, and why."""

    row: int
    kind: Literal["not_increasing", "jitter"]
    reason: str


def find_time_problem(
    time: np.ndarray, period: float | None = None, *, jitter: bool = True
) -> TimeProblem | None:
    """First row whose time is not strictly increasing or (``jitter``) whose step is off-nominal.

    The nominal period is ``period`` when given (the declared ``sample_rate_hz``), else the median
    step. A step may differ from it by at most :data:`JITTER_LIMIT` of the period.
    """
    steps = np.diff(time)
    backwards = np.flatnonzero(~(steps > 0))
    if backwards.size:
        row = int(backwards[0]) + 1
        return TimeProblem(
            row,
            "not_increasing",
            f"{time[row]:.10g} is not greater than the previous row's {time[row - 1]:.10g}",
        )
    if not jitter or steps.size == 0:
        return None
    nominal = float(np.median(steps)) if period is None else period
    deviation = np.abs(steps - nominal)
    off = np.flatnonzero(deviation > (JITTER_LIMIT + 1e-9) * nominal)
    if not off.size:
        return None
    step = int(off[0])
    return TimeProblem(
        step + 1,
        "jitter",
        f"step {steps[step]:.6g} s from the previous row deviates {100 * deviation[step] / nominal:.2f} % "
        f"from the nominal period {nominal:.6g} s (limit {100 * JITTER_LIMIT:g} %)",
    )


def first_non_finite(columns: dict[str, np.ndarray]) -> tuple[str, int] | None:
    """(column, row) of the first nan/inf, scanning rows in order and columns left to right."""
    best: tuple[int, int, str] | None = None
    for order, (name, values) in enumerate(columns.items()):
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size and (best is None or (int(bad[0]), order) < best[:2]):
            best = (int(bad[0]), order, name)
    return None if best is None else (best[2], best[0])


def check_recording(
    rec: Recording,
    row_label: Callable[[int], str],
    meta_label: Callable[[str], str],
) -> None:
    """Enforce the contract's rules on parsed data; messages use the caller's row/metadata labels."""
    source = rec.source
    if len(rec.time_s) == 0:
        raise UserError(f"{source}: no data rows")
    bad = first_non_finite(rec.columns)
    if bad is not None:
        name, row = bad
        value = rec.columns[name][row]
        raise UserError(f"{source}: {row_label(row)}, column {name!r}: {value} is not a finite number")
    time = rec.time_s
    problem = find_time_problem(time, jitter=False)
    if problem is None:
        period = _declared_period(rec, meta_label)
        problem = find_time_problem(time, period)
    if problem is not None:
        raise UserError(f"{source}: {row_label(problem.row)}, column 'time_s': {problem.reason}")


def _declared_period(rec: Recording, meta_label: Callable[[str], str]) -> float | None:
    """1 / sample_rate_hz when declared; it must be a positive number that matches time_s."""
    text = rec.meta.get("sample_rate_hz")
    if text is None:
        return None
    where = f"{rec.source}: {meta_label('sample_rate_hz')}"
    try:
        rate = float(text)
    except ValueError:
        rate = math.nan
    if not (math.isfinite(rate) and rate > 0):
        raise UserError(f"{where}: {_quote(text)} is not a positive number")
    if len(rec.time_s) >= 2:
        median_step = float(np.median(np.diff(rec.time_s)))
        if abs(median_step * rate - 1.0) > JITTER_LIMIT:
            raise UserError(
                f"{where}: declares {rate:g} Hz but the median time_s step is {median_step:.6g} s "
                f"({1 / median_step:.6g} Hz)"
            )
    return 1.0 / rate


# --------------------------------------------------------------------------- reading


def recording_format(path: str | Path) -> RecordingFormat:
    """'csv' or 'npz' from the file extension (case-insensitive); anything else is a UserError."""
    suffix = Path(path).suffix.lower()
    if suffix == ".csv":
        return "csv"
    if suffix == ".npz":
        return "npz"
    raise UserError(f"{path}: unsupported extension {suffix or '(none)'!r}; recordings are .csv or .npz")


def read_recording(path: str | Path) -> Recording:
    """Read and validate a recording (``.csv`` or ``.npz``); every violation is a one-line UserError."""
    if recording_format(path) == "csv":
        return _read_csv(path)
    return _read_npz(path)


def _read_csv(path: str | Path) -> Recording:
    table = read_table(path, delimiter=",")
    missing = [name for name in REQUIRED_COLUMNS if name not in table.columns]
    if missing:
        raise UserError(
            f"{table.source}: line {table.header_line} (header), column {missing[0]!r}: missing required "
            f"column (columns: {', '.join(table.names)})"
        )
    if len(table) == 0:
        raise UserError(f"{table.source}: no data rows after the header on line {table.header_line}")
    rec = Recording(table.columns, table.meta, table.source)
    check_recording(
        rec,
        row_label=table.row_label,
        meta_label=lambda key: f"line {table.meta_lines[key]}, metadata {key!r}",
    )
    return rec


def _parse_npz_meta(source: str, array: np.ndarray) -> dict[str, str]:
    if array.ndim != 0 or array.dtype.kind not in "US":
        raise UserError(
            f"{source}: array {NPZ_META!r}: expected a 0-d string array, got {array.dtype} {array.shape}"
        )
    text = array.item()
    text = text.decode("utf-8", errors="replace") if isinstance(text, bytes) else str(text)
    meta: dict[str, str] = {}
    for number, raw in enumerate(text.splitlines(), start=1):
        entry = raw.strip().removeprefix("#").strip()
        if not entry:
            continue
        key, sep, value = entry.partition("=")
        if not sep or not _META_KEY.fullmatch(key.strip()):
            raise UserError(f"{source}: array {NPZ_META!r}, line {number}: {_quote(entry)} is not key=value")
        meta[key.strip()] = value.strip()
    return meta


def _read_npz(path: str | Path) -> Recording:
    source = str(path)
    if not Path(path).is_file():
        raise UserError(f"{source}: no such file")
    try:
        archive = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise UserError(f"{source}: not a readable .npz archive ({type(exc).__name__})") from None
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise UserError(f"{source}: not a .npz archive (a single .npy array?)")
    columns: dict[str, np.ndarray] = {}
    meta: dict[str, str] = {}
    with archive:
        for name in archive.files:
            try:
                array = archive[name]
            except ValueError:
                raise UserError(f"{source}: column {name!r}: holds Python objects, not numbers") from None
            except (OSError, zipfile.BadZipFile, EOFError) as exc:
                raise UserError(f"{source}: column {name!r}: unreadable ({type(exc).__name__})") from None
            if name == NPZ_META:
                meta = _parse_npz_meta(source, array)
                continue
            if array.ndim != 1:
                raise UserError(f"{source}: column {name!r}: array has shape {array.shape}, expected 1-D")
            if array.dtype.kind not in "iuf":
                raise UserError(f"{source}: column {name!r}: dtype {array.dtype} is not a real number type")
            columns[name] = array.astype(np.float64)
    missing = [name for name in REQUIRED_COLUMNS if name not in columns]
    if missing:
        raise UserError(
            f"{source}: column {missing[0]!r}: missing required column (arrays: {', '.join(columns)})"
        )
    expected = len(columns["time_s"])
    for name, values in columns.items():
        if len(values) != expected:
            raise UserError(
                f"{source}: column {name!r}: has {len(values)} rows but column 'time_s' has {expected}"
            )
    rec = Recording(columns, meta, source)
    check_recording(
        rec,
        row_label=lambda row: f"row {row + 1}",
        meta_label=lambda key: f"array {NPZ_META!r}, key {key!r}",
    )
    return rec


# --------------------------------------------------------------------------- writing


def csv_time_decimals(time: np.ndarray) -> int:
    """Decimals of ``time_s`` in CSV output: 6, or more when the median step is under 1 ms.

    Chosen so rounding moves a step by at most 0.1 % of the period, well inside the 1 % jitter
    rule, and a written recording always reads back.
    """
    if len(time) < 2:
        return TIME_DECIMALS
    step = float(np.median(np.diff(time)))
    if not (math.isfinite(step) and step > 0):
        return TIME_DECIMALS
    return max(TIME_DECIMALS, 3 + math.ceil(-math.log10(step)))


def _check_recording_writable(rec: Recording) -> None:
    """Structural rules a writer must not break (a bug in the caller, hence ValueError)."""
    for name in REQUIRED_COLUMNS:
        if name not in rec.columns:
            raise ValueError(f"{rec.source}: cannot write a recording without column {name!r}")
    for name, values in rec.columns.items():
        if not name or name != name.strip() or name.startswith("#") or any(c in name for c in ",\r\n"):
            raise ValueError(f"{rec.source}: column name {name!r} cannot be written")
        if np.ndim(values) != 1:
            raise ValueError(f"{rec.source}: column {name!r} is not 1-D")
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise ValueError(
                f"{rec.source}: column {name!r}, row {bad[0] + 1}: {values[bad[0]]} is not finite"
            )
    for key, value in rec.meta.items():
        if not _META_KEY.fullmatch(key) or any(c in str(value) for c in "\r\n"):
            raise ValueError(f"{rec.source}: metadata {key!r}={value!r} cannot be written")


def _ordered_meta(meta: dict[str, str]) -> list[tuple[str, str]]:
    first = [("sample_rate_hz", meta["sample_rate_hz"])] if "sample_rate_hz" in meta else []
    return first + [(k, v) for k, v in meta.items() if k != "sample_rate_hz"]


def write_recording(rec: Recording, path: str | Path) -> None:
    """Write every column (unknown ones included) to ``.csv`` or ``.npz``; atomic, nothing left on error."""
    fmt = recording_format(path)
    _check_recording_writable(rec)
    if fmt == "npz" and NPZ_META in rec.columns:
        raise UserError(f"{path}: column name {NPZ_META!r} is reserved in .npz files; write .csv instead")
    with atomic_output(path) as tmp:
        if fmt == "csv":
            _write_csv(rec, tmp)
        else:
            _write_npz(rec, tmp)


def _write_csv(rec: Recording, tmp: Path) -> None:
    names = list(rec.columns)
    time_format = f"%.{csv_time_decimals(np.asarray(rec.time_s))}f"
    value_format = f"%.{VALUE_DIGITS}g"
    row_format = ",".join(time_format if name == "time_s" else value_format for name in names) + "\n"
    arrays = [np.asarray(rec.columns[name], dtype=np.float64) for name in names]
    n = len(arrays[0])
    with open(tmp, "w", encoding="utf-8", newline="\n") as out:
        for key, value in _ordered_meta(rec.meta):
            out.write(f"# {key}={value}\n")
        out.write(",".join(names) + "\n")
        for start in range(0, n, WRITE_CHUNK_ROWS):
            block = np.column_stack([a[start : start + WRITE_CHUNK_ROWS] for a in arrays])
            out.write((row_format * len(block)) % tuple(block.ravel().tolist()))


def _write_npz(rec: Recording, tmp: Path) -> None:
    arrays = {name: np.asarray(values, dtype=np.float64) for name, values in rec.columns.items()}
    if rec.meta:
        arrays[NPZ_META] = np.array("\n".join(f"{k}={v}" for k, v in _ordered_meta(rec.meta)))
    with open(tmp, "wb") as out:
        np.savez(out, **arrays)
