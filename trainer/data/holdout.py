"""``--holdout``: train on one part of a single recording and score on the rest.

For users with one chamber run. The held-out part touches one end of the recording so that the
training part stays one contiguous run (stateful methods see no jump):

- ``F`` or ``last:F``: the last fraction ``F`` (0 < F < 1) is held out, training on the first part;
- ``first:F``: the first fraction ``F`` is held out, training on the last part;
- ``T0:`` / ``:T1``: by time in seconds from the recording's start: from ``T0`` to the end, or
  from the start to ``T1``.

:func:`overlap_warning` says when validation data is (part of) the training data.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from trainer.data.recording import TIME_ORIGIN_META, Recording, data_fingerprint
from trainer.errors import UserError
from trainer.train_stats import TrainStats

MIN_ROWS = 16  # each part must hold at least this many samples
Side = Literal["first", "last"]


@dataclass(frozen=True)
class Holdout:
    """Which end is held out, by fraction of the rows or by a time boundary (seconds from start)."""

    side: Side
    fraction: float | None = None
    boundary_s: float | None = None

    @property
    def spec(self) -> str:
        """The ``--holdout`` text that gives this split (``last:0.5``, ``:1500``: the part before 1500 s)."""
        if self.fraction is not None:
            return f"{self.side}:{self.fraction:g}"
        return f":{self.boundary_s:g}" if self.side == "first" else f"{self.boundary_s:g}:"

    def describe(self) -> str:
        amount = f"{100 * self.fraction:g} %" if self.fraction is not None else f"{self.boundary_s:g} s"
        if self.boundary_s is not None:
            where = "before" if self.side == "first" else "after"
            return f"held out: the part {where} t = {amount}, training on the rest"
        return f"held out: the {self.side} {amount} of the rows, training on the rest"


def parse_holdout(spec: str) -> Holdout:
    """``F``, ``first:F``, ``last:F``, ``T0:`` or ``:T1``; a one-line UserError otherwise."""
    text = spec.strip()

    def number(value: str, what: str) -> float:
        try:
            x = float(value)
        except ValueError:
            x = math.nan
        if not math.isfinite(x):
            raise UserError(f"--holdout {spec!r}: {what} {value!r} is not a number")
        return x

    def fraction(value: str) -> float:
        f = number(value, "fraction")
        if not 0 < f < 1:
            raise UserError(f"--holdout {spec!r}: the fraction must lie strictly between 0 and 1")
        return f

    side, colon, rest = text.partition(":")
    if not colon:
        return Holdout("last", fraction=fraction(text))
    if side in ("first", "last"):
        return Holdout(side, fraction=fraction(rest))  # type: ignore[arg-type]
    if side and not rest:
        return Holdout("last", boundary_s=number(side, "time"))
    if rest and not side:
        return Holdout("first", boundary_s=number(rest, "time"))
    raise UserError(
        f"--holdout {spec!r}: use F, first:F, last:F (fractions) or T0: / :T1 (seconds); the held-out "
        "part must touch the start or the end so that the training part stays one run"
    )


def split(rec: Recording, holdout: Holdout) -> tuple[Recording, Recording]:
    """(training part, held-out part) of ``rec``."""
    n = len(rec)
    if holdout.fraction is not None:
        held = round(holdout.fraction * n)
        cut = n - held if holdout.side == "last" else held
    else:
        assert holdout.boundary_s is not None
        cut = int(np.searchsorted(rec.time_s - rec.time_s[0], holdout.boundary_s, side="left"))
    first, last = rec.slice(0, cut), rec.slice(cut, n)
    for part in (first, last):  # its times count from the run's start, as --holdout's T does
        part.meta[TIME_ORIGIN_META] = repr(rec.time_origin_s)
    if min(len(first), len(last)) < MIN_ROWS:
        duration_s = float(rec.time_s[-1] - rec.time_s[0])
        beyond = (
            f" (T counts from the recording's start: 0 .. {duration_s:g} s here)"
            if holdout.boundary_s is not None and not 0.0 < holdout.boundary_s < duration_s
            else ""
        )
        train_rows, held_rows = (len(first), len(last)) if holdout.side == "last" else (len(last), len(first))
        raise UserError(
            f"{rec.source}: --holdout leaves {train_rows} rows to train on and {held_rows} held out; each "
            f"part needs at least {MIN_ROWS}{beyond}"
        )
    return (first, last) if holdout.side == "last" else (last, first)


def _same_file(a: str, b: str) -> bool:
    try:
        return Path(a).resolve() == Path(b).resolve()
    except OSError:
        return a == b


def training_part(train_stats: TrainStats, rec: Recording) -> Recording | None:
    """The rows of ``rec`` that are the model's training data, proved by content (``data_sha256``):
    whatever the path, the working directory or a copy of the file. None when ``rec`` does not hold
    them (another run, or a model without a recorded time range)."""
    if train_stats.time_range_s is None:
        return None
    lo, hi = train_stats.time_range_s
    start = int(np.searchsorted(rec.time_s, lo, side="left"))
    part = rec.slice(start, int(np.searchsorted(rec.time_s, hi, side="right")))
    if train_stats.n_samples is not None and len(part) != train_stats.n_samples:  # cheap first test
        return None
    return part if data_fingerprint(part) == train_stats.data_sha256 else None


def overlap_warning(
    train_stats: TrainStats,
    valid: Recording,
    fingerprint: str,
    *,
    whole: Recording | None = None,
    what: str = "validation",
) -> str | None:
    """A warning when ``valid`` is the training data or overlaps it, one line.

    ``train_stats`` is :func:`trainer.fitting.training_stats` of the training data (also stored in
    ``model.pt``); ``fingerprint`` is :func:`trainer.data.recording.data_fingerprint` of ``valid``;
    ``whole`` the recording ``valid`` was cut from (``--holdout``) and ``what`` names ``valid`` in the
    message. Overlap is proved by content (the training rows' fingerprint found in ``whole``) or by
    the same file and overlapping times.
    """
    if train_stats.data_sha256 == fingerprint:
        return (
            f"warning: the {what} data is the training data: every score is in-sample and says "
            "nothing about a new run (use another recording or --holdout)"
        )
    share = training_row_share(train_stats, valid, fingerprint, whole=whole)
    if share is None or train_stats.time_range_s is None:
        return None
    lo, hi = train_stats.time_range_s
    return (
        f"warning: {100 * share:.1f} % of the {what} rows are training rows (the model was trained on "
        f"t = {lo:g} .. {hi:g} s of this recording, {train_stats.source or 'source unnamed'}): "
        "those scores are in-sample"
    )


def training_row_share(
    train_stats: TrainStats, valid: Recording, fingerprint: str, *, whole: Recording | None = None
) -> float | None:
    """The share of ``valid``'s rows the model was trained on (1.0: it is the training data), or None
    when it holds none (:func:`overlap_warning`'s proof: content, or the same file and times)."""
    if train_stats.data_sha256 == fingerprint:
        return 1.0
    if train_stats.time_range_s is None:
        return None
    lo, hi = train_stats.time_range_s
    inside = (valid.time_s >= lo) & (valid.time_s <= hi)
    if not np.any(inside):
        return None
    source = train_stats.source or ""
    if (source and _same_file(source, valid.source)) or training_part(
        train_stats, whole or valid
    ) is not None:
        return float(np.mean(inside))
    return None


def part_left_for_training(rec: Recording, spec: str | None) -> Recording:
    """The part of ``rec`` that ``--holdout spec`` leaves for training (all of it without one)."""
    return rec if spec is None else split(rec, parse_holdout(spec))[0]
