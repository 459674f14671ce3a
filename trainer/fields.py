"""One field validator: typed access to a nested dict with one-line errors naming the field.

A parsed document (a TOML configuration, a checkpoint's payload) is validated table by table.
:class:`Fields` holds what every reader shares: the source named at the start of every error,
the dotted path of the table, key look-up with a record of the keys read, sub-tables, and the
rejection of unknown keys. Two wordings of the messages exist, fixed by the files' users and
tests, so the subclasses only say how a field is named and how its value is checked:

* :class:`TableFields` (TOML configuration): ``<source>: [recording] rate must be > 0, got 0``;
  numbers must be TOML numbers (never strings or booleans).
* :class:`DottedFields` (checkpoint payload): ``<source>: field 'payload.rate_hz' is missing``;
  numbers are anything ``float()`` takes (tensors, numpy scalars), arrays anything numpy takes.
"""

from __future__ import annotations

import math
import sys
import tomllib
from typing import Any, NoReturn, Self

import numpy as np

from trainer.errors import UserError

NUMBER_RULES = ("finite", "positive", "nonnegative")


def parse_toml(text: str, source: str) -> dict[str, Any]:
    """A TOML document; invalid TOML or nesting too deep for the parser is a one-line UserError."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{source}: invalid TOML ({exc})") from None
    except RecursionError:
        raise UserError(
            f"{source}: invalid TOML (arrays or tables nested deeper than about {sys.getrecursionlimit()} levels)"
        ) from None


def show(value: Any, limit: int = 40) -> str:
    """``repr`` of a value for a message, shortened so the message stays one readable line."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


class Fields:
    """One table (dict) of a document: ``data`` at dotted ``path`` of the file ``source``."""

    def __init__(self, source: str, data: Any, path: str) -> None:
        self.source, self.data, self.path = source, data, path
        self.used: set[str] = set()
        if not isinstance(data, dict):
            self.fail(self.not_a_table(data))

    # ---- wording, set by the subclass
    def not_a_table(self, data: Any) -> str:
        raise NotImplementedError

    def missing(self, key: str) -> str:
        raise NotImplementedError

    def unknown(self, key: str, expected: str) -> str:
        raise NotImplementedError

    # ---- shared mechanics
    def error(self, message: str) -> UserError:
        """The one-line error ``<source>: <message>``."""
        return UserError(f"{self.source}: {message}")

    def fail(self, message: str) -> NoReturn:
        raise self.error(message)

    def name(self, key: str) -> str:
        """Dotted name of ``key`` in the document."""
        return f"{self.path}.{key}" if self.path else key

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str) -> Any:
        """The value of a required ``key``, unchecked."""
        if key not in self.data:
            self.fail(self.missing(key))
        self.used.add(key)
        return self.data[key]

    def sub(self, key: str) -> Self:
        """The sub-table ``key``, as a reader of the same kind."""
        return type(self)(self.source, self.raw(key), self.name(key))

    def only(self, allowed: tuple[str, ...]) -> None:
        """Reject unknown keys first: a typo is the cause, the "missing" key its symptom."""
        for key in self.data:
            if key not in allowed:
                self.fail(self.unknown(key, ", ".join(allowed)))

    def finish(self, hint: tuple[str, ...] | None = None) -> None:
        """Reject keys nobody read: typos must not pass silently."""
        unread = [k for k in self.data if k not in self.used]
        if unread:
            expected = ", ".join(hint) if hint is not None else ", ".join(sorted(self.used)) or "none"
            self.fail(self.unknown(unread[0], expected))


