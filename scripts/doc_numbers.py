"""Numbers quoted in README.md and docs/*.md, regenerated from a run of the code as it is.

A quoted number is written between markers, ``<!-- num:KEY -->2.359<!-- /num -->`` or, with its own
format, ``<!-- num:KEY:.3g -->4.52<!-- /num -->``; KEY names a measurement of :data:`REGISTRY`
(declared once below, each with the run that measures it). ``python scripts/doc_numbers.py`` fills
every marker from a fresh measurement; ``--check`` changes nothing and exits 1 listing each marker
whose text differs. Cheap measurements (cubic and PLA fits on the bundled real run, a second) always
run; ``--slow`` adds the physics fits (3 min 12 s of CPU on the 2-core Xeon VM, 2026-12-01). Timings
(keys ending ``seconds``) are written but never checked: they depend on the machine and its load.
The markers cover README.md, docs/channels.md and docs/signoff.md; the other docs' tables are
re-measured by their benches (bench/), by hand, and are not checked here.

    python scripts/doc_numbers.py [--check] [--slow] [FILE.md ...]
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from trainer.data.recording import Recording
    from trainer.scoring.unit_scores import PartScores

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT.parent / "shared" / "data" / "real" / "tofupilot_imu_chamber_cycle.tsv"
DOCS = (ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")))
HOLDOUT = "3131:"  # the split the docs quote: the last cooling held out (`--holdout 3131:`)
MARKER = re.compile(r"<!-- num:(?P<key>[\w.]+)(?::(?P<fmt>[^ ]+))? -->(?P<text>.*?)<!-- /num -->")
TIMING_SUFFIX = "seconds"


@dataclass(frozen=True)
class Measurement:
    """A run that yields several numbers (``{key: value}``) and each key's default format."""

    run: Callable[[], dict[str, float]]
    formats: dict[str, str]
    slow: bool = False


@cache
def _real_channels() -> dict[str, Recording]:
    """The bundled real run, every channel as a one-channel view (``--preset tofupilot --channels all``)."""
    from trainer.data.channels import channel_view, select_channels
    from trainer.data.importer import import_foreign, options_with_preset

    rec = import_foreign(REAL, options_with_preset("tofupilot", channels=("all",)))
    return {c.name: channel_view(rec, c) for c in select_channels(rec, ("all",))}


def _residual(method: str, channel: str) -> tuple[float, float]:
    """In-sample fit residual RMS as ``trainer fit`` prints it, and the fit's CPU time (s: the fits run
    on one BLAS thread, so this is their wall time on an idle core whatever the machine's load)."""
    from trainer.fitting import fit_with_stats

    started = time.process_time()
    _, stats = fit_with_stats(method, _real_channels()[channel])
    assert stats.fit_residual_rms_mg is not None  # fit_with_stats always records it
    return stats.fit_residual_rms_mg, time.process_time() - started


def _held_out(method: str, channel: str) -> tuple[PartScores, PartScores]:
    """Trained before t = 3131 s, scored as ``trainer report --holdout 3131:`` scores it: (whole, held out)."""
    from trainer.data.holdout import parse_holdout, split
    from trainer.dlstm.realtime import PAPER_RUN_SMOOTHING_S
    from trainer.fitting import fit_compensator
    from trainer.scoring.unit_scores import score_unit

    rec = _real_channels()[channel]
    holdout = parse_holdout(HOLDOUT)
    train, _ = split(rec, holdout)
    model = fit_compensator(method, train)
    trained = (float(np.min(train.temp_c)), float(np.max(train.temp_c)))
    scores = score_unit(rec, model.compensate(rec.without_truth()), PAPER_RUN_SMOOTHING_S, trained, holdout)
    assert scores.held_out is not None
    return scores.whole, scores.held_out


def _cubic_residuals() -> dict[str, float]:
    return {f"real.poly3.residual.{name}": _residual("poly3", name)[0] for name in _real_channels()}


def _gyro_z_held_out() -> dict[str, float]:
    out: dict[str, float] = {}
    for method in ("poly3", "pla"):
        _, held = _held_out(method, "gyro0_z")
        out[f"real.holdout.gyro0_z.{method}"] = held.model.rms_mg
        out["real.holdout.gyro0_z.uncompensated"] = held.uncompensated.rms_mg
        out["real.holdout.gyro0_z.noise_floor"] = held.noise_floor_mg
    return out


def _signoff(method: str) -> Callable[[], dict[str, float]]:
    """The accel0_z rows of docs/signoff.md's example (``trainer report ... --holdout 3131:``)."""

    def run() -> dict[str, float]:
        whole, held = _held_out(method, "accel0_z")
        key = f"real.signoff.accel0_z.{method}"
        return {
            f"{key}.holdout_rms": held.model.rms_mg,
            f"{key}.holdout_max": held.model.max_abs_mg,
            f"{key}.residual_max": whole.model.max_abs_mg,
            f"{key}.heating_rms": whole.model.heating_rms_mg,
            f"{key}.cooling_rms": whole.model.cooling_rms_mg,
        }

    return run


