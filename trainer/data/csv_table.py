"""A generic engine for delimited text tables: typed column parsing with one-line errors, fast.

Knows nothing of recordings (see :mod:`trainer.data.recording_io` for the format built on it).
Files reach 1.44 million rows, so text is parsed by numpy's C parser in chunks of a few MB. A
chunk the fast path cannot take (a character that is not part of a plain number, a comment or
blank line, a field numpy rejects) is scanned row by row in Python: that scan is the authority
on what is valid and exists to name the exact file, line and column in the error message. Both
paths accept exactly the same numbers (plain decimal or scientific notation, surrounding spaces
allowed), so which one ran never changes the result.

A file is: comment lines (``#``; ``# key=value`` ones are metadata), a header line of column
names, then one row of numbers per line (comments and blank lines may appear anywhere).
:func:`write_table` writes the same layout.
"""

from __future__ import annotations

import io
import math
import re
import unicodedata
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from trainer.budget import check_memory
from trainer.errors import UserError

CHUNK_BYTES = 8 << 20  # text handed to numpy's parser at once
# Peak memory of read_table per byte of the file (the text, its chunks, the parsed float64 blocks
# and their concatenation): 3.2 measured with tracemalloc on a 120 000-row simulated CSV.
READ_BYTES_PER_FILE_BYTE = 4
WRITE_CHUNK_ROWS = 10_000  # rows formatted per string operation when writing

META_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]*")  # the key of a ``# key=value`` comment
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?", re.ASCII)
_META_COMMENT = re.compile(r"#\s*([A-Za-z_][A-Za-z0-9_.\-]*)\s*=(.*)")
_NUMERIC_BYTES = b"0123456789.eE+- \t\r\n"  # all a chunk of plain numbers can contain
_NON_FINITE_WORDS = {"nan", "inf", "infinity"}
_DECIMAL_COMMA = re.compile(r"[+-]?\d*,\d+(?:[eE][+-]?\d+)?", re.ASCII)
_FIELD_SPACE = " \t"  # the spaces a field may carry around its number (ASCII only, like numpy's parser)


def quote(text: str, limit: int = 40) -> str:
    """``repr`` of a cell for a message, shortened so the message stays one readable line."""
    return repr(text if len(text) <= limit else text[: limit - 3] + "...")


# --------------------------------------------------------------------------- reading


