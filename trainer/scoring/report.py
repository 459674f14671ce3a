"""The comparison report: Markdown tables next to the paper's Table 1, and Figures 10-13 as PNGs."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from trainer import methods as registry
from trainer.data.channels import DEFAULT_UNIT, signal_of
from trainer.data.recording import Recording
from trainer.data.smoothing import moving_average, window_samples
from trainer.dlstm.realtime import PAPER_TRAIN_SMOOTHING_S
from trainer.scoring.allan import plot_allan
from trainer.scoring.compare import Comparison
from trainer.scoring.evaluate import Evaluation
from trainer.scoring.markdown import markdown_table
from trainer.scoring.plots import plot_fit, plot_series
from trainer.scoring.static import DEAD_BAND_C_PER_MIN, RATE_WINDOW_S, DriftLeft


def how_to_read(comparison: Comparison) -> str:
    """Why the report ranks by drift left, said with this comparison's own figures: the persistence
    row's Allan score when it was run, ground truth and the oracle row only when the data has them."""
    averages = comparison.evaluation.table.average_improvement_pct
    text = (
        "An Allan-variance improvement rewards any operation that removes low-frequency content, a real "
        "acceleration as readily as the drift."
    )
    persistence = next((m.name for m in registry.entries() if m.reference and m.name in averages), None)
    if persistence is not None:
        others = {k: v for k, v in averages.items() if k != persistence and math.isfinite(v)}
        best = max(others, key=lambda k: others[k], default=None)
        compared = f"; the best method here, {best}, {others[best]:.2f} %" if best is not None else ""
        text += (
            f" The {persistence} row subtracts the previous smoothed output with no model at all: it scores "
            f"{averages[persistence]:.2f} % on average (Aver){compared}."
        )
    if comparison.evaluation.drift:
        return text + (
            " Methods are therefore ranked by what compensation has to achieve: the RMS of the drift left "
            "behind against the simulator's ground truth (`true_drift_mg`), and the fraction of a true input "
            "signal that survives compensation. The oracle row removes the exact true drift (evaluation "
            "only): it is what perfect compensation scores."
        )
    return text + (
        " Methods are therefore ranked by the drift left on this recording, which has no ground truth "
        "(the compensated output's deviation from a constant, below), and, where an input was injected "
        "(`--inject`), by the fraction of it that survives compensation."
    )


def _sci(value: float) -> str:
    return "n/a" if not math.isfinite(value) else f"{value:.3g}"


def _drift_cells(left: DriftLeft | None) -> list[str]:
    if left is None:
        return ["n/a"] * 4
    return [_sci(left.rms_mg), _sci(left.max_abs_mg), _sci(left.heating_rms_mg), _sci(left.cooling_rms_mg)]


def headline_table(comparison: Comparison) -> str:
    """One row per method: drift left (overall, max, per branch), input kept, Allan improvement.

    The drift left is measured against ``true_drift_mg`` when the validation recording has it, else
    as the deviation of the compensated output from a constant (a static recording); the last row
    is the white-noise floor no compensator can go below.
    """
    evaluation = comparison.evaluation
    table = evaluation.table
    survival_sets = list(comparison.survival.items())
    header = ["method", "drift left RMS (mg)", "max (mg)", "heating RMS (mg)", "cooling RMS (mg)"]
    in_range = evaluation.static_in_range if not evaluation.drift else {}
    if in_range:  # a static recording partly outside the training range: extrapolation apart
        header.append("in training range RMS (mg)")

    def in_range_cell(name: str) -> list[str]:
        if not in_range:
            return []
        return [_sci(in_range[name].rms_mg) if name in in_range else ""]

    header += [f"input kept: {Path(src).stem} (%)" for src, _ in survival_sets]
    header += ["B (mg)", "K (mg/s^1/2)", "R (mg/s)", "Allan aver. impr. (%)", "fit time (s)"]
    raw = table.raw
    rows = [
        ["uncompensated", *_drift_cells(evaluation.drift_left("raw")), *in_range_cell("raw")]
        + ["100" for _ in survival_sets]
        + [_sci(raw.b_mg), _sci(raw.k_mg_per_rt_s), _sci(raw.r_mg_per_s), "", ""]
    ]
    for name, coefficients in table.compensated.items():
        row = [name, *_drift_cells(evaluation.drift_left(name)), *in_range_cell(name)]
        for _, scores in survival_sets:
            row.append(f"{100 * scores[name].gain:.1f}" if name in scores else "n/a")
        row += [
            _sci(coefficients.b_mg),
            _sci(coefficients.k_mg_per_rt_s),
            _sci(coefficients.r_mg_per_s),
            f"{table.average_improvement_pct[name]:.2f}",
            f"{comparison.fit_seconds[name]:.1f}" if name in comparison.fit_seconds else "",
        ]
        rows.append(row)
    floor = _sci(evaluation.noise_floor_mg)
    rows.append(["noise floor (white noise)", floor] + [""] * (len(header) - 2))
    return markdown_table(header, rows)