class TableFields(Fields):
    """A TOML table: errors read ``<source>: [<path>] <key> <problem>``."""

    def error(self, message: str) -> UserError:
        """The one-line error ``<source>: [<path>] <message>``."""
        return super().error(f"[{self.path}] {message}")

    def not_a_table(self, data: Any) -> str:
        return f"must be a table, got {show(data)}"

    def missing(self, key: str) -> str:
        return f"missing {key}"

    def unknown(self, key: str, expected: str) -> str:
        return f"unknown key {key!r} (expected: {expected})"

    def number(self, key: str, rule: str = "finite", default: float | None = None) -> float:
        """A TOML number obeying ``rule``; ``default`` (if given) when the key is absent."""
        if key not in self.data and default is not None:
            return default
        return self.check_number(key, self.raw(key), rule)

    def check_number(self, label: str, value: Any, rule: str = "finite") -> float:
        """``value`` (called ``label`` in errors) as a float if it is a finite number obeying
        ``rule`` (one of :data:`NUMBER_RULES`): for numbers that are not directly under a key."""
        if isinstance(value, bool) or not isinstance(value, int | float):
            self.fail(f"{label} must be a number, got {show(value)}")
        number = float(value)
        if not math.isfinite(number):
            self.fail(f"{label} must be finite, got {show(value)}")
        if rule == "positive" and not number > 0:
            self.fail(f"{label} must be > 0, got {show(value)}")
        if rule == "nonnegative" and not number >= 0:
            self.fail(f"{label} must be >= 0, got {show(value)}")
        return number

    def string(self, key: str, choices: tuple[str, ...] | None = None, default: str | None = None) -> str:
        """A string, one of ``choices`` if given; ``default`` (if given) when the key is absent."""
        if key not in self.data and default is not None:
            return default
        value = self.raw(key)
        if not isinstance(value, str):
            self.fail(f"{key} must be a string, got {show(value)}")
        if choices is not None and value not in choices:
            self.fail(f"{key} must be one of {', '.join(choices)}, got {value!r}")
        return value


class DottedFields(Fields):
    """A checkpoint dict: errors read ``<source>: field '<path>.<key>' <problem>``."""

    def not_a_table(self, data: Any) -> str:
        return f"field '{self.path}' must be a dict, got {type(data).__name__}"

    def missing(self, key: str) -> str:
        return f"field '{self.name(key)}' is missing"

    def unknown(self, key: str, expected: str) -> str:
        return f"field '{self.name(key)}' is unknown (expected: {expected})"

    def number(self, key: str, *, positive: bool = False) -> float:
        """Anything ``float()`` takes, finite (and > 0 if ``positive``)."""
        value = self.raw(key)
        try:
            result = float(value)
        except (TypeError, ValueError):
            self.fail(f"field '{self.name(key)}' must be a number, got {value!r}")
        if not math.isfinite(result) or (positive and result <= 0):
            self.fail(
                f"field '{self.name(key)}' must be a finite{' positive' if positive else ''} number, "
                f"got {result!r}"
            )
        return result

    def integer(self, key: str, lo: int, hi: int) -> int:
        """A whole number in ``[lo, hi]`` (``3.0`` is accepted)."""
        value = self.number(key)
        if value != int(value) or not lo <= value <= hi:
            self.fail(f"field '{self.name(key)}' must be an integer in [{lo}, {hi}], got {value!r}")
        return int(value)

    def array(self, key: str, shape: tuple[int, ...]) -> np.ndarray:
        """A finite float64 copy of an array-like (tensors included) of exactly ``shape``."""
        value = self.raw(key)
        try:
            given = np.asarray(value.detach().cpu().double().numpy() if hasattr(value, "detach") else value)
        except (TypeError, ValueError):
            self.fail(f"field '{self.name(key)}' must be an array of numbers")
        if given.dtype.kind not in "iuf":  # numpy would read text ("12", full-width "１２") as a number
            self.fail(f"field '{self.name(key)}' must be an array of numbers, got {show(value)}")
        arr = given.astype(np.float64)
        if arr.shape != shape:
            self.fail(f"field '{self.name(key)}' must have shape {shape}, got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            self.fail(f"field '{self.name(key)}' holds NaN or inf")
        return arr.copy()

    def numbers(self, key: str, count: int, *, positive: bool = False) -> tuple[float, ...]:
        """``count`` finite numbers (each > 0 if ``positive``)."""
        arr = self.array(key, (count,))
        if positive and np.any(arr <= 0):
            self.fail(f"field '{self.name(key)}' must be positive, got {arr.tolist()}")
        return tuple(float(v) for v in arr)
