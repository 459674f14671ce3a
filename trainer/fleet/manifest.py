"""The fleet manifest: which units, which recordings, which methods (CSV or TOML; docs/fleet.md).

TOML carries fleet-wide settings in ``[fleet]`` and one ``[[unit]]`` table per unit; CSV is the
spreadsheet form, one row per unit (columns ``id``, ``recordings``, and optionally ``methods``,
``export_name``, ``import``; lists separated by ``;``) with the default settings. Paths are
relative to the manifest's directory. Everything is checked here, before any work is submitted:
a bad manifest is one line naming the file, the unit and the field.
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from codegen.render import validate_name
from trainer import methods as registry
from trainer.data.holdout import parse_holdout
from trainer.errors import UserError
from trainer.fields import TableFields, parse_toml, show
from trainer.fleet import options

DEFAULT_HOLDOUT = "last:0.25"  # a `--holdout` spec (trainer/data/holdout.py), as `trainer report` takes
DEFAULT_DIAGNOSE_HOLDOUT = 0.25
LIST_SEPARATOR = ";"  # inside one CSV cell
UNIT_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")  # a directory name on every system
FLEET_KEYS = (
    "methods",
    "method_options",
    "import",
    "sim",
    "holdout",
    "diagnose_holdout",
    "diagnose_blocks",
)
UNIT_KEYS = ("id", "recordings", "methods", "export_name", "import")
CSV_COLUMNS = ("id", "recordings", "methods", "export_name", "import")


@dataclass(frozen=True)
class FleetSettings:
    """What every unit shares. ``method_options``: method -> its ``trainer fit`` option text."""

    methods: tuple[str, ...] = field(default_factory=lambda: default_methods())
    method_options: dict[str, str] = field(default_factory=dict)
    import_text: str = ""
    sim: Path | None = None  # the physics the finder starts from (default: bias_poly + noise)
    holdout: str = DEFAULT_HOLDOUT  # the part scored when a unit has one recording (a --holdout spec)
    diagnose_holdout: float = DEFAULT_DIAGNOSE_HOLDOUT
    diagnose_blocks: int | None = None  # None: the finder's default


@dataclass(frozen=True)
class UnitSpec:
    """One unit: the first recording is fitted and diagnosed, the second (if any) evaluated."""

    id: str
    recordings: tuple[Path, ...]
    methods: tuple[str, ...]
    export_name: str
    import_text: str  # '' = the files are recordings (.csv/.npz) or flight logs with default options
    fit_kwargs: dict[str, dict[str, Any]] = field(default_factory=dict, compare=False)
    importer: options.UnitImport | None = field(default=None, compare=False)  # how its files are read


@dataclass(frozen=True)
class Manifest:
    source: Path
    settings: FleetSettings
    units: tuple[UnitSpec, ...]


def default_methods() -> tuple[str, ...]:
    """The registry's memoryless methods (closed-form fits, well under a second per unit), in
    registry order: a fleet of DLSTM fits takes minutes per unit, so those are asked for by name."""
    return tuple(m.name for m in registry.entries() if m.family == registry.MEMORYLESS and m.in_fit_cli)


def default_export_name(unit_id: str) -> str:
    """``tdc_<id>`` with every character a C identifier cannot hold replaced by ``_``."""
    return re.sub(r"[^A-Za-z0-9_]", "_", f"tdc_{unit_id}")


def _list(value: Any, where: str, what: str) -> tuple[str, ...]:
    """A TOML list of strings or one string with ``;`` separators."""
    items = value.split(LIST_SEPARATOR) if isinstance(value, str) else value
    if not isinstance(items, list | tuple) or not all(isinstance(i, str) for i in items):
        raise UserError(f"{where}: {what} must be a list of strings, got {show(value)}")
    cleaned = tuple(i.strip() for i in items if i.strip())
    if not cleaned:
        raise UserError(f"{where}: {what} is empty")
    return cleaned


def _methods(value: Any, where: str) -> tuple[str, ...]:
    names = _list(value, where, "methods")
    for name in names:
        options.check_method(name, f"{where}: methods")
    if len(set(names)) != len(names):
        raise UserError(f"{where}: methods lists a method twice: {', '.join(names)}")
    return names


def _holdout(table: TableFields) -> str:
    """The ``holdout`` spec, checked by the parser ``trainer report --holdout`` uses; stored as text."""
    if table.has("eval_fraction"):
        table.fail(
            'eval_fraction is now holdout, a --holdout spec: holdout = "last:F" (or F, first:F, T0:, :T1)'
        )
    value = table.raw("holdout") if table.has("holdout") else DEFAULT_HOLDOUT
    if isinstance(value, bool) or not isinstance(value, str | int | float):
        table.fail(f'holdout must be a --holdout spec such as "last:0.25", got {show(value)}')
    try:
        parse_holdout(str(value))
    except UserError as exc:
        table.fail(f"holdout: {exc}")
    return str(value).strip()


def _settings(table: TableFields, base: Path) -> FleetSettings:
    holdout_spec = _holdout(table)
    table.only(FLEET_KEYS)
    where = f"{table.source}: [fleet]"
    methods = _methods(table.raw("methods"), where) if table.has("methods") else default_methods()
    method_options: dict[str, str] = {}
    if table.has("method_options"):
        sub = table.sub("method_options")
        for name in sub.data:
            options.check_method(name, f"{where} method_options")
            method_options[name] = options.canonical(sub.string(name), f"{where} method_options.{name}")
            options.fit_kwargs(name, method_options[name], f"{where} method_options.{name}")  # check now
    import_text = options.canonical(table.string("import", default=""), f"{where} import")
    if import_text:
        options.UnitImport.parse(import_text, f"{where} import")  # syntax; each unit's files in _unit
    sim = base / table.string("sim") if table.has("sim") else None
    if sim is not None and not sim.is_file():
        raise UserError(f"{where}: sim {sim}: no such file")
    holdout = table.number("diagnose_holdout", "nonnegative", DEFAULT_DIAGNOSE_HOLDOUT)
    if not holdout < 0.5:
        table.fail(f"diagnose_holdout must be < 0.5, got {holdout}")
    blocks = None
    if table.has("diagnose_blocks"):
        number = table.number("diagnose_blocks", "positive")
        if number != int(number) or number < 50:
            table.fail(f"diagnose_blocks must be a whole number >= 50, got {number:g}")
        blocks = int(number)
    return FleetSettings(methods, method_options, import_text, sim, holdout_spec, holdout, blocks)


def _unit(raw: dict[str, Any], where: str, base: Path, settings: FleetSettings) -> UnitSpec:
    unknown = [k for k in raw if k not in UNIT_KEYS]
    if unknown:
        raise UserError(f"{where}: unknown key {unknown[0]!r} (expected: {', '.join(UNIT_KEYS)})")
    unit_id = raw.get("id")
    if not isinstance(unit_id, str) or not UNIT_ID.match(unit_id):
        raise UserError(
            f"{where}: id must be 1-64 letters, digits, '.', '_' or '-' (a directory name), got {show(unit_id)}"
        )
    where = f"{where} ({unit_id})"
    if "recordings" not in raw:
        raise UserError(f"{where}: recordings is missing")
    recordings = tuple(base / p for p in _list(raw["recordings"], where, "recordings"))
    if len(recordings) > 2:
        raise UserError(
            f"{where}: recordings lists {len(recordings)} files; give 1 (fit) or 2 (fit, evaluate)"
        )
    methods = _methods(raw["methods"], where) if raw.get("methods") else settings.methods
    export_name = raw.get("export_name") or default_export_name(unit_id)
    if not isinstance(export_name, str):
        raise UserError(f"{where}: export_name must be a string, got {show(export_name)}")
    try:
        validate_name(export_name)
    except UserError as exc:
        raise UserError(f"{where}: export_name {str(exc).removeprefix('--name ')}") from None
    import_text = raw.get("import") or settings.import_text
    if not isinstance(import_text, str):
        raise UserError(
            f"{where}: import must be a string of 'trainer import' options, got {show(import_text)}"
        )
    import_text = options.canonical(import_text, f"{where} import")
    importer = options.UnitImport.parse(import_text, f"{where} import")
    for path in recordings:  # options that cannot apply to a file's kind: one line, nothing run
        importer.check(path)
    kwargs = {m: options.fit_kwargs(m, settings.method_options.get(m, ""), where) for m in methods}
    return UnitSpec(unit_id, recordings, methods, export_name, import_text, kwargs, importer)


def _read_toml(path: Path) -> tuple[FleetSettings, list[tuple[str, dict[str, Any]]]]:
    data = parse_toml(_text(path), str(path))
    top = TableFields(str(path), data, "")
    top.only(("fleet", "unit"))
    settings = _settings(top.sub("fleet"), path.parent) if top.has("fleet") else FleetSettings()
    units = data.get("unit", [])
    if not isinstance(units, list) or not all(isinstance(u, dict) for u in units):
        raise UserError(f"{path}: 'unit' must be an array of tables ([[unit]])")
    return settings, [(f"{path}: unit {i + 1}", u) for i, u in enumerate(units)]


def _text(path: Path) -> str:
    """The manifest's text; a file that is not UTF-8 text is the user's, in one line."""
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise UserError(f"{path}: not UTF-8 text (byte {exc.start}): a binary file, not a manifest") from None
    except OSError as exc:
        raise UserError(f"{path}: cannot read the manifest ({exc.strerror})") from None


def _read_csv(path: Path) -> tuple[FleetSettings, list[tuple[str, dict[str, Any]]]]:
    with io.StringIO(_text(path), newline="") as handle:
        reader = csv.DictReader(row for row in handle if not row.lstrip().startswith("#"))
        header = reader.fieldnames or []
        for index, name in enumerate(header):
            if name not in CSV_COLUMNS:
                raise UserError(f"{path}: unknown column {name!r} (expected: {', '.join(CSV_COLUMNS)})")
            if name in header[:index]:  # DictReader would keep the last one silently
                raise UserError(
                    f"{path}: column {name!r} appears twice in the header (columns {header.index(name) + 1} "
                    f"and {index + 1})"
                )
        for required in ("id", "recordings"):
            if required not in header:
                raise UserError(f"{path}: column {required!r} is missing")
        rows = []
        for row in reader:
            if None in row:
                raise UserError(f"{path}: line {reader.line_num}: more cells than columns")
            cells = {k: v.strip() for k, v in row.items() if v is not None and v.strip()}
            if cells:
                rows.append((f"{path}: line {reader.line_num}", cells))
    return FleetSettings(), rows


def load_manifest(path: str | Path) -> Manifest:
    """Read and check a ``.toml`` or ``.csv`` manifest."""
    source = Path(path)
    if not source.is_file():
        raise UserError(f"{source}: no such manifest")
    suffix = source.suffix.lower()
    if suffix not in (".toml", ".csv"):
        raise UserError(f"{source}: a manifest is .toml or .csv, not {suffix or 'without extension'}")
    base = source.resolve().parent
    settings, raw_units = (_read_toml if suffix == ".toml" else _read_csv)(source)
    if settings.sim is not None:
        settings = FleetSettings(**{**settings.__dict__, "sim": settings.sim.resolve()})
    units = [_unit(raw, where, base, settings) for where, raw in raw_units]
    if not units:
        raise UserError(f"{source}: lists no units")
    seen: dict[str, int] = {}
    for index, unit in enumerate(units):
        if unit.id in seen:
            raise UserError(
                f"{source}: unit id {unit.id!r} appears twice (units {seen[unit.id] + 1} and {index + 1})"
            )
        seen[unit.id] = index
    return Manifest(source, settings, tuple(units))