def drift_left_explanation(evaluation: Evaluation) -> str:
    """What the headline's drift-left columns measure, for the report."""
    heating, cooling = evaluation.branch_fractions
    branches = (
        f"`heating` / `cooling`: the same over the samples whose temperature rate (centred "
        f"{RATE_WINDOW_S:g} s least-squares slope) is above +{DEAD_BAND_C_PER_MIN:g} degC/min / below "
        f"-{DEAD_BAND_C_PER_MIN:g} degC/min ({100 * heating:.1f} % / {100 * cooling:.1f} % of the "
        "samples; the rest dwell or turn)."
    )
    floor = (
        f"The noise floor ({_sci(evaluation.noise_floor_mg)} mg) is the white-noise RMS of the raw output "
        f"after the same {evaluation.smoothing_s} s smoothing, from first differences: a drift left near "
        "it is noise, not drift."
    )
    if evaluation.drift:
        return (
            "`drift left` is `true_drift_mg - (accel_mg - compensated)` on the validation recording, "
            "RMS and maximum magnitude; a method that models the drift relative to T_ref (the default "
            "for temperature-driven methods, docs/trainer.md) is scored against the true drift relative "
            f"to its value at T_ref. {branches} {floor}"
        )
    return (
        "The validation recording has no ground truth: it is scored as a static recording, where "
        "everything the compensated output does besides noise is drift left. `drift left` is the "
        f"deviation of the compensated output ({evaluation.smoothing_s} s smoothing) from one constant "
        f"(its mean), RMS and maximum magnitude. {branches} {floor}"
        + (
            " `in training range`: the RMS over the samples whose temperature lies inside the training "
            "range (outside it every temperature-driven method extrapolates or holds its end value)."
            if evaluation.static_in_range
            else ""
        )
    )


def paper_side_by_side(comparison: Comparison) -> str:
    """Our improvements next to the paper's, for the paper's four methods."""
    improvements = comparison.evaluation.table.improvement_pct
    average = comparison.evaluation.table.average_improvement_pct
    header = ["method", "B impr. ours / paper (%)", "K impr. ours / paper (%)", "R impr. ours / paper (%)"]
    header += ["Aver ours / paper (%)"]
    rows = []
    for name in registry.paper_names():
        if name not in improvements:
            continue
        paper = registry.REGISTRY[name].paper_table1
        assert paper is not None
        ours = improvements[name]
        row = [name]
        for term, key in (("B", "b_mg"), ("K", "k_mg_per_rt_s"), ("R", "r_mg_per_s")):
            row.append(f"{ours[key]:.2f} / {paper.term(term)[1]:.2f}")
        row.append(f"{average[name]:.2f} / {paper.Aver:.2f}")
        rows.append(row)
    return markdown_table(header, rows)


def write_figures(comparison: Comparison, train: Recording, valid: Recording, out_dir: Path) -> list[str]:
    """Figures 10-13 of the paper plus the input-survival figure; returns the file names."""
    names = []
    # a reference predictor (persistence) would hide the data
    shown = [m for m in comparison.models if not registry.REGISTRY[m].reference]
    signal = signal_of(valid)
    for rec, name, title in (
        (train, "fig10_training_fit.png", "Fit on training data (drift estimate vs 5 s smoothed output)"),
        (valid, "fig11_validation_fit.png", "Fit on validation data (drift estimate vs 5 s smoothed output)"),
    ):
        blind = rec.without_truth()
        reference = _smooth(rec.accel_mg, rec.sample_rate_hz, PAPER_TRAIN_SMOOTHING_S)
        estimates = {m: comparison.models[m].predict_drift(blind) for m in shown}
        plot_fit(
            rec.time_s,
            "output (5 s smoothing)",
            reference,
            estimates,
            out_dir / name,
            title=title,
            signal=signal,
        )
        names.append(name)
    evaluation = comparison.evaluation
    smoothed = {
        k: v
        for k, v in evaluation.smoothed.items()
        if k not in registry.REGISTRY or not registry.REGISTRY[k].reference
    }
    plot_series(
        valid.time_s,
        smoothed,
        out_dir / "fig12_compensated.png",
        title=f"Compensated validation output ({evaluation.smoothing_s} s smoothing)",
        signal=signal,
    )
    plot_allan(
        dict(evaluation.curves),
        out_dir / "fig13_allan.png",
        title="Allan deviation after compensation",
        signal=signal,
    )
    names += ["fig12_compensated.png", "fig13_allan.png"]
    return names


def write_survival_figure(comparison: Comparison, rec: Recording, out_dir: Path, name: str) -> None:
    """True input against each compensated output (5 s smoothing) on an input-test recording."""
    blind = rec.without_truth()
    rate = rec.sample_rate_hz
    true_input = rec.truth("accel_mg")
    assert true_input is not None, "input tests carry true_accel_mg (checked on reading)"
    series = {"true input": true_input}
    series.update(
        {
            m: _smooth(model.compensate(blind), rate, PAPER_TRAIN_SMOOTHING_S)
            for m, model in comparison.models.items()
        }
    )
    plot_series(
        rec.time_s,
        series,
        out_dir / name,
        title=f"True input after compensation ({Path(rec.source).name})",
        signal=signal_of(rec),
    )


