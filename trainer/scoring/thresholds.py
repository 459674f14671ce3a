"""Sign-off thresholds (``trainer report --config thresholds.toml``): the keys, their meaning, and
a reader that refuses anything else in one line.

The file has one table, ``[thresholds]``; every key is optional and a key that is absent is not
checked. A key that is given but whose measurement is missing (no ``--holdout``, no verify result,
no bench) fails the sign-off as "not measured": a reviewer signs what was measured.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from trainer.errors import UserError
from trainer.fields import parse_toml

Bound = Literal["max", "min"]


@dataclass(frozen=True)
class Threshold:
    """One key: what it bounds, in which unit, and whether the measurement must stay below or above."""

    key: str
    bound: Bound
    unit: str
    meaning: str


THRESHOLDS: dict[str, Threshold] = {
    t.key: t
    for t in (
        Threshold("residual_rms_mg", "max", "mg", "RMS drift left over the whole recording"),
        Threshold("residual_max_mg", "max", "mg", "largest |drift left| over the whole recording"),
        Threshold("branch_rms_mg", "max", "mg", "RMS drift left on the heating and on the cooling branch"),
        Threshold("branch_max_mg", "max", "mg", "largest |drift left| on the heating and the cooling branch"),
        Threshold("holdout_rms_mg", "max", "mg", "RMS drift left on the held-out part (--holdout)"),
        Threshold("holdout_max_mg", "max", "mg", "largest |drift left| on the held-out part (--holdout)"),
        Threshold(
            "min_coverage",
            "min",
            "",
            "share (0..1) of the recording's temperature span inside the trained range",
        ),
        Threshold(
            "max_verify_mismatches", "max", "samples", "codegen verify mismatches (the C vs the golden)"
        ),
        Threshold("max_flash_bytes", "max", "B", "flash of the module (bench, else the manifest's tables)"),
        Threshold("max_ram_bytes", "max", "B", "RAM of the module (bench, else the manifest's state)"),
        Threshold("max_instructions_per_sample", "max", "instructions", "Cortex-M4 cost per sample (bench)"),
    )
}
TABLE = "thresholds"


# Above every limit a sign-off can mean (mg, bytes, instructions, samples); a limit line at 1e308
# cannot even be drawn.
THRESHOLD_MAX = 1e9


def load_thresholds(path: str | os.PathLike[str]) -> dict[str, float]:
    """The ``[thresholds]`` of a TOML file; a bad file, table, key or value is a one-line UserError."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise UserError(f"{p}: cannot read the thresholds ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise UserError(f"{p}: invalid TOML ({exc})") from None
    data = parse_toml(text, str(p))
    extra = sorted(set(data) - {TABLE})
    if extra:
        raise UserError(f"{p}: unknown table or key {extra[0]!r}; the thresholds go in [{TABLE}]")
    table = data.get(TABLE, {})
    if not isinstance(table, dict):
        raise UserError(f"{p}: {TABLE!r} must be a table ([{TABLE}])")
    out: dict[str, float] = {}
    for key, value in table.items():
        if key not in THRESHOLDS:
            raise UserError(
                f"{p}: [{TABLE}] unknown key {key!r}; known keys: {', '.join(THRESHOLDS)} (docs/signoff.md)"
            )
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not 0 <= value <= THRESHOLD_MAX  # NaN fails too
        ):
            raise UserError(
                f"{p}: [{TABLE}] {key} must be a number from 0 to {THRESHOLD_MAX:g}, got {value!r}"
            )
        if key == "min_coverage" and value > 1:
            raise UserError(f"{p}: [{TABLE}] min_coverage is a share between 0 and 1, got {value!r}")
        out[key] = float(value)
    return out


def passes(key: str, measured: float, limit: float) -> bool:
    """``measured`` within ``limit`` (at most for a "max" key, at least for a "min" one)."""
    return measured <= limit if THRESHOLDS[key].bound == "max" else measured >= limit
