"""Blocked cross-validation of one real run over its thermal segments.

A single split of one chamber run says little: which end is held out decides the verdict (the
physics compensator won by 72 % at one split of the bundled run and lost by 23 % at another).
Here every thermal segment of the run (each heating, cooling and dwell; :func:`thermal_segments`)
is held out in turn, the method is trained on the rest, and the held-out segment is scored (a run
that does not reverse, a single ramp or a warm-up, is cut into thirds of its temperature span;
:func:`folds_of`):

- **warm**: the model runs from the recording's start, through the training rows, and is scored
  on the segment, as firmware running since power-on;
- **cold**: the model starts at the segment's first sample, as at power-on there (a method's
  history states are then unknown and take their initial values);
- the **natural** start of a fold is cold for a segment that starts the run and warm otherwise;
  the cross-validated figure (:attr:`MethodCV.cv_rms`) pools the natural held-out samples.

Training on a run with a hole: a memoryless method is fitted on the training rows alone (their
order does not matter to it). A method with state needs the temperature history without gaps,
so it sees the whole run's temperature, and the held-out segment's output is replaced by the cubic
fitted on the training rows (:func:`impute_held_out`): those rows then carry no information the
training rows do not have, and the method's filters run through the segment as they would. The
physics fit goes further: the rows are marked (``held_out``), and its least squares give the
marked blocks no weight at all (:class:`trainer.diagnose.gls.Gls`), so it is the fit to the
training rows alone, not pulled towards the imputed cubic.
Recursive methods (the output's own past) cannot be trained on such a run and are not
cross-validated; a single ``--holdout`` split scores them.

Scores are the static drift left of :mod:`trainer.scoring.static` (RMS of the compensated output
about its mean over the held-out segment, after the validation smoothing), in the channel's unit,
over the whole segment and over its samples inside the training temperature range.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from trainer import methods as registry
from trainer.data.holdout import MIN_ROWS
from trainer.data.recording import HELD_OUT_COLUMN, Recording
from trainer.errors import UserError
from trainer.fleet.cluster import TaskMap
from trainer.scoring.static import (
    COOLING,
    HEATING,
    NEITHER,
    RATE_WINDOW_S,
    static_drift_left,
    thermal_branch,
)

MIN_SEGMENT_FRACTION = 0.05  # a thermal run shorter than 5 % of the recording joins its neighbour
MIN_SEGMENT_S = 300.0  # ... and so does one shorter than 5 minutes
MIN_SEGMENTS = 2
RAMP_PARTS = 3  # a run that does not reverse is cut into this many parts (folds_of)
UNCOMPENSATED = "uncompensated"
LABELS = {HEATING: "heating", COOLING: "cooling", NEITHER: "dwell"}


@dataclass(frozen=True)
class Segment:
    """Rows ``start:stop`` of one thermal segment, its label and its time span (s from the start)."""

    start: int
    stop: int
    label: str
    t0_s: float
    t1_s: float
    temp_from_c: float
    temp_to_c: float

    @property
    def name(self) -> str:
        return f"{self.label} {self.t0_s:.0f}-{self.t1_s:.0f} s ({self.temp_from_c:.1f} -> {self.temp_to_c:.1f} degC)"


def rate_window_s(temp_c: np.ndarray, rate_hz: float) -> float:
    """The window of the temperature rate that cuts segments: :data:`RATE_WINDOW_S`, or twice the
    time a ramp holds one reading of a coarse thermometer, up to :data:`MIN_SEGMENT_S`.

    A thermometer read to 1 degC on a 1.1 degC/min ramp holds each reading for about a minute: over
    60 s the slope reads 0 as often as the ramp, the samples alternate between a ramp and a dwell,
    and the short runs merged into one segment a whole cycle (cooling, heating, cooling), so that
    ``auto`` judged it a run that does not reverse. The hold is the 75th percentile of the readings'
    durations, dwells (one reading for longer than a segment) left out; a thermometer that changes
    at nearly every sample keeps :data:`RATE_WINDOW_S`.
    """
    changes = np.flatnonzero(np.diff(temp_c) != 0) + 1
    held_s = np.diff(np.r_[0, changes, len(temp_c)]) / rate_hz
    ramps = held_s[held_s < MIN_SEGMENT_S]
    if ramps.size == 0:
        return RATE_WINDOW_S
    return float(np.clip(2.0 * np.percentile(ramps, 75), RATE_WINDOW_S, MIN_SEGMENT_S))


def thermal_segments(rec: Recording) -> list[Segment]:
    """The recording's heating, cooling and dwell segments, short runs joined to their neighbour.

    The branch of every sample comes from :func:`trainer.scoring.static.thermal_branch`; a run
    shorter than :data:`MIN_SEGMENT_FRACTION` of the recording or :data:`MIN_SEGMENT_S` (a turning
    point, a brief overshoot) is joined to the segment before it (the first one to the next).
    """
    temp = np.asarray(rec.temp_c, dtype=np.float64)
    branch = thermal_branch(temp, rec.sample_rate_hz, window_s=rate_window_s(temp, rec.sample_rate_hz))
    edges = np.flatnonzero(np.diff(branch)) + 1
    starts, stops = np.r_[0, edges], np.r_[edges, len(branch)]
    t = np.asarray(rec.time_s, dtype=np.float64) - rec.time_origin_s  # a --holdout part: the run's clock
    shortest = max(MIN_SEGMENT_FRACTION * len(branch), MIN_SEGMENT_S * rec.sample_rate_hz)
    runs: list[list[int]] = []  # [start, stop, branch]
    for start, stop in zip(starts.tolist(), stops.tolist(), strict=True):
        if runs and (stop - start < shortest or runs[-1][1] - runs[-1][0] < shortest):
            longer = runs[-1][1] - runs[-1][0] >= stop - start
            runs[-1] = [runs[-1][0], stop, runs[-1][2] if longer else int(branch[start])]
        else:
            runs.append([start, stop, int(branch[start])])
    merged: list[list[int]] = []
    for run in runs:  # neighbours that ended up with the same label are one segment
        if merged and merged[-1][2] == run[2]:
            merged[-1][1] = run[1]
        else:
            merged.append(run)
    return [
        Segment(a, b, LABELS[k], float(t[a]), float(t[b - 1]), float(temp[a]), float(temp[b - 1]))
        for a, b, k in merged
    ]


@dataclass(frozen=True)
class FoldScore:
    """One method on one held-out segment: drift left RMS (channel unit), warm and cold."""

    warm_rms: float
    cold_rms: float
    warm_in_range_rms: float  # NaN: no held-out sample inside the training range
    cold_in_range_rms: float
    in_range_fraction: float


def pooled_rms(values: Sequence[float], weights: Sequence[float]) -> float:
    """RMS pooled over folds: each fold's RMS weighted by its number of samples (folds without a
    sample or without a figure are left out; NaN when none is left)."""
    v, w = np.asarray(values, dtype=np.float64), np.asarray(weights, dtype=np.float64)
    keep = np.isfinite(v) & (w > 0)
    if not np.any(keep):
        return math.nan
    return float(np.sqrt(np.sum(w[keep] * np.square(v[keep])) / np.sum(w[keep])))


@dataclass
class MethodCV:
    """Every fold of one method (in segment order) and the pooled cross-validated figures."""

    name: str
    folds: list[FoldScore]
    natural_cold: list[bool]
    sizes: list[int]
    fit_seconds: float = 0.0

    def natural(self) -> list[float]:
        """Each fold's figure at its natural start (cold for a segment that starts the run)."""
        return [
            f.cold_rms if cold else f.warm_rms for f, cold in zip(self.folds, self.natural_cold, strict=True)
        ]

    @property
    def cv_rms(self) -> float:
        """The cross-validated drift left: RMS pooled over every held-out sample at its natural start."""
        return pooled_rms(self.natural(), self.sizes)

    @property
    def cv_in_range_rms(self) -> float:
        """The pooled figure over the held-out samples inside the training range (natural start): where
        a fold lies outside it every model holds its edge value, so that part scores the clamp, not the
        model's shape. The whole pooled figure when no fold has a sample inside."""
        values = [
            f.cold_in_range_rms if cold else f.warm_in_range_rms
            for f, cold in zip(self.folds, self.natural_cold, strict=True)
        ]
        inside = [size * f.in_range_fraction for size, f in zip(self.sizes, self.folds, strict=True)]
        pooled = pooled_rms(values, inside)
        return pooled if math.isfinite(pooled) else self.cv_rms

    def stat(self, what: str, how: Callable[[np.ndarray], float]) -> float:
        values = np.array([getattr(f, what) for f in self.folds], dtype=np.float64)
        values = values[np.isfinite(values)]
        return float(how(values)) if values.size else math.nan


