"""A unit's ``result.json``: one record, written by the run and read by the cache and the report.

:class:`UnitResult` declares the file's fields once. :meth:`UnitResult.to_json` writes strict,
stable JSON (sorted keys, NaN/inf as null); :meth:`UnitResult.from_dict` reads a file written by
this or an older version (fields added since default to empty). The per-method summaries and the
diagnosis summary stay plain JSON tables (:func:`trainer.fleet.stages.drift_left_summary`,
:func:`trainer.fleet.stages.diagnosis_summary` write them).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, Literal, Self

from trainer.fleet.manifest import UnitSpec

RESULT_FILE = "result.json"
Status = Literal["ok", "failed"]
OK: Final = "ok"
FAILED: Final = "failed"


def json_bytes(value: Any) -> bytes:
    """Stable JSON (sorted keys, two-space indent, newline at the end)."""
    return (json.dumps(value, indent=2, sort_keys=True, allow_nan=False) + "\n").encode()


def finite(value: Any) -> Any:
    """NaN/inf (an unobserved score) as None, so that ``result.json`` is strict JSON."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite(v) for v in value]
    return value


@dataclass(frozen=True)
class Failure:
    """A stage that failed (``load``, ``method poly3``, ``export poly3``...): the one-line error, and
    whether a restart should compute it again (``retry``: not the unit's fault but a bug, a lost
    worker or the environment)."""

    stage: str
    error: str
    retry: bool = False

    def to_dict(self) -> dict[str, Any]:
        return {"stage": self.stage, "error": self.error, "retry": self.retry}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Self:
        return cls(str(data["stage"]), str(data["error"]), bool(data.get("retry", False)))


@dataclass(frozen=True)
class UnitResult:
    """What a unit's run produced (``units/ID/result.json``)."""

    id: str
    key: str | None  # trainer.fleet.cache.unit_key; None: the recordings were unreadable
    status: Status
    retry: bool  # a failure a rerun may fix: the unit is not cached as done
    errors: tuple[Failure, ...]
    recordings: tuple[str, ...]
    evaluated_on: str | None  # the scored part (held-out part or validation recording)
    export_name: str
    methods: dict[str, dict[str, Any]]  # method -> its summary, or {"error": ...}
    diagnosis: dict[str, Any] | None  # the finder's summary; None when it did not run
    channel: str | None = None  # the recording's channel and unit label (None: never loaded)
    unit: str | None = None
    import_notes: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return self.status == OK

    @classmethod
    def failed(cls, unit: UnitSpec, key: str | None, error: Failure) -> Self:
        """A unit that never reached scoring: every method carries the one error."""
        return cls(
            id=unit.id,
            key=key,
            status=FAILED,
            retry=error.retry,
            errors=(error,),
            recordings=tuple(str(p) for p in unit.recordings),
            evaluated_on=None,
            export_name=unit.export_name,
            methods={m: {"error": error.error} for m in unit.methods},
            diagnosis=None,
        )

    def to_dict(self) -> dict[str, Any]:
        """The JSON document (NaN/inf as None)."""
        return finite(
            {
                "id": self.id,
                "key": self.key,
                "status": self.status,
                "retry": self.retry,
                "errors": [e.to_dict() for e in self.errors],
                "recordings": list(self.recordings),
                "evaluated_on": self.evaluated_on,
                "channel": self.channel,
                "unit": self.unit,
                "import_notes": list(self.import_notes),
                "export_name": self.export_name,
                "methods": self.methods,
                "diagnosis": self.diagnosis,
            }
        )

    def to_json(self) -> bytes:
        return json_bytes(self.to_dict())

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Self:
        """A stored result; a field written only by newer versions defaults to empty."""
        status = data["status"]
        if status not in (OK, FAILED):
            raise ValueError(f"status {status!r} is not {OK!r} or {FAILED!r}")
        return cls(
            id=str(data["id"]),
            key=data.get("key"),
            status=status,
            retry=bool(data.get("retry", False)),
            errors=tuple(Failure.from_dict(e) for e in data.get("errors", [])),
            recordings=tuple(map(str, data.get("recordings", []))),
            evaluated_on=data.get("evaluated_on"),
            export_name=str(data.get("export_name", "")),
            methods=dict(data.get("methods") or {}),
            diagnosis=data.get("diagnosis"),
            channel=data.get("channel"),
            unit=data.get("unit"),
            import_notes=tuple(data.get("import_notes", [])),
        )

    @classmethod
    def read(cls, path: Path) -> Self | None:
        """The result stored at ``path``, or None when there is none or it is unreadable."""
        try:
            return cls.from_dict(json.loads(path.read_text(encoding="utf-8")))
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            return None
