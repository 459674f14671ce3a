"""Read and write recordings in the formats of ``shared/specs/recording-format.md``.

This module is the recording format: required columns, metadata, the time-axis and finiteness
rules, the CSV and NPZ layouts. The CSV text itself is read and written by the generic engine of
:mod:`trainer.data.csv_table` (fast chunked parsing, one-line errors naming line and column).

CSV output keeps enough digits for the tool, not every bit: ``time_s`` with 6 decimals (more
when the sampling period is under 1 ms, so rounding stays below 0.1 % of a period) and every
other column with 10 significant digits (relative error <= 5e-10, far below any sensor's
resolution). NPZ output is exact. Reading a CSV written here and writing it again gives the
same bytes.
"""

from __future__ import annotations

import math
import os
import zipfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Literal, NamedTuple

import numpy as np
from scipy.optimize import minimize_scalar

from trainer.budget import FLOAT_BYTES, check_memory
from trainer.data.channels import channels_in, own_temp_column
from trainer.data.csv_table import META_KEY, quote, read_table, write_table
from trainer.data.flightlog import A_KIND, data_column, flight_log_at
from trainer.data.recording import ONE_AXIS_COLUMNS, Recording, require_rows
from trainer.errors import SWAPPED_HINT, UserError, atomic_output

RecordingFormat = Literal["csv", "npz"]
RECORDING_SUFFIXES: dict[str, RecordingFormat] = {".csv": "csv", ".npz": "npz"}
MODEL_SUFFIX = ".pt"  # what trainer fit writes (named when one is given where a recording goes)
CONFIG_SUFFIX = ".toml"  # a physics configuration (named when one is given where a recording goes)

JITTER_LIMIT = 0.01  # largest accepted |step - nominal period| / nominal period
TIME_DECIMALS = 6  # minimum decimals of time_s in CSV output
VALUE_DIGITS = 10  # significant digits of every other CSV column
NPZ_META = "meta"  # name of the optional 0-d string array in .npz files


# --------------------------------------------------------------------------- validation


class TimeProblem(NamedTuple):
    """The first row of a time axis that breaks the contract, and why."""

    row: int
    kind: Literal["not_increasing", "jitter"]
    reason: str