@dataclass
class CrossValidation:
    """Blocked cross-validation of one channel: segments, one :class:`MethodCV` per method."""

    source: str
    unit: str
    segments: list[Segment]
    results: dict[str, MethodCV]  # uncompensated first
    skipped: dict[str, str] = field(default_factory=dict)  # method -> why it was not cross-validated

    def to_dict(self, timings: bool = True) -> dict[str, Any]:
        """Plain values (the saved table and, without ``timings``, the checkpoint's selection record:
        a model file, and the sha256 its export carries, must not depend on how long a fit took)."""
        return {
            "source": self.source,
            "unit": self.unit,
            "segments": [vars(s) for s in self.segments],
            "methods": {
                name: {
                    "cv_rms": r.cv_rms,
                    **({"fit_seconds": r.fit_seconds} if timings else {}),
                    "natural_cold": r.natural_cold,
                    "folds": [vars(f) for f in r.folds],
                }
                for name, r in self.results.items()
            },
            "skipped": dict(self.skipped),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> CrossValidation:
        """The inverse of :meth:`to_dict` (a checkpoint's selection record)."""
        segments = [Segment(**s) for s in data["segments"]]
        sizes = [s.stop - s.start for s in segments]
        results = {
            name: MethodCV(
                name,
                [FoldScore(**f) for f in r["folds"]],
                list(r["natural_cold"]),
                sizes,
                r.get("fit_seconds", math.nan),  # a checkpoint keeps no timing: unknown
            )
            for name, r in data["methods"].items()
        }
        return cls(str(data["source"]), str(data["unit"]), segments, results, dict(data.get("skipped", {})))


def cross_validatable(method: str) -> bool:
    """Methods that can be trained on a run with a hole (not the recursive ones)."""
    return registry.get(method).family != registry.RECURSIVE


def folds_of(rec: Recording) -> list[Segment]:
    """The segments to hold out: the thermal segments of a run that reverses (heats and cools);
    else (one ramp, a fridge-to-room warm-up whose slow end is a dwell, a dwell alone)
    :data:`RAMP_PARTS` parts, each held out in turn: the first and last then extrapolate in
    temperature, the middle ones interpolate. A ramp's parts cover equal spans of temperature (on
    an exponential warm-up, equal times would leave the middle part a degree or two); a dwell's
    are equal in time. A one-line error when that leaves too few rows.

    Held out whole, the two segments of a warm-up each lie outside the other's range, where every
    model holds its edge value: the cubic left exactly what no compensation leaves, and ``auto``
    shipped nothing on a PX4-style calibration run."""
    segments = thermal_segments(rec)
    labels = {s.label for s in segments}
    if len(segments) >= MIN_SEGMENTS and {LABELS[HEATING], LABELS[COOLING]} <= labels:
        return segments
    n = len(rec)
    if n < RAMP_PARTS * MIN_ROWS:
        raise UserError(
            f"{rec.source}: cross-validation needs a run that heats and cools, or "
            f"{RAMP_PARTS * MIN_ROWS} rows to cut one into {RAMP_PARTS} parts; this run has {n} rows; score it "
            "on another recording (VALID) or give --holdout"
        )
    temp = np.asarray(rec.temp_c, dtype=np.float64)
    t = np.asarray(rec.time_s, dtype=np.float64) - rec.time_origin_s  # a --holdout part: the run's clock
    ramps = [s.label for s in segments if s.label != LABELS[NEITHER]]
    label = ramps[0] if ramps else LABELS[NEITHER]
    edges = _temperature_parts(temp, rising=label == LABELS[HEATING]) if ramps else None
    if edges is None:
        edges = [round(k * n / RAMP_PARTS) for k in range(RAMP_PARTS + 1)]
    return [
        Segment(
            a,
            b,
            f"{label} {k + 1}/{RAMP_PARTS}",
            float(t[a]),
            float(t[b - 1]),
            float(temp[a]),
            float(temp[b - 1]),
        )
        for k, (a, b) in enumerate(itertools.pairwise(edges))
    ]


def _temperature_parts(temp: np.ndarray, *, rising: bool) -> list[int] | None:
    """Row edges of :data:`RAMP_PARTS` parts of a run that only heats (or only cools) covering equal
    spans of its temperature (of the running maximum, or minimum: the thermometer's noise does not
    move an edge back); None when a part would hold fewer than ``MIN_ROWS`` rows."""
    envelope = np.maximum.accumulate(temp) if rising else -np.minimum.accumulate(temp)
    levels = envelope[0] + (envelope[-1] - envelope[0]) * np.arange(1, RAMP_PARTS) / RAMP_PARTS
    edges = [0, *np.searchsorted(envelope, levels, side="left").tolist(), temp.size]
    return edges if all(b - a >= MIN_ROWS for a, b in itertools.pairwise(edges)) else None


def training_rows(n: int, segment: Segment) -> np.ndarray:
    mask = np.ones(n, dtype=bool)
    mask[segment.start : segment.stop] = False
    return mask


def impute_held_out(rec: Recording, train: np.ndarray) -> Recording:
    """``rec`` with the held-out output replaced by the cubic fitted on the training rows alone."""
    from trainer.baselines.poly3 import CubicPolynomial

    cubic = CubicPolynomial().fit(rows(rec, train))
    filled = np.where(train, rec.accel_mg, cubic.predict_drift(rec))
    held = (~train).astype(np.float64)
    return Recording({**rec.columns, "accel_mg": filled, HELD_OUT_COLUMN: held}, dict(rec.meta), rec.source)


def rows(rec: Recording, mask: np.ndarray) -> Recording:
    """The rows of ``rec`` where ``mask`` holds (their times keep their values)."""
    return Recording({k: v[mask] for k, v in rec.columns.items()}, dict(rec.meta), rec.source)


def _score(
    output_warm: np.ndarray,
    output_cold: np.ndarray,
    temp: np.ndarray,
    branch: np.ndarray,
    temp_range: tuple[float, float],
) -> FoldScore:
    inside = (temp >= temp_range[0]) & (temp <= temp_range[1])

    def rms(x: np.ndarray, where: np.ndarray | None = None) -> float:
        if where is not None:
            if not np.any(where):
                return math.nan
            x, b = x[where], branch[where]
        else:
            b = branch
        return static_drift_left(x, b).rms_mg

    return FoldScore(
        rms(output_warm),
        rms(output_cold),
        rms(output_warm, inside),
        rms(output_cold, inside),
        float(np.mean(inside)),
    )


@dataclass(frozen=True)
class FoldTask:
    """One fit of a cross-validation: ``method`` trained without ``segment`` and scored on it."""

    method: str
    fit: Callable[[Recording], object]
    stateful: bool  # trained on the imputed whole run (impute_held_out), not on the training rows
    segment: Segment
    index: int  # the segment's number in the run (from 0)


def _smoothed(x: np.ndarray, rate_hz: float, smoothing_s: float) -> np.ndarray:
    """The output as the score reads it (the validation smoothing)."""
    from trainer.scoring.evaluate import smooth_for_scoring

    return np.asarray(smooth_for_scoring(np.asarray(x, dtype=np.float64), rate_hz, smoothing_s))


def run_fold(task: FoldTask, rec: Recording, smoothing_s: float) -> tuple[FoldScore, float]:
    """Fit ``task`` and score its held-out segment warm and cold; also the fit's seconds."""
    rate = rec.sample_rate_hz

    def smooth(x: np.ndarray) -> np.ndarray:
        return _smoothed(x, rate, smoothing_s)

    s = task.segment
    temp = np.asarray(rec.temp_c, dtype=np.float64)
    mask = training_rows(len(rec), s)
    train = impute_held_out(rec, mask) if task.stateful else rows(rec, mask)
    start = time.perf_counter()
    model = task.fit(train)
    seconds = time.perf_counter() - start
    predict = model.predict_drift  # type: ignore[attr-defined]
    warm = smooth(rec.accel_mg - predict(rec))[s.start : s.stop]
    part = rec.slice(s.start, s.stop)
    cold = smooth(part.accel_mg - predict(part))
    lo, hi = float(np.min(temp[mask])), float(np.max(temp[mask]))
    branch = thermal_branch(temp, rate)[s.start : s.stop]
    return _score(warm, cold, temp[s.start : s.stop], branch, (lo, hi)), seconds


def own_run_figures(
    rec: Recording, drift: np.ndarray, segments: Sequence[Segment], smoothing_s: float
) -> list[tuple[str, float]]:
    """Where a model fitted on the whole of ``rec`` (its estimate ``drift`` over the run, from
    power-on) is scored on its own run, and its drift left there: each segment as a fold's natural
    start is (about the segment's constant), then the whole run and its heating and cooling rows
    about the run's one constant (what ``trainer evaluate`` and the sign-off print). The check that
    the model shipped is not worse on its own run than what cross-validation judged: a segment about
    its own constant cannot see a level the model moves between segments (the bundled run's gyro z,
    a branch offset fitted against an uncompensated step at the cold reversal: 0.23 deg/s between
    its segments' means, 0.03 without compensation)."""
    out = _smoothed(np.asarray(rec.accel_mg, dtype=np.float64) - drift, rec.sample_rate_hz, smoothing_s)
    branch = thermal_branch(np.asarray(rec.temp_c, dtype=np.float64), rec.sample_rate_hz)
    figures = [
        (s.name, static_drift_left(out[s.start : s.stop], branch[s.start : s.stop]).rms_mg) for s in segments
    ]
    whole = static_drift_left(out, branch)
    return [
        *figures,
        ("whole run, about its one constant", whole.rms_mg),
        ("heating rows, about the run's one constant", whole.heating_rms_mg),
        ("cooling rows, about the run's one constant", whole.cooling_rms_mg),
    ]


def cross_validate(
    rec: Recording,
    fitters: dict[str, Callable[[Recording], object]],
    *,
    stateful: set[str],
    smoothing_s: float,
    unit: str = "mg",
    log: Callable[[str], None] | None = None,
    fold_segments: Sequence[Segment] | None = None,
    tasks: TaskMap | None = None,
) -> CrossValidation:
    """Hold out every thermal segment of ``rec`` in turn; ``fitters[name](train_rec)`` returns a fitted
    compensator (anything with ``predict_drift``). ``stateful`` names the methods trained on the
    imputed whole run (:func:`impute_held_out`) instead of on the training rows alone. ``fold_segments``
    replaces :func:`folds_of` (a bench comparing fold schemes). ``tasks`` runs the fits on its
    workers when one of them is stateful (the physics fits: seconds to minutes each); quick fits
    alone stay in this process. Every fit runs on one thread wherever it runs: the figures do not
    depend on the workers."""

    rec = rec.without_truth()
    segments = list(fold_segments) if fold_segments is not None else folds_of(rec)
    rate = rec.sample_rate_hz
    temp = np.asarray(rec.temp_c, dtype=np.float64)
    branch = thermal_branch(temp, rate)
    natural_cold = [s.start == 0 for s in segments]
    sizes = [s.stop - s.start for s in segments]
    results: dict[str, MethodCV] = {}

    raw_folds = []
    for s in segments:
        raw = _smoothed(rec.accel_mg[s.start : s.stop], rate, smoothing_s)
        mask = training_rows(len(rec), s)
        lo, hi = float(np.min(temp[mask])), float(np.max(temp[mask]))
        raw_folds.append(_score(raw, raw, temp[s.start : s.stop], branch[s.start : s.stop], (lo, hi)))
    results[UNCOMPENSATED] = MethodCV(UNCOMPENSATED, raw_folds, natural_cold, sizes)
    fold_tasks = [
        FoldTask(name, fit, name in stateful, s, index)
        for name, fit in fitters.items()
        for index, s in enumerate(segments)
    ]
    runner = tasks if tasks is not None else TaskMap()
    began = time.perf_counter()

    def done(count: int, task: FoldTask, result: tuple[FoldScore, float]) -> None:
        if log is not None:
            log(
                f"cross-validation: {task.method}, segment {task.index + 1}/{len(segments)} held out: "
                f"{task.segment.name} (fit {count} of {len(fold_tasks)} done in {result[1]:.1f} s, "
                f"{time.perf_counter() - began:.0f} s so far)"
            )

    quick = not any(t.stateful for t in fold_tasks)
    if log is not None and runner.parallel and not quick and len(fold_tasks) > 1:
        log(f"{len(fold_tasks)} fits of the cross-validation on {runner.width} worker processes (--jobs)")
    scored = runner.map(
        run_fold, fold_tasks, shared={"rec": rec, "smoothing_s": smoothing_s}, here=quick, done=done
    )
    for name in fitters:
        mine = [result for task, result in zip(fold_tasks, scored, strict=True) if task.method == name]
        seconds = sum(result[1] for result in mine)
        results[name] = MethodCV(
            name, [result[0] for result in mine], natural_cold, sizes, seconds / len(segments)
        )
    return CrossValidation(rec.source, unit, segments, results)


def table_lines(cv: CrossValidation, chosen: str | None = None) -> list[str]:
    """The cross-validation as a Markdown table: per method the pooled figure, median and worst
    held-out drift left (natural start), warm and cold, whole segment and inside the training range."""
    unit = cv.unit
    lines = [
        f"| method | CV drift left ({unit}) | median / worst, natural start | warm median / worst | "
        f"cold median / worst | in range, warm median / worst | per segment (natural) |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, r in cv.results.items():
        natural = np.array(r.natural())
        mark = f"**{name}** (chosen)" if name == chosen else name
        lines.append(
            f"| {mark} | {r.cv_rms:.4g} | {np.median(natural):.4g} / {np.max(natural):.4g} | "
            f"{r.stat('warm_rms', np.median):.4g} / {r.stat('warm_rms', np.max):.4g} | "
            f"{r.stat('cold_rms', np.median):.4g} / {r.stat('cold_rms', np.max):.4g} | "
            f"{r.stat('warm_in_range_rms', np.median):.4g} / {r.stat('warm_in_range_rms', np.max):.4g} | "
            + " / ".join(f"{v:.4g}" for v in natural)
            + " |"
        )
    return lines


def segment_lines(segments: Sequence[Segment]) -> list[str]:
    return [
        f"- segment {i + 1}: {s.name}, {s.stop - s.start} samples, scored "
        + (
            "cold (it starts the recording: held out, the model starts on it from power-on)"
            if s.start == 0
            else "warm (the model runs from the start of the recording, through the segments before it)"
        )
        for i, s in enumerate(segments)
    ]
