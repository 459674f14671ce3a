"""A unit's cache key and its all-or-nothing result directory ``OUTDIR/units/ID/``.

The key is the SHA-256 of everything that decides a unit's result: the content of its recordings
and of the finder's simulation, the methods with their option text, the import options, the
export name, the fleet's evaluation and diagnosis settings and the tool's version. A restarted run
skips a unit whose ``result.json`` carries the same key, so nothing is computed twice; a changed
file or setting changes the key and the unit is computed again.

A unit's files are written into a hidden staging directory beside it and renamed into place, with
``result.json`` among them: a unit directory either holds a whole result or does not exist.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from pathlib import Path

from trainer import __version__
from trainer.errors import UserError, raise_write_error
from trainer.fleet.manifest import FleetSettings, UnitSpec
from trainer.fleet.result import RESULT_FILE, UnitResult

UNITS_DIR = "units"
_STAGING_PREFIX = "."  # staging and retired directories are hidden and cleaned at the next start
_CHUNK_BYTES = 1 << 20


def file_sha256(path: Path, where: str) -> str:
    digest = hashlib.sha256()
    try:
        with open(path, "rb") as handle:
            while chunk := handle.read(_CHUNK_BYTES):
                digest.update(chunk)
    except OSError as exc:
        raise UserError(f"{where}: {path}: cannot read ({exc.strerror})") from None
    return digest.hexdigest()


def unit_key(unit: UnitSpec, settings: FleetSettings) -> str:
    """The unit's cache key (hex SHA-256); an unreadable recording is a :class:`UserError`."""
    where = f"unit {unit.id}"
    document = {
        "version": __version__,
        "recordings": [file_sha256(p, where) for p in unit.recordings],
        "methods": {m: settings.method_options.get(m, "") for m in unit.methods},
        "export_name": unit.export_name,
        "import": unit.import_text,
        "sim": None if settings.sim is None else file_sha256(settings.sim, "[fleet] sim"),
        "holdout": settings.holdout,
        "diagnose_holdout": settings.diagnose_holdout,
        "diagnose_blocks": settings.diagnose_blocks,
    }
    return hashlib.sha256(json.dumps(document, sort_keys=True).encode()).hexdigest()


def unit_dir(out_dir: Path, unit_id: str) -> Path:
    return out_dir / UNITS_DIR / unit_id


def read_result(out_dir: Path, unit_id: str) -> UnitResult | None:
    """The unit's stored ``result.json``, or None when there is none (or it is unreadable)."""
    return UnitResult.read(unit_dir(out_dir, unit_id) / RESULT_FILE)


def is_done(out_dir: Path, unit_id: str, key: str) -> bool:
    """A finished result of the same inputs and settings (an infrastructure failure is retried)."""
    result = read_result(out_dir, unit_id)
    return result is not None and result.key == key and not result.retry


def clean_staging(out_dir: Path) -> None:
    """Remove what an interrupted run left half-written (hidden staging/retired directories)."""
    units = out_dir / UNITS_DIR
    if units.is_dir():
        for entry in units.iterdir():
            if entry.name.startswith(_STAGING_PREFIX) and entry.is_dir():
                shutil.rmtree(entry, ignore_errors=True)


def publish_unit(out_dir: Path, unit_id: str, files: dict[str, bytes]) -> Path:
    """Write ``files`` (relative path -> content) as ``units/ID/``, replacing an older result whole."""
    units = out_dir / UNITS_DIR
    units.mkdir(parents=True, exist_ok=True)
    target = units / unit_id
    staging = Path(tempfile.mkdtemp(prefix=f"{_STAGING_PREFIX}{unit_id}.", suffix=".part", dir=units))
    try:
        for relative, content in sorted(files.items()):
            path = staging / relative
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(content)
            os.chmod(path, 0o644)
        os.chmod(staging, 0o755)
        retired = None
        if target.exists():
            retired = Path(tempfile.mkdtemp(prefix=f"{_STAGING_PREFIX}{unit_id}.", suffix=".old", dir=units))
            os.replace(target, retired / unit_id)
        os.replace(staging, target)
        if retired is not None:
            shutil.rmtree(retired, ignore_errors=True)
    except BaseException as exc:
        shutil.rmtree(staging, ignore_errors=True)
        raise_write_error(exc, target)
        raise
    return target