def _physics_residuals() -> dict[str, float]:
    out: dict[str, float] = {}
    seconds = []
    for name in ("accel0_z", "gyro0_x"):
        out[f"real.physics.residual.{name}"], elapsed = _residual("physics", name)
        seconds.append(elapsed)
    out[f"real.physics.fit_{TIMING_SUFFIX}"] = float(np.mean(seconds))
    return out


_SIGNOFF_KEYS = ("holdout_rms", "holdout_max", "residual_max", "heating_rms", "cooling_rms")
REGISTRY: tuple[Measurement, ...] = (
    Measurement(
        _cubic_residuals,
        {f"real.poly3.residual.accel0_{a}": ".3f" for a in "xyz"}
        | {f"real.poly3.residual.gyro0_{a}": ".3g" for a in "xyz"},
    ),
    Measurement(
        _gyro_z_held_out,
        {f"real.holdout.gyro0_z.{k}": ".3g" for k in ("uncompensated", "poly3", "pla")}
        | {"real.holdout.gyro0_z.noise_floor": ".2g"},
    ),
    Measurement(_signoff("poly3"), {f"real.signoff.accel0_z.poly3.{k}": ".4g" for k in _SIGNOFF_KEYS}),
    Measurement(
        _signoff("physics"), {f"real.signoff.accel0_z.physics.{k}": ".4g" for k in _SIGNOFF_KEYS}, slow=True
    ),
    Measurement(
        _physics_residuals,
        {"real.physics.residual.accel0_z": ".4g", "real.physics.residual.gyro0_x": ".3g"}
        | {f"real.physics.fit_{TIMING_SUFFIX}": ".0f"},
        slow=True,
    ),
)
FORMATS: dict[str, str] = {k: f for m in REGISTRY for k, f in m.formats.items()}
assert len(FORMATS) == sum(len(m.formats) for m in REGISTRY), "a key is declared twice"


def measure(keys: Iterable[str], *, slow: bool) -> dict[str, float]:
    """Run the measurements that yield ``keys`` (slow ones only when ``slow``)."""
    wanted = set(keys)
    values: dict[str, float] = {}
    for m in REGISTRY:
        if wanted & set(m.formats) and (slow or not m.slow):
            values |= m.run()
    return values


def markers(text: str) -> list[re.Match[str]]:
    return list(MARKER.finditer(text))


def unknown_keys(paths: Iterable[Path]) -> list[str]:
    """``path: KEY`` for every marker naming no measurement."""
    return [f"{p}: {m['key']}" for p in paths for m in markers(p.read_text()) if m["key"] not in FORMATS]


def fill(text: str, values: dict[str, float]) -> tuple[str, list[str]]:
    """``text`` with every measured marker filled, and one line per marker whose text changed."""
    changed: list[str] = []

    def replace(m: re.Match[str]) -> str:
        key = m["key"]
        if key not in values:
            return m.group(0)
        new = format(values[key], m["fmt"] or FORMATS[key])
        if new != m["text"]:
            changed.append(f"{key}: {m['text']} -> {new}")
        fmt = f":{m['fmt']}" if m["fmt"] else ""
        return f"<!-- num:{key}{fmt} -->{new}<!-- /num -->"

    return MARKER.sub(replace, text), changed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="*", type=Path, help="Markdown files (default: README.md, docs/*.md)")
    parser.add_argument("--check", action="store_true", help="change nothing; exit 1 when a number differs")
    parser.add_argument("--slow", action="store_true", help="include the physics fits (a few minutes of CPU)")
    args = parser.parse_args(argv)
    paths = [p.resolve() for p in args.files] or list(DOCS)
    if bad := unknown_keys(paths):
        print("error: markers without a measurement: " + ", ".join(bad), file=sys.stderr)
        return 2
    keys = {m["key"] for p in paths for m in markers(p.read_text())}
    values = measure(keys, slow=args.slow)
    stale = 0
    for path in paths:
        text = path.read_text()
        new, changed = fill(text, values)
        if args.check:
            changed = [c for c in changed if not c.split(":")[0].endswith(TIMING_SUFFIX)]
            stale += len(changed)
            for line in changed:
                print(f"{path.relative_to(ROOT)}: {line}")
        elif new != text:
            path.write_text(new)
            for line in changed:
                print(f"{path.relative_to(ROOT)}: {line}")
    skipped = sorted(k for k in keys if k not in values)
    if skipped:
        print(f"not measured (slow; --slow runs them): {len(skipped)} numbers")
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