@dataclass
class Table:
    """Numeric columns of a delimited text file, with the file line each row came from.

    Shared by the recording reader and the importer of foreign files, so both name lines the
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
        if path.is_file():
            check_memory(
                path.stat().st_size * READ_BYTES_PER_FILE_BYTE, f"{path}: reading", "split the recording"
            )
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
    data: bytes,
    source: str,
    delimiter: str,
    meta: dict[str, str],
    meta_lines: dict[str, int],
    other_delimiter_fix: str = "",
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
            names = [name.strip() for name in text.split(delimiter)]
            _check_delimiter(names, source, line, delimiter, other_delimiter_fix)
            return _Preamble(line, names, end + 1)
        pos, line = end + 1, line + 1
    if b"\r" in data and b"\n" not in data:
        raise UserError(
            f"{source}: its lines end in CR alone (an old Mac text file), so it reads as one line; "
            "convert the line ends to LF or CRLF"
        )
    raise UserError(f"{source}: no header line (the file is empty or holds only comments)")


DELIMITER_NAMES = {"\t": "tab", ",": "comma", ";": "semicolon"}  # the delimiters trainer import reads


def _check_delimiter(names: list[str], source: str, line: int, delimiter: str, fix: str) -> None:
    """A header that does not split on ``delimiter`` but holds another delimiter: the file was
    written with that one (a spreadsheet's semicolons), which every data line would fail on.
    ``fix``: what the caller's user does about it, appended in parentheses."""
    if len(names) != 1:
        return
    for other, word in DELIMITER_NAMES.items():
        if other != delimiter and other in names[0]:
            raise UserError(
                f"{source}: line {line} (header): {quote(names[0])} is one column: the file looks "
                f"{word}-delimited, this reader splits on {delimiter!r}" + (f" ({fix})" if fix else "")
            )


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
    text = cell.strip(_FIELD_SPACE)
    where = f"{source}: line {line}, column {column!r}"
    if not text:
        raise UserError(f"{where}: empty field")
    if not text.isascii():
        odd = next(c for c in text if not c.isascii())
        raise UserError(
            f"{where}: {quote(text)} holds {unicodedata.name(odd, 'a non-ASCII character')} (U+{ord(odd):04X}); "
            f"numbers must be plain ASCII digits: replace it or re-export the file"
        )
    if _NUMBER.fullmatch(text):
        value = float(text)
        if not math.isfinite(value):
            raise UserError(f"{where}: {quote(text)} is out of the float64 range")
        return value
    if text.lower().lstrip("+-") in _NON_FINITE_WORDS:
        raise UserError(f"{where}: {quote(text)} is not allowed (nan and inf are errors)")
    if _DECIMAL_COMMA.fullmatch(text):
        raise UserError(
            f"{where}: {quote(text)} is not a number (a decimal comma? trainer import takes --decimal-comma)"
        )
    raise UserError(f"{where}: {quote(text)} is not a number")


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
    if block.shape != (n_lines, n_columns) or not np.isfinite(block).all():
        return None  # the row-by-row parse names the line and quotes the cell (``1e400``)
    return block


def _scan_chunk(
    chunk: bytes,
    first_line: int,
    names: list[str],
    used: list[int],
    delimiter: str,
    source: str,
    meta: dict[str, str],
    meta_lines: dict[str, int],
    allow_empty: frozenset[int] = frozenset(),
) -> tuple[np.ndarray, np.ndarray]:
    """Row-by-row parse of a chunk: skips comments and blank lines, raises on the first bad cell.

    An empty field of a column in ``allow_empty`` (indices) becomes NaN instead of an error.
    """
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
        rows.append(
            [
                math.nan
                if j in allow_empty and not fields[j].strip()
                else _parse_cell(fields[j], source, line, names[j])
                for j in used
            ]
        )
        lines.append(line)
    return np.array(rows, dtype=np.float64).reshape(len(rows), len(used)), np.array(lines, dtype=np.int64)


def read_table(
    path: str | Path,
    *,
    delimiter: str = ",",
    columns: Sequence[str] | None = None,
    decimal_comma: bool = False,
    allow_empty: Sequence[str] = (),
    other_delimiter_fix: str = "",
) -> Table:
    """Parse a delimited text file with a header into float64 columns.

    ``columns=None`` parses every column (and requires every header name to be present and
    unique); otherwise only the named ones, so unused columns may hold anything but must still
    have a field on every row. Lines starting with ``#`` are comments (``# key=value`` ones land
    in ``meta``), blank lines are skipped. Every value is finite: ``nan``/``inf`` words and overflows
    such as ``1e999`` are refused with the cell's text. A header that is one
    column holding another common delimiter is refused, ``other_delimiter_fix`` saying what to do.

    ``decimal_comma``: numbers are written ``1,5`` (the delimiter is then not a comma). Empty
    fields of the ``allow_empty`` columns read as NaN (a channel logged more slowly than the rest).
    """
    source = str(path)
    data = _read_bytes(Path(path))
    meta: dict[str, str] = {}
    meta_lines: dict[str, int] = {}
    preamble = _read_preamble(data, source, delimiter, meta, meta_lines, other_delimiter_fix)
    used = _select_columns(source, preamble, columns)
    names = preamble.names
    if decimal_comma:
        data = data[: preamble.body_start] + data[preamble.body_start :].replace(b",", b".")
    empty_ok = frozenset(j for j in used if names[j] in allow_empty)
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
            values, lines = _scan_chunk(
                chunk, line, names, used, delimiter, source, meta, meta_lines, empty_ok
            )
            blocks.append(values)
            line_blocks.append(lines)
        pos, line = end, line + n_lines

    values = np.concatenate(blocks) if blocks else np.empty((0, len(used)))
    lines = np.concatenate(line_blocks) if line_blocks else np.empty(0, dtype=np.int64)
    parsed = {names[j]: np.ascontiguousarray(values[:, k]) for k, j in enumerate(used)}
    return Table(source, names, preamble.header_line, parsed, lines, meta, meta_lines)


# --------------------------------------------------------------------------- writing


def write_table(
    path: str | Path,
    columns: dict[str, np.ndarray],
    formats: Sequence[str],
    meta: Sequence[tuple[str, str]] = (),
    *,
    delimiter: str = ",",
) -> None:
    """Write ``# key=value`` lines, the header and the rows, each column with its printf format.

    Writes ``path`` directly: wrap the call in :func:`trainer.errors.atomic_output` so that a
    failure leaves no partial file.
    """
    names = list(columns)
    row_format = delimiter.join(formats) + "\n"
    arrays = [np.asarray(columns[name], dtype=np.float64) for name in names]
    n = len(arrays[0])
    with open(path, "w", encoding="utf-8", newline="\n") as out:
        for key, value in meta:
            out.write(f"# {key}={value}\n")
        out.write(delimiter.join(names) + "\n")
        for start in range(0, n, WRITE_CHUNK_ROWS):
            block = np.column_stack([a[start : start + WRITE_CHUNK_ROWS] for a in arrays])
            out.write((row_format * len(block)) % tuple(block.ravel().tolist()))