def find_time_problem(
    time: np.ndarray, period: float | None = None, *, jitter: bool = True
) -> TimeProblem | None:
    """First row whose time is not strictly increasing or (``jitter``) that jitters beyond the limit.

    The nominal period is ``period`` when given (the declared ``sample_rate_hz``), else the median
    step. The format accepts "jitter up to 1 % of the period", which a logger meets in either of two
    ways: each step within :data:`JITTER_LIMIT` of the nominal period (a clock that restarts its
    count at every sample), or each timestamp within that of the run's uniform grid (a free-running
    clock read late by up to 1 %, whose steps then differ by up to 2 %). A row is refused only when
    it meets neither: its step is off-nominal and it or the row before lies off the grid (a lost
    sample does both).
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
    limit = (JITTER_LIMIT + 1e-9) * nominal
    off_step = deviation > limit
    if not off_step.any():
        return None
    from_grid = np.abs(grid_offset(time))
    off_grid = from_grid > limit
    off = np.flatnonzero(off_step & (off_grid[1:] | off_grid[:-1]))
    if not off.size:
        return None
    step = int(off[0])
    grid_pct = 100 * max(from_grid[step], from_grid[step + 1]) / nominal
    return TimeProblem(
        step + 1,
        "jitter",
        f"step {steps[step]:.6g} s from the previous row deviates {100 * deviation[step] / nominal:.2f} % "
        f"from the nominal period {nominal:.6g} s, and the two rows lie up to {grid_pct:.2f} % of it off "
        f"the run's uniform grid (limit {100 * JITTER_LIMIT:g} %, for the step or the grid)",
    )


def grid_offset(time: np.ndarray) -> np.ndarray:
    """Each row's time minus the run's uniform grid (seconds), the grid that keeps the largest
    offset smallest (the minimax line: its period minimises the spread of the offsets, a convex
    function searched next to the least-squares period; its phase centres them). A clock read
    within 1 % of its ticks is then within 1 % of this grid, however short or long the file."""
    time = np.asarray(time, dtype=np.float64)
    index = np.arange(time.size, dtype=np.float64)
    centred = index - index.mean()
    since_start = time - time[0]
    least_squares = float(centred @ since_start / max(float(centred @ centred), 1.0))

    def spread(period: float) -> float:
        return float(np.ptp(since_start - period * index))

    steps = max(time.size - 1, 1)
    width = 0.05 * abs(least_squares) / steps  # 5 % of a period over the run: beyond any accepted jitter
    best = minimize_scalar(
        spread,
        bounds=(least_squares - width, least_squares + width),
        method="bounded",
        options={"xatol": 1e-7 * abs(least_squares) / steps},
    )
    period = float(best.x) if best.fun < spread(least_squares) else least_squares
    offset = since_start - period * index
    return offset - 0.5 * (float(offset.max()) + float(offset.min()))


def first_non_finite(columns: dict[str, np.ndarray]) -> tuple[str, int] | None:
    """(column, row) of the first nan/inf, scanning rows in order and columns left to right."""
    best: tuple[int, int, str] | None = None
    for order, (name, values) in enumerate(columns.items()):
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size and (best is None or (int(bad[0]), order) < best[:2]):
            best = (int(bad[0]), order, name)
    return None if best is None else (best[2], best[0])


def missing_required(names: Sequence[str]) -> tuple[str, str] | None:
    """(column, why) of the first required column ``names`` lack, or None.

    ``time_s`` always. ``temp_c`` and ``accel_mg`` are the one-axis recording's; beside named
    channels (``accel0_x_mg``, ``gyro0_x_dps``, ...) the contract makes them optional: ``accel_mg``
    then only serves the commands run without ``--channels``, and ``temp_c`` is needed only by a
    channel without its own ``<sensor><instance>_temp_c``.
    """
    if "time_s" not in names:
        return "time_s", "missing required column"
    channels = channels_in(names)
    if not channels:
        missing = [name for name in ONE_AXIS_COLUMNS if name not in names]
        return (missing[0], "missing required column") if missing else None
    if "temp_c" not in names:
        shared = [c.name for c in channels.values() if c.temp_column == "temp_c"]
        if shared:
            return "temp_c", (
                f"missing: channel {shared[0]} has no temperature column of its own "
                f"({own_temp_column(shared[0])}) and the file has no temp_c"
            )
    return None


def check_recording(
    rec: Recording,
    row_label: Callable[[int], str],
    meta_label: Callable[[str], str],
) -> None:
    """Enforce the contract's rules on parsed data; messages use the caller's row/metadata labels."""
    source = rec.source
    if len(rec.time_s) == 0:
        raise UserError(f"{source}: no data rows")
    require_rows(len(rec.time_s), source)
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
        raise UserError(f"{where}: {quote(text)} is not a positive number")
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
    # a flight log, by its first bytes (one renamed .csv read as text said "not UTF-8 text"), or an
    # output named .ulg: never a recording here, and never to be overwritten by one
    if (kind := flight_log_at(path)) is not None:
        raise UserError(
            f"{path}: {A_KIND[kind]} flight log where a recording (.csv or .npz) is expected: convert it "
            f"with 'trainer import {path} -o NAME.csv' first ({SWAPPED_HINT})"
        )
    if suffix in RECORDING_SUFFIXES:
        return RECORDING_SUFFIXES[suffix]
    if not str(path).strip():  # Path("") is ".", a directory: the message named an empty path
        raise UserError("an empty file name where a recording (.csv or .npz) is expected")
    if Path(path).is_dir():
        raise UserError(f"{path}: a directory, not a recording (.csv or .npz)")
    if suffix == MODEL_SUFFIX:
        raise UserError(
            f"{path}: a model file ({MODEL_SUFFIX}) where a recording (.csv or .npz) is expected ({SWAPPED_HINT})"
        )
    if suffix == CONFIG_SUFFIX:
        raise UserError(
            f"{path}: a physics TOML where a recording (.csv or .npz) is expected ({SWAPPED_HINT})"
        )
    raise UserError(f"{path}: unsupported extension {suffix or '(none)'!r}; recordings are .csv or .npz")


def read_recording(path: str | os.PathLike[str]) -> Recording:
    """Read and validate a recording (``.csv`` or ``.npz``); every violation is a one-line UserError."""
    path = Path(path)
    rec = _read_csv(path) if recording_format(path) == "csv" else _read_npz(path)
    return _accel_mg_is_milli_g(rec)


def _accel_mg_is_milli_g(rec: Recording) -> Recording:
    """The format's ``accel_mg`` is milli-g whatever other metadata say ("``sample_rate_hz`` is the only
    key a reader may rely on"): ``unit`` and ``channel`` name the channel a one-channel command reads
    only when the file holds that channel's own column (``gyro0_x_dps``, as this tool writes a
    gyroscope's view); beside a bare ``accel_mg`` they are ignored."""
    unit = rec.meta.get("unit", "mg")
    if unit == "mg" or rec.channel_column() is not None or "accel_mg" not in rec.columns:
        return rec
    meta = {k: v for k, v in rec.meta.items() if k not in ("unit", "channel")}
    return Recording(rec.columns, meta, rec.source, rec.row_label, rec.accel_column)


