"""The bundled real run's thermal loops: heating minus each cooling at one temperature (issue 20).

What a cubic in temperature cannot hold, and what the catalogue's one branch offset (one amplitude,
one width) can: for every channel, the output's mean over the samples of each thermal segment within
``+-BIN_C`` of a grid temperature, and the heating segment's mean minus each cooling segment's, where
both segments pass that temperature. A branch offset gives one sign at both reversals (the heating
branch above the cooling one, or below) and a gap that opens over its width after each reversal; a
gap at the hot reversal that is missing at the cold one, or a first cooling unlike the last, is
physics the catalogue's symmetric loop does not describe (docs/real-data.md, gyro z).

    python bench/bench_real_loops.py [--channels gyro0_z,accel0_z]
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np
from bundled_run import REAL, bundled_run

from trainer.data.channels import channel_unit, channel_view, select_channels
from trainer.data.recording import Recording
from trainer.scoring.crossval import Segment, folds_of

GRID_C = np.arange(-10.0, 71.0, 10.0)  # the temperatures the loops are read at
BIN_C = 1.0  # samples within this of a grid temperature make its mean
MIN_SAMPLES = 20  # fewer samples in a bin: that segment does not pass the temperature


def segment_mean_at(rec: Recording, segment: Segment, temp_c: float) -> float:
    """The output's mean over ``segment``'s samples within ``BIN_C`` of ``temp_c`` (NaN: too few)."""
    temp = np.asarray(rec.temp_c, dtype=np.float64)[segment.start : segment.stop]
    out = np.asarray(rec.accel_mg, dtype=np.float64)[segment.start : segment.stop]
    near = np.abs(temp - temp_c) <= BIN_C
    return float(np.mean(out[near])) if np.count_nonzero(near) >= MIN_SAMPLES else float("nan")


def _span(segment: Segment) -> str:
    return f"{segment.label} {segment.t0_s:.0f}-{segment.t1_s:.0f} s"


def loop_rows(rec: Recording) -> list[tuple[str, list[float]]]:
    """(``heating minus <cooling segment>``, the gap at each grid temperature) for every heating
    segment and every cooling segment of ``rec``."""
    segments = folds_of(rec)
    heating = [s for s in segments if s.label.startswith("heating")]
    cooling = [s for s in segments if s.label.startswith("cooling")]
    rows = []
    for h in heating:
        for c in cooling:
            gaps = [segment_mean_at(rec, h, t) - segment_mean_at(rec, c, t) for t in GRID_C]
            rows.append((f"{_span(h)} minus {_span(c)}", gaps))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--channels", default="all")
    args = parser.parse_args()
    started = time.perf_counter()
    full = bundled_run()
    print(f"# {REAL.name}; {platform.processor() or platform.machine()}")
    print(f"heating minus cooling at one temperature (mean within +-{BIN_C:g} degC; '-': not passed)")
    for channel in select_channels(full, tuple(args.channels.split(","))):
        rec = channel_view(full, channel)
        unit = channel_unit(rec)
        print(f"\n## {channel.name} ({unit})\n")
        print("| segments | " + " | ".join(f"{t:g} degC" for t in GRID_C) + " |")
        print("|---|" + "---|" * len(GRID_C))
        for label, gaps in loop_rows(rec):
            cells = ["-" if np.isnan(g) else f"{g:+.3g}" for g in gaps]
            print(f"| {label} | " + " | ".join(cells) + " |")
    print(f"\n({time.perf_counter() - started:.1f} s)")


if __name__ == "__main__":
    main()