def _smooth(x: np.ndarray, rate_hz: float, seconds: float) -> np.ndarray:
    return moving_average(x, window_samples(seconds, rate_hz), mode="trailing")


def fusion_lines(comparison: Comparison) -> list[str]:
    """What SSA/ISSA actually changed: the training MSE of the best network before and after."""
    lines = []
    for name, model in comparison.models.items():
        training = getattr(model, "training", None)
        if not training or "best_loss_after_gradient" not in training or training.get("optimiser") == "none":
            continue
        before, after = training["best_loss_after_gradient"], training["best_loss"]
        change = 100.0 * (before - after) / before if before > 0 else 0.0
        lines.append(
            f"- {name}: training MSE (standardised) of the best network {before:.4e} after gradient "
            f"training, {after:.4e} after {len(training['optimiser_best_per_cycle']) - 1} cycles "
            f"({change:.3g} % better)"
        )
    if not lines:
        return []
    return [
        "## What the sparrow search changed",
        "",
        *lines,
        "",
        "The sparrow moves of eq. (9)-(11) and (16)-(17) add one scalar to every one of the 1,331 "
        "weights of a network or contract all of them towards zero, so on a gradient-trained "
        "population they rarely find a better network; the global best (and ISSA's elitism) then "
        "returns the best trained network unchanged. docs/optimiser.md has the benchmark evidence.",
        "",
    ]


def render_report(
    comparison: Comparison,
    settings: object,
    frontend: dict,
    args: object,
    figures: list[str],
    channel: str = "",
    unit: str = DEFAULT_UNIT,
) -> str:
    """The Markdown report a reviewer reads: setup, headline table, Table 1, the paper's numbers.

    ``channel``: the compared channel with its unit (``gyro0_z (deg/s)``), named in the title;
    ``unit``: its unit suffix (the paper's accelerometer figures are set beside an accelerometer's only)."""
    evaluation = comparison.evaluation
    lines = [
        f"# mems-tdc comparison report{f': channel {channel}' if channel else ''}",
        "",
        f"- training recording: `{getattr(args, 'train', '?')}`",
        f"- validation recording: `{getattr(args, 'valid', None) or 'the held-out part of the training recording'}`",
        f"- fusion settings: {settings}",
        f"- front end: {frontend} (see docs/realtime.md)",
        f"- validation smoothing before the Allan analysis: {evaluation.smoothing_s} s",
        "",
        "## How to read the scores",
        "",
        how_to_read(comparison),
        "",
        "## Headline: drift left and true input kept",
        "",
        *[f"- {note}" for note in comparison.notes],
        *([""] if comparison.notes else []),
        headline_table(comparison),
        "",
        drift_left_explanation(evaluation),
        "`input kept` is the least-squares gain of the compensated output on the true input "
        "of an input-test recording (100 % = the real signal passes untouched); for an input injected "
        "into the validation data (`--inject`) it is the gain of the change the injection makes to the "
        "compensated output, so the drift left on real data cancels.",
        "",
    ]
    for source, scores in comparison.survival.items():
        lines += [f"Input test `{source}`:", ""]
        header = ["method", "input kept (%)", "error vs true input RMS (mg)", "true input RMS (mg)"]
        rows = [
            [name, f"{100 * s.gain:.1f}", _sci(s.error_rms_mg), _sci(s.input_rms_mg)]
            for name, s in scores.items()
        ]
        lines += [markdown_table(header, rows), ""]
    lines += fusion_lines(comparison)
    lines += [
        "## The paper's Table 1 layout (Allan coefficients of the validation data)",
        "",
        evaluation.table.to_markdown(),
        "",
    ]
    if unit == DEFAULT_UNIT:
        lines += [
            "## Improvements next to the paper's Table 1",
            "",
            paper_side_by_side(comparison),
            "",
            "The paper's absolute B, K and R (of its accelerometer: 5.43e-4 mg, 4.33e-5 mg/s^1/2, "
            "1.18e-6 mg/s uncompensated) are orders of magnitude below what its own 2 h ramp implies (R x "
            "7200 s is only 8.5e-3 mg of drift), so only the improvement percentages are compared.",
            "",
        ]
    else:  # relabel_units would make the paper's accelerometer a gyroscope, its milli-g deg/s
        lines += [
            "The paper's Table 1 is of another kind of sensor: this channel's improvements are not set beside it.",
            "",
        ]
    warnings = [
        f"{name}: {100 * f:.2f} % of validation samples outside the trained temperature range"
        for name, f in evaluation.out_of_range_fraction.items()
        if f > 0
    ]
    if warnings:
        lines += ["## Warnings", "", *[f"- {w}" for w in warnings], ""]
    lines += ["## Figures", ""] + [f"![{name}]({name})" for name in figures] + [""]
    return "\n".join(lines)