def _read_csv(path: str | Path) -> Recording:
    table = read_table(
        path,
        delimiter=",",
        other_delimiter_fix="trainer import converts a file with another delimiter into a recording",
    )
    missing = missing_required(table.names)
    if missing:
        raise UserError(
            f"{table.source}: line {table.header_line} (header), column {missing[0]!r}: {missing[1]} "
            f"(columns: {', '.join(table.names)})"
        )
    if len(table) == 0:
        raise UserError(f"{table.source}: no data rows after the header on line {table.header_line}")
    rec = Recording(table.columns, table.meta, table.source, table.row_label)
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
        if not sep or not META_KEY.fullmatch(key.strip()):
            raise UserError(f"{source}: array {NPZ_META!r}, line {number}: {quote(entry)} is not key=value")
        meta[key.strip()] = value.strip()
    return meta


def _member_name(zipped: zipfile.ZipFile, name: str) -> str:
    """The zip member that holds the array ``name`` (np.savez writes ``name.npy``)."""
    return f"{name}.npy" if f"{name}.npy" in zipped.namelist() else name


def _member_header(zipped: zipfile.ZipFile, member: str) -> tuple[tuple[int, ...], np.dtype[Any]]:
    """Shape and dtype from a ``.npy`` member's header alone: nothing of the data is read."""
    with zipped.open(member) as handle:
        version = np.lib.format.read_magic(handle)
        read_header = (
            np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        )
        shape, _, dtype = read_header(handle)
    return shape, dtype


def _npz_member(archive: np.lib.npyio.NpzFile, name: str, source: str) -> np.ndarray:
    """One member as an array; a member that is not a ``.npy`` array, holds Python objects, or whose
    header promises more data than it holds is a one-line UserError (checked before allocating)."""
    where = f"{source}: column {name!r}"
    zipped = archive.zip
    assert zipped is not None, "an open NpzFile has its zip"
    member = _member_name(zipped, name)
    try:
        shape, dtype = _member_header(zipped, member)
        if dtype.hasobject:  # pickled Python objects: never loaded (their size says nothing of a truncation)
            raise UserError(f"{where}: holds Python objects, not numbers")
        size = zipped.getinfo(member).file_size
        if math.prod(shape) * dtype.itemsize > size:
            raise UserError(
                f"{where}: its header declares {math.prod(shape)} values of {dtype} but the member holds "
                f"{size} bytes (truncated or forged)"
            )
        array = archive[name]
    except UserError:
        raise
    except ValueError as exc:
        if "pickle" in str(exc):
            raise UserError(f"{where}: holds Python objects, not numbers") from None
        raise UserError(f"{where}: not a NumPy array (.npy) member ({exc})") from None
    except Exception as exc:  # zip, I/O and header-parsing errors of a damaged member all mean the same
        raise UserError(f"{where}: unreadable ({type(exc).__name__})") from None
    if not isinstance(array, np.ndarray):
        raise UserError(f"{where}: not a NumPy array (.npy) member")
    return array


def _npz_bytes(archive: np.lib.npyio.NpzFile) -> float:
    """Memory the members take once loaded and converted to float64, from their headers alone
    (a compressed member of 1e10 zeros is a few MB on disk); an unreadable header counts 0 and
    is reported when the member is loaded."""
    total = 0.0
    if archive.zip is None:
        return total
    for name in archive.files:
        try:
            shape, dtype = _member_header(archive.zip, _member_name(archive.zip, name))
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            continue
        total += math.prod(float(n) for n in shape) * (dtype.itemsize + FLOAT_BYTES)
    return total


