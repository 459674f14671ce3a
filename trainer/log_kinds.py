"""The flight-log kinds this tool reads (PX4 ULog, ArduPilot DataFlash), by their first bytes.

Declared here, below every other module, because both reading (:mod:`trainer.data.flightlog`)
and writing (:func:`trainer.errors.check_output_path`: no output is ever written over a flight
log, whatever its name) need them.
"""

from __future__ import annotations

import os

# File kind -> its first bytes. ULog: "ULog" 0x01 0x12 0x35 (ULog file format, PX4 docs).
# DataFlash: every message starts 0xA3 0x95 <type>, and a log starts with the FMT message (128).
MAGIC: dict[str, bytes] = {"ulog": b"ULog\x01\x12\x35", "dataflash": b"\xa3\x95\x80"}
KIND_NAMES = {"ulog": "PX4 ULog", "dataflash": "ArduPilot DataFlash"}
# with its article, as a message reads it ("a PX4 ULog log", "an ArduPilot DataFlash log")
A_KIND = {kind: f"{'an' if name[0] in 'AEIOU' else 'a'} {name}" for kind, name in KIND_NAMES.items()}
HEAD_BYTES = 16  # enough for every magic above


def kind_of_head(head: bytes) -> str | None:
    """'ulog', 'dataflash' or None from a file's first bytes."""
    return next((kind for kind, magic in MAGIC.items() if head.startswith(magic)), None)


def existing_log_kind(path: str | os.PathLike[str]) -> str | None:
    """The kind of flight log an existing regular file is, else None (also when it cannot be read:
    the caller's own checks say why)."""
    try:
        with open(path, "rb") as handle:
            return kind_of_head(handle.read(HEAD_BYTES))
    except OSError:
        return None
