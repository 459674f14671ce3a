"""What ``trainer plan`` writes: the chamber program (TOML for ``trainer simulate --config``), its
set-points (CSV), a plot of every profile, and the report with the table."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes

from trainer.data.channels import UNIT_LABELS
from trainer.physics.config import PhysicsConfig, config_to_toml
from trainer.physics.profiles import build_profile
from trainer.plan.design import Choice
from trainer.plan.limits import ChamberLimits
from trainer.plan.montecarlo import CUBIC, PHYSICS, sensor
from trainer.plan.priors import Prior
from trainer.plan.programs import Program
from trainer.plan.summary import Summary, Target, draws_text
from trainer.scoring.markdown import markdown_table
from trainer.scoring.plots import new_figure, save_figure

PROGRAM_TOML, SETPOINTS_CSV, PLOT_PNG, REPORT_MD = "program.toml", "setpoints.csv", "program.png", "report.md"


def program_toml(
    base: PhysicsConfig, priors: Sequence[Prior], program: Program, rate_hz: float, channel: str | None = None
) -> str:
    """The planned program on the sensor, the targets at their priors' centres (in ``channel``'s table)."""
    cfg = sensor(base, [p.centre for p in priors], program, rate_hz, channel)
    head = (
        f"# trainer plan: {program.name}, {program.duration_s / 3600:.2f} h\n"
        "# [protocol] is the chamber program; the effects are the targets at their prior ranges' centres.\n"
    )
    return head + config_to_toml(cfg)


def setpoints_csv(program: Program) -> str:
    return "time_s,setpoint_c\n" + "".join(f"{t:.12g},{c:.12g}\n" for t, c in program.corners())


def plot(path: Path, planned: Program, others: Sequence[Program], validation: Program) -> None:
    figure = new_figure((9.0, 4.5), 110)
    axes = figure.add_subplot(1, 1, 1)
    for program in others:
        _draw(axes, program, lw=1.0, alpha=0.6)
    _draw(axes, validation, lw=1.0, ls="--", color="grey")
    _draw(axes, planned, lw=2.5, color="black")
    axes.set_xlabel("time (h)")
    axes.set_ylabel("chamber set-point (degC)")
    axes.legend(fontsize=7, loc="best")
    axes.grid(alpha=0.3)
    save_figure(figure, path)


def _draw(axes: Axes, program: Program, **style: Any) -> None:
    profile = build_profile(program.name, program.start_c, program.segments)
    t = np.linspace(0.0, profile.duration_s, 2000)
    label = f"{program.name} ({program.duration_s / 3600:.1f} h)"
    axes.plot(t / 3600.0, profile.setpoint(t), label=label, **style)


def _cell(rate: float, error: float) -> str:
    err = "" if math.isnan(error) else f" ({100 * error:.0f} %)"
    return f"{100 * rate:.0f}{err}"


def table(summaries: Sequence[Summary], priors: Sequence[Prior], target: Target) -> str:
    unit = UNIT_LABELS[priors[0].unit]
    headers = [
        "profile",
        "hours",
        *(p.identifier for p in priors),
        f"physics ({unit})",
        f"cubic ({unit})",
        "physics / cubic",
        "target",
    ]
    rows = [
        [
            s.name,
            f"{s.duration_s / 3600:.2f}",
            *(_cell(s.identified[p.identifier], s.median_error[p.identifier]) for p in priors),
            f"{s.drift_left[PHYSICS]:.3g}",
            f"{s.drift_left[CUBIC]:.3g}",
            f"{s.ratio_median:.2f} (max {s.ratio_max:.2f})",
            s.verdict_label(target),
        ]
        for s in summaries
    ]
    return markdown_table(headers, rows)


def report(
    choice: Choice,
    standard: Sequence[Summary],
    priors: Sequence[Prior],
    limits: ChamberLimits,
    target: Target,
    validation: Program,
    *,
    seed: int,
    rate_hz: float,
    channel: str | None = None,
) -> str:
    s = choice.summary
    lines = [
        "# Chamber program (`trainer plan`)",
        "",
        f"Chamber: {limits.low_c:g}..{limits.high_c:g} degC, at most {limits.max_rate_c_per_min:g} degC/min, "
        f"{limits.settling_s:g} s settling, at most {limits.max_duration_s / 3600:g} h.",
        f"Channel: {channel or 'the accelerometer'}. "
        + "Targets (uniform priors): "
        + "; ".join(p.describe() for p in priors)
        + ".",
        f"Target: each effect identified (named by `physics`, checked parameters within {100 * target.tolerance:g} %) "
        f"in >= {100 * target.identify_rate:g} % of draws, and `physics` leaving <= {target.vs_cubic:g}x the cubic "
        "(median over draws) on the validation profile.",
        "",
        f"**Planned: {choice.program.name}, {choice.program.duration_s / 3600:.2f} h**: {s.verdict_text(target)}.",
        "",
        "Cells: identified in % of draws (median largest relative error of the checked parameters where "
        "named); drift left = RMS against the true drift on the validation profile, median over draws. "
        f"{draws_text(s.draws)} per profile, seed {seed}, simulated at {rate_hz:g} Hz; validation profile: "
        f"{validation.name} ({validation.duration_s / 3600:.2f} h, starting hot, other rates).",
        "",
        table([s, *standard], priors, target),
        "",
        "## Candidates tried (shortest first)",
        "",
        *(f"- {p.name} ({p.duration_s / 3600:.2f} h): {what}" for p, what in choice.tried),
        "",
        "## Program",
        "",
        *(
            f"{i}. {seg.label} to {seg.end_c:g} degC, {seg.duration_s / 60:.1f} min"
            for i, seg in enumerate(choice.program.segments, 1)
        ),
        "",
        f"Files: `{PROGRAM_TOML}` (`trainer simulate --config {PROGRAM_TOML} --seed N -o run.csv`), "
        f"`{SETPOINTS_CSV}` (set-point corners), `{PLOT_PNG}`.",
        "",
    ]
    return "\n".join(lines)