def _read_npz(path: str | Path) -> Recording:
    source = str(path)
    if Path(path).is_dir():
        raise UserError(f"{source}: is a directory, not a file")
    if not Path(path).is_file():
        raise UserError(f"{source}: no such file")
    try:
        archive = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        try:
            with open(path, "rb") as head:
                start = head.read(64)
        except OSError:
            start = b""
        cause = (
            "a text file named .npz: a CSV recording takes the .csv extension"
            if start.lstrip(b"\xef\xbb\xbf#\r\n ").startswith(b"time_s") or b"time_s," in start
            else "truncated or damaged (a copy cut short?), or not written by numpy.savez"
        )
        raise UserError(f"{source}: not a readable .npz archive ({type(exc).__name__}): {cause}") from None
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise UserError(f"{source}: not a .npz archive (a single .npy array?)")
    columns: dict[str, np.ndarray] = {}
    meta: dict[str, str] = {}
    with archive:
        check_memory(_npz_bytes(archive), f"{source}: loading", "split the recording")
        for name in archive.files:
            array = _npz_member(archive, name, source)
            if name == NPZ_META:
                meta = _parse_npz_meta(source, array)
                continue
            if array.ndim != 1:
                raise UserError(f"{source}: column {name!r}: array has shape {array.shape}, expected 1-D")
            if array.dtype.kind not in "iuf":
                raise UserError(f"{source}: column {name!r}: dtype {array.dtype} is not a real number type")
            columns[name] = array.astype(np.float64)
    missing = missing_required(list(columns))
    if missing:
        raise UserError(f"{source}: column {missing[0]!r}: {missing[1]} (arrays: {', '.join(columns)})")
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
    missing = missing_required(list(rec.columns))
    if missing:
        raise ValueError(f"{rec.source}: cannot write a recording without column {missing[0]!r}")
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
        if not META_KEY.fullmatch(key) or any(c in str(value) for c in "\r\n"):
            raise ValueError(f"{rec.source}: metadata {key!r}={value!r} cannot be written")


def _ordered_meta(meta: dict[str, str]) -> list[tuple[str, str]]:
    first = [("sample_rate_hz", meta["sample_rate_hz"])] if "sample_rate_hz" in meta else []
    return first + [(k, v) for k, v in meta.items() if k != "sample_rate_hz"]


def contract_columns(rec: Recording) -> Recording:
    """``rec`` as the format holds it: ``accel_mg`` is milli-g only, so a gyroscope's or barometer's
    one-channel data (a view, an import of such a channel) goes to its named column (``gyro0_x_dps``;
    dropped when the recording holds that already), which ``channel``/``unit`` metadata point to
    and :meth:`Recording.one_axis_or_none` reads back as ``accel_mg``."""
    unit = rec.meta.get("unit", "mg")
    if unit == "mg" or "accel_mg" not in rec.columns or not rec.meta.get("channel"):
        return rec
    column = data_column(rec.meta["channel"], unit)
    if column in rec.columns:  # an import keeps both: one column, under the channel's own name
        columns = {name: values for name, values in rec.columns.items() if name != "accel_mg"}
    else:
        columns = {(column if name == "accel_mg" else name): values for name, values in rec.columns.items()}
    return Recording(columns, dict(rec.meta), rec.source)


def write_recording(rec: Recording, path: str | Path) -> None:
    """Write every column (unknown ones included) to ``.csv`` or ``.npz``; atomic, nothing left on error.
    A gyroscope's or barometer's data leave ``accel_mg`` for their own column (:func:`contract_columns`)."""
    rec = contract_columns(rec)
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
    time_format = f"%.{csv_time_decimals(np.asarray(rec.time_s))}f"
    value_format = f"%.{VALUE_DIGITS}g"
    formats = [time_format if name == "time_s" else value_format for name in rec.columns]
    write_table(tmp, rec.columns, formats, _ordered_meta(rec.meta))


def _write_npz(rec: Recording, tmp: Path) -> None:
    arrays = {name: np.asarray(values, dtype=np.float64) for name, values in rec.columns.items()}
    if rec.meta:
        arrays[NPZ_META] = np.array("\n".join(f"{k}={v}" for k, v in _ordered_meta(rec.meta)))
    with open(tmp, "wb") as out:
        np.savez(out, allow_pickle=False, **arrays)
