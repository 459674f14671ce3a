"""What the recording's own temperature profile lets the finder identify, and where things are.

Before searching for a missing effect the finder works out from the temperature alone which
effects the test could reveal: hysteresis needs a reversal of temperature over a common range,
a thermal lag and a dT/dt term need ramp corners or a second ramp rate (on one constant-rate
ramp both are a constant offset the polynomial absorbs), stress relaxation needs a long hold,
``scale_factor_tc`` needs a second orientation. Effects that cannot show are reported as not
identifiable, with the test that would make them identifiable.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from trainer.data.channels import relabel_units
from trainer.diagnose.blocks import BlockData
from trainer.diagnose.branches import classify_branches, runs_of
from trainer.physics.catalogue import CANDIDATE_ORDER, DEFINITIONS
from trainer.physics.catalogue.base import Identifiability, Region
from trainer.physics.profiles import parse_segments

BRANCH_NAMES = {1: "heating", -1: "cooling", 0: "hold"}


@dataclass(frozen=True)
class Segment:
    label: str
    start_s: float
    end_s: float


@dataclass
class Profile:
    """Branch per block, segments, and the features that decide identifiability."""

    branch: np.ndarray  # +1 heating, -1 cooling, 0 hold, per block
    rate: np.ndarray  # degC/min per block
    segments: list[Segment]
    segments_from: str  # "metadata" or "temperature"
    reversals: int
    overlap_c: tuple[float, float] | None  # temperature range seen both heating and cooling
    hold_s: float  # longest hold (s)
    holds_after_ramp_s: float  # longest hold that follows a ramp
    corners: int
    ramp_rates: list[float]
    starts_from_rest: bool
    temp_min_c: float
    temp_max_c: float
    duration_s: float
    lattice_lsb_c: float | None
    known_input_varies: bool
    identifiability: dict[str, Identifiability] = field(default_factory=dict)
    # block centres and (de-quantised) temperatures: what an effect's signature is tested against
    block_t_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    block_temp_c: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def to_dict(self) -> dict[str, object]:
        return {
            "segments": [{"label": s.label, "start_s": s.start_s, "end_s": s.end_s} for s in self.segments],
            "segments_from": self.segments_from,
            "temp_range_c": [self.temp_min_c, self.temp_max_c],
            "reversals": self.reversals,
            "heating_cooling_overlap_c": None if self.overlap_c is None else list(self.overlap_c),
            "longest_hold_s": self.hold_s,
            "longest_hold_after_ramp_s": self.holds_after_ramp_s,
            "ramp_corners": self.corners,
            "ramp_rates_c_per_min": self.ramp_rates,
            "starts_from_rest": self.starts_from_rest,
            "thermometer_lsb_c": self.lattice_lsb_c,
        }


def _segments(data: BlockData, meta: dict[str, str], codes: np.ndarray) -> tuple[list[Segment], str]:
    text = meta.get("segments")
    if text:
        try:
            return [Segment(*item) for item in parse_segments(text)], "metadata"
        except ValueError:
            pass
    segments = []
    starts = data.starts
    end = data.t[-1] + 0.5 * data.block_s
    for index, (code, a, b) in enumerate(runs_of(codes)):
        label = {1: "ramp_up", -1: "ramp_down"}.get(code, "soak" if index == 0 else "hold")
        stop = starts[b] if b < codes.size else end
        segments.append(Segment(label, float(starts[a]), float(stop)))
    return segments, "temperature"


def analyse_profile(
    data: BlockData, meta: dict[str, str], known_input_varies: bool = False, *, seen_only: bool = False
) -> Profile:
    """Branches, segments and identifiability from the block temperatures.

    ``seen_only``: reversals and the range seen both heating and cooling count only the blocks an
    outer cross-validation does not hold out (``data.held_out``: their output is imputed), so that
    a fold holding out the only heating run identifies no branch term from what its coolings show.
    """
    temp = data.temperature(True)
    rate = data.rate(True)
    codes = classify_branches(rate, data.block_s)
    segments, source = _segments(data, meta, codes)
    runs = runs_of(codes)
    moving = [(code, a, b) for code, a, b in runs if code != 0]
    seen = np.ones(codes.size, dtype=bool)
    if seen_only and data.held_out is not None:
        seen = ~data.held_out
    shown = [(code, a, b) for code, a, b in moving if np.mean(seen[a:b]) > 0.5]
    reversals = sum(1 for r0, r1 in itertools.pairwise(shown) if r0[0] != r1[0])
    heat = temp[(codes == 1) & seen]
    cool = temp[(codes == -1) & seen]
    overlap = None
    if heat.size and cool.size:
        lo = max(float(heat.min()), float(cool.min()))
        hi = min(float(heat.max()), float(cool.max()))
        if hi > lo:
            overlap = (lo, hi)
    hold_lengths = [(b - a) * data.block_s for code, a, b in runs if code == 0]
    ramp_rates: list[float] = []
    for _, a, b in moving:
        core = np.abs(rate[a:b])
        value = float(np.median(core))
        if not any(abs(value / r - 1.0) < 0.25 for r in ramp_rates):
            ramp_rates.append(value)
    first_ramp = moving[0] if moving else None
    starts_from_rest = bool(
        first_ramp is not None
        and first_ramp[1] == 0
        and abs(rate[0]) < 0.5 * float(np.median(np.abs(rate[first_ramp[1] : first_ramp[2]])))
    )
    corners = max(0, len(runs) - 1) + int(starts_from_rest)
    profile = Profile(
        branch=codes,
        rate=rate,
        segments=segments,
        segments_from=source,
        reversals=reversals,
        overlap_c=overlap,
        hold_s=max(hold_lengths, default=0.0),
        holds_after_ramp_s=data.hold_after_ramp_s,
        corners=corners,
        ramp_rates=sorted(ramp_rates),
        starts_from_rest=starts_from_rest,
        temp_min_c=float(temp.min()),
        temp_max_c=float(temp.max()),
        duration_s=data.duration_s,
        lattice_lsb_c=data.lattice_lsb_c,
        known_input_varies=known_input_varies,
        block_t_s=data.t,
        block_temp_c=temp,
    )
    profile.identifiability = identifiability(profile)
    return profile


def identifiability(p: Profile) -> dict[str, Identifiability]:
    """Which catalogue effects this temperature profile can reveal, and what test would help.

    Each definition carries its own rule (``finder.identifiability``); the finder's candidates
    are those with a rule.
    """
    return {k: rule(p) for k in CANDIDATE_ORDER if (rule := DEFINITIONS[k].finder.identifiability)}


def in_unit(ident: dict[str, Identifiability], unit: str) -> dict[str, Identifiability]:
    """The rules' texts, written for milli-g, in the channel's unit and sensor (a gyroscope's
    scale-factor test is a rate table, not a flip to -1 g)."""
    return {
        k: replace(info, reason=relabel_units(info.reason, unit), test=relabel_units(info.test, unit))
        for k, info in ident.items()
    }


def region(
    data: BlockData,
    profile: Profile,
    a: int,
    b: int,
    significance: Mapping[str, float | str],
    kind: str,
    note: str = "",
) -> Region:
    """A :class:`Region` covering blocks ``a:b``."""
    a = max(0, min(a, data.n - 1))
    b = max(a + 1, min(b, data.n))
    t0 = float(data.starts[a])
    t1 = float(data.starts[b - 1] + data.block_s)
    temp = data.temperature(True)[a:b]
    labels = []
    for seg in profile.segments:
        if seg.end_s > t0 and seg.start_s < t1 and seg.label not in labels:
            labels.append(seg.label)
    codes = profile.branch[a:b]
    counts = {c: int(np.sum(codes == c)) for c in (1, -1, 0)}
    top = max(counts, key=lambda c: counts[c])
    branch = BRANCH_NAMES[top] if counts[top] >= 0.8 * codes.size else "mixed"
    return Region(
        t0,
        t1,
        "+".join(labels) or "?",
        float(temp.min()),
        float(temp.max()),
        branch,
        significance,
        kind,
        note,
    )
