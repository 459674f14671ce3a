"""Temperature set-point protocols (labelled piecewise-linear segments).

The ``segments`` metadata written into every simulated recording is produced and parsed here, so
that later tools (fitting, the mismatch finder) can name where in a recording something shows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SEGMENT_LABELS: tuple[str, ...] = ("soak", "ramp_up", "hold", "ramp_down")
PROTOCOL_NAMES: tuple[str, ...] = ("paper-oven", "extended", "realistic-train", "realistic-valid", "custom")


@dataclass(frozen=True)
class SegmentSpec:
    """A protocol step: ``label``, how long, and the set-point at its end.

    For ``soak``/``hold`` the set-point is ``end_c`` throughout (a different value from the
    previous end is a set-point step at the segment start); ramps go linearly to ``end_c``.
    """

    label: str
    duration_s: float
    end_c: float


# Seed paper section 2.2: soak -40 degC 1 h (not recorded: the die starts in equilibrium), then
# the recorded ramp at 1 degC/min to 80 degC, 2 h.
PAPER_OVEN: tuple[float, tuple[SegmentSpec, ...]] = (-40.0, (SegmentSpec("ramp_up", 7200.0, 80.0),))

# Both branches over 25..80 degC and two dwells: shows hysteresis (branch offset that persists
# in the holds), lag (rate-dependent offset that reverses sign) and relaxation (decay in holds).
EXTENDED: tuple[float, tuple[SegmentSpec, ...]] = (
    -40.0,
    (
        SegmentSpec("soak", 1800.0, -40.0),
        SegmentSpec("ramp_up", 7200.0, 80.0),
        SegmentSpec("hold", 3600.0, 80.0),
        SegmentSpec("ramp_down", 3300.0, 25.0),
        SegmentSpec("hold", 1800.0, 25.0),
    ),
)

# The realistic experiment (trainer/physics/realistic.toml, docs/simulator.md): two chamber cycles
# that differ in ramp rates and in the order of the range, so that a compensator trained on one
# is validated on temperature histories it has not seen. Training: up at 1.0, down at 1.5, up
# at 0.5 degC/min, starting cold; validation: starting hot, down at 2.0, up at 0.7, down at 1.0.
REALISTIC_TRAIN: tuple[float, tuple[SegmentSpec, ...]] = (
    -20.0,
    (
        SegmentSpec("soak", 1200.0, -20.0),
        SegmentSpec("ramp_up", 5400.0, 70.0),
        SegmentSpec("hold", 1800.0, 70.0),
        SegmentSpec("ramp_down", 2800.0, 0.0),
        SegmentSpec("hold", 1200.0, 0.0),
        SegmentSpec("ramp_up", 4800.0, 40.0),
        SegmentSpec("hold", 1200.0, 40.0),
    ),
)
REALISTIC_VALID: tuple[float, tuple[SegmentSpec, ...]] = (
    60.0,
    (
        SegmentSpec("soak", 1200.0, 60.0),
        SegmentSpec("ramp_down", 2400.0, -20.0),
        SegmentSpec("hold", 1800.0, -20.0),
        SegmentSpec("ramp_up", 7700.0, 70.0),
        SegmentSpec("hold", 1200.0, 70.0),
        SegmentSpec("ramp_down", 3000.0, 20.0),
        SegmentSpec("hold", 1200.0, 20.0),
    ),
)

BUILTIN_PROTOCOLS: dict[str, tuple[float, tuple[SegmentSpec, ...]]] = {
    "paper-oven": PAPER_OVEN,
    "extended": EXTENDED,
    "realistic-train": REALISTIC_TRAIN,
    "realistic-valid": REALISTIC_VALID,
}


@dataclass(frozen=True)
class Segment:
    """A segment placed on the recording's time axis (seconds from the first sample)."""

    label: str
    start_s: float
    end_s: float
    start_c: float
    end_c: float


@dataclass(frozen=True)
class Profile:
    """The chamber set-point ``S(t)`` of one protocol."""

    name: str
    segments: tuple[Segment, ...]

    @property
    def duration_s(self) -> float:
        return self.segments[-1].end_s

    def setpoint(self, t: np.ndarray) -> np.ndarray:
        """``S(t)``: linear inside each segment, right-continuous at set-point steps."""
        t = np.asarray(t, dtype=np.float64)
        starts = np.array([s.start_s for s in self.segments])
        idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(self.segments) - 1)
        s0 = np.array([s.start_s for s in self.segments])[idx]
        s1 = np.array([s.end_s for s in self.segments])[idx]
        c0 = np.array([s.start_c for s in self.segments])[idx]
        c1 = np.array([s.end_c for s in self.segments])[idx]
        frac = np.clip((t - s0) / (s1 - s0), 0.0, 1.0)
        return c0 + (c1 - c0) * frac


def build_profile(
    name: str, start_c: float, specs: tuple[SegmentSpec, ...], duration_s: float | None = None
) -> Profile:
    """Place ``specs`` on the time axis; ``duration_s`` time-compresses the whole protocol to it.

    Compression scales every segment's duration by the same factor and keeps the temperatures,
    so ramps get steeper: it is meant for short test recordings, not for physics.
    """
    total = sum(spec.duration_s for spec in specs)
    scale = 1.0 if duration_s is None else duration_s / total
    segments: list[Segment] = []
    clock = 0.0
    temp = start_c
    for spec in specs:
        end = clock + spec.duration_s * scale
        begin_c = spec.end_c if spec.label in ("soak", "hold") else temp
        segments.append(Segment(spec.label, clock, end, begin_c, spec.end_c))
        clock, temp = end, spec.end_c
    return Profile(name, tuple(segments))


def _fmt(value: float) -> str:
    return f"{value:.12g}"


def format_segments(segments: tuple[Segment, ...]) -> str:
    """Metadata value ``label:start_s:end_s;...`` (seconds on the recording's ``time_s`` axis)."""
    return ";".join(f"{s.label}:{_fmt(s.start_s)}:{_fmt(s.end_s)}" for s in segments)


def parse_segments(text: str) -> list[tuple[str, float, float]]:
    """Inverse of :func:`format_segments`; raises ValueError on malformed text."""
    out: list[tuple[str, float, float]] = []
    for item in text.strip().split(";"):
        parts = item.split(":")
        if len(parts) != 3 or parts[0] not in SEGMENT_LABELS:
            raise ValueError(f"malformed segment {item!r} (expected label:start_s:end_s)")
        start, end = float(parts[1]), float(parts[2])
        if not (math.isfinite(start) and math.isfinite(end) and end > start):
            raise ValueError(f"malformed segment {item!r} (need finite start_s < end_s)")
        out.append((parts[0], start, end))
    return out
