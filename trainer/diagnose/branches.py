"""Heating, cooling or hold per block of the finder, from the block temperature rate.

One classification for the profile's identifiability (:mod:`.profile`) and for what the block
data itself tells a search (the longest hold after a ramp, :attr:`.blocks.BlockData.hold_after_ramp_s`).
"""

from __future__ import annotations

import numpy as np


def runs_of(codes: np.ndarray) -> list[tuple[int, int, int]]:
    """(code, start, stop) of runs of equal values."""
    if codes.size == 0:
        return []
    edges = np.flatnonzero(np.diff(codes)) + 1
    starts = np.concatenate(([0], edges))
    stops = np.concatenate((edges, [codes.size]))
    return [(int(codes[a]), int(a), int(b)) for a, b in zip(starts, stops, strict=True)]


def classify_branches(rate: np.ndarray, block_s: float) -> np.ndarray:
    """+1/-1/0 per block; runs shorter than ~2 min (or 2 % of the run) merge into a neighbour."""
    scale = float(np.percentile(np.abs(rate), 95)) if rate.size else 0.0
    threshold = max(0.05, 0.1 * scale)
    codes = np.where(rate > threshold, 1, np.where(rate < -threshold, -1, 0)).astype(np.int64)
    min_len = max(2, round(max(120.0, 0.02 * rate.size * block_s) / block_s))
    for _ in range(4):
        runs = runs_of(codes)
        if len(runs) <= 1:
            break
        changed = False
        for index, (_, a, b) in enumerate(runs):
            if b - a >= min_len:
                continue
            neighbours = [runs[k] for k in (index - 1, index + 1) if 0 <= k < len(runs)]
            longest = max(neighbours, key=lambda run: run[2] - run[1])
            codes[a:b] = longest[0]
            changed = True
        if not changed:
            break
    return codes


def longest_hold_after_ramp_s(rate_c_per_min: np.ndarray, block_s: float) -> float:
    """The longest hold after a ramp (s; a hold that starts the run is a soak), 0 when the run
    never stops after a ramp."""
    runs = runs_of(classify_branches(rate_c_per_min, block_s))
    return max(((b - a) * block_s for k, (code, a, b) in enumerate(runs) if code == 0 and k > 0), default=0.0)
