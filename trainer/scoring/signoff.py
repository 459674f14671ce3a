"""The sign-off report of one unit (``trainer report``): per channel what a reviewer signs.

Per channel (one model on its own channel of the recording, in the channel's unit): the drift
against temperature with the model's fit, the drift left against temperature by heating and cooling
branch, its RMS and maximum per branch, on the held-out part and in the trained range, each beside
the uncompensated output's (:mod:`trainer.scoring.unit_scores`, the fleet's scoring too), the
coverage of the recording's temperatures by the trained range, the model id, the ``codegen verify``
result, the module's flash, RAM and instructions, and the verdict (:mod:`trainer.scoring.verdict`)
from the thresholds (:mod:`trainer.scoring.thresholds`) and the guard against a model that leaves
more drift than no compensation. Everything is a function of the inputs: no dates, no paths other
than those given, so the same inputs give the same document.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from matplotlib.axes import Axes

from trainer import methods as registry
from trainer.compensator import Compensator
from trainer.data.recording import Recording
from trainer.scoring.evaluate import smooth_for_scoring
from trainer.scoring.markdown import markdown_table
from trainer.scoring.plots import new_figure, save_figure
from trainer.scoring.static import COOLING, HEATING, DriftLeft, thermal_branch
from trainer.scoring.thresholds import THRESHOLDS, passes
from trainer.scoring.unit_scores import PartScores, UnitScores, coverage
from trainer.scoring.verdict import (
    NO_VERDICT,
    Figures,
    SegmentFigures,
    Verdict,
    outside_trained_range,
    undetermined_reason,
    verdict,
    worse_on_a_part,
    worse_on_a_segment,
    worse_than_uncompensated,
)

NOT_MEASURED = "not measured"
# the flash figure a module's manifest gives: its const tables, not its code, so it is shown but does
# not measure a flash threshold (the module's object is, ``bench/bench_cortex_m.py --json``)
TABLES_ONLY = "manifest: const tables only"


@dataclass(frozen=True)
class VerifySummary:
    """What ``codegen verify`` found (run by the report, or read from ``codegen verify --json``)."""

    mismatches: int
    samples: int
    state_equal: bool
    model_id: str
    source: str  # the module directory or the JSON file
    rate_millihz: int = 0  # the module's declared rate (0: any)
    resampled_from_hz: float | None = None  # the recording's rate when verify interpolated it
    schedule: str = "step"  # the module's network-step schedule (manifest)
    latency_samples: int = 0  # spread: samples by which the estimate comes later than with "step"
    delayed_equal: bool | None = None  # spread: drift removed = the step schedule's, delayed (None: not run)
    # spread, run by the report: the fixed-point module's drift left by schedule (codegen.verify.schedule_parts)
    schedule_scores: tuple[tuple[str, DriftLeft], ...] = ()

    @property
    def ok(self) -> bool:
        return self.mismatches == 0 and self.state_equal


@dataclass(frozen=True)
class Cost:
    """Flash, RAM and instructions per sample of the module, each with where it comes from."""

    flash_bytes: tuple[float, str] | None = None
    ram_bytes: tuple[float, str] | None = None
    instructions_per_sample: tuple[float, str] | None = None


@dataclass
class ChannelReport:
    channel: str  # what the report calls the channel: the training recording's channel, else the file stem
    unit: str  # the channel's unit as printed: mg, deg/s, Pa
    model_path: str
    model_id: str
    method: str  # the registered method (what loads it)
    trained_range_c: tuple[float, float]
    recording_range_c: tuple[float, float]
    scores: UnitScores
    held_out: str | None = None  # how the held-out part was chosen
    # the checkpoint's selection record (trainer.selection) when the report's recording is its training run
    crossval: dict[str, Any] | None = None
    verify: VerifySummary | None = None
    cost: Cost = field(default_factory=Cost)
    notes: list[str] = field(default_factory=list)
    figures: list[str] = field(default_factory=list)
    shown: str = ""  # the name the reader knows it by (auto's candidate: poly2, physics-branch), else method
    undetermined: list[str] = field(default_factory=list)  # Compensator.undetermined(): a review reason
    # the share of the recording's rows the model was trained on (trainer.data.holdout.training_row_share),
    # None for none: without a hold-out the figures are in-sample on that share, else of another run
    training_row_share: float | None = 1.0
    # train_stats.held_out of a model fitted with --holdout, when the recording is its training run: the
    # figures of the part that fit held out (trainer.scoring.fit_holdout), judged when the report has
    # no held-out part of its own that is not training rows
    fit_held_out: dict[str, Any] | None = None
    # the share of the --holdout part's rows that are training rows (overlap_warning), None when it holds
    # none: its figures are in-sample there, so a held-out threshold is not measured by them (a model
    # trained on the whole run passed one on its own data) and the guard says so
    held_out_training_share: float | None = None
    scored_range_c: tuple[float, float] | None = None  # the temperatures the figures are of (None: not kept)

    @property
    def name(self) -> str:
        return self.shown or self.method

    @property
    def held_out_in_sample(self) -> bool:
        return self.held_out_training_share is not None

    @property
    def label(self) -> str:
        return f"{self.channel} / {self.name}"

    @property
    def stem(self) -> str:
        """File-name stem of the channel's figures."""
        return f"{self.channel}_{self.name}".replace("/", "_")

    @property
    def coverage(self) -> float:
        """Share of the recording's temperature span inside the trained range (1: all of it)."""
        return coverage(self.recording_range_c, self.trained_range_c)

    @property
    def figures_for_verdict(self) -> Figures:
        """The figures the guard compares: cross-validated when the model carries its cross-validation
        on this run, else held-out (the whole recording's, in-sample, without a hold-out)."""
        part = self.scores.headline
        if self.crossval is not None:
            from trainer.selection import cross_validated_figures

            cv = cross_validated_figures(self.crossval)
            return Figures(
                f"cross-validated over {cv.segments} thermal segments",
                cv.model,
                cv.uncompensated,
                cv.model_in_range,
                cv.uncompensated_in_range,
                noise_floor=part.noise_floor_mg,
                unit=self.unit,
            )
        if self.fit_held_out is not None and (self.scores.held_out is None or self.held_out_in_sample):
            from trainer.scoring.fit_holdout import held_out_figures

            return held_out_figures(self.fit_held_out, self.unit)
        return Figures(
            self.part_basis,
            part.model.rms_mg,
            part.uncompensated.rms_mg,
            math.nan if part.model_in_range is None else part.model_in_range.rms_mg,
            math.nan if part.uncompensated_in_range is None else part.uncompensated_in_range.rms_mg,
            part.noise_floor_mg,
            self.unit,
        )

    @property
    def part_basis(self) -> str:
        """What the headline part's rows are to the model: held out, or training rows (in-sample)."""
        if self.scores.held_out is not None and self.held_out_training_share is not None:
            return (
                f"held-out ({100 * self.held_out_training_share:.0f} % of it training rows, in-sample there)"
            )
        if self.scores.held_out is not None:
            return "held-out"
        if self.training_row_share is not None and self.training_row_share >= 1.0:
            return "all samples (in-sample)"
        if self.training_row_share is not None:  # a model fitted with --holdout, scored on the whole run
            return (
                f"all samples ({100 * self.training_row_share:.0f} % of them training rows, in-sample there)"
            )
        return "all samples of a recording not trained on"

    @property
    def review(self) -> list[str]:
        """Why a human should look (the verdict's REVIEW): a model that cross-validation found better
        than no compensation pooled but worse on one held-out segment; a model that carries a
        parameter its training run does not determine (it extrapolates wherever its state is not the
        training run's)."""
        undetermined = undetermined_reason(self.label, self.undetermined)
        reasons = [] if undetermined is None else [undetermined]
        if self.crossval is None and self.scored_range_c is not None:
            outside = outside_trained_range(self.label, coverage(self.scored_range_c, self.trained_range_c))
            reasons += [] if outside is None else [outside]
        if self.crossval is None:
            # a branch the model misplaces (a hysteresis, a lag) shows on the heating or cooling rows
            # alone; auto refuses that for what it ships (trainer.selection.own_run_failure), a model
            # fitted by name gets this look
            part = self.scores.headline
            branches = [
                SegmentFigures(
                    f"{b} rows of the scored part, {self.part_basis},",
                    getattr(part.model, f"{b}_rms_mg"),
                    getattr(part.uncompensated, f"{b}_rms_mg"),
                )
                for b in ("heating", "cooling")
            ]
            branch = worse_on_a_part(self.label, "", branches, part.noise_floor_mg, self.unit)
            return reasons + ([] if branch is None else [branch])
        from trainer.selection import cross_validated_figures

        floor = self.scores.headline.noise_floor_mg
        reason = worse_on_a_segment(
            self.label, cross_validated_figures(self.crossval).per_segment, floor, self.unit
        )
        return reasons + ([] if reason is None else [reason])


def drift_left(rec: Recording, compensated: np.ndarray, smoothing_s: float) -> np.ndarray:
    """The smoothed compensated output minus its mean (the residual figure's points)."""
    x = smooth_for_scoring(np.asarray(compensated, dtype=np.float64), rec.sample_rate_hz, smoothing_s)
    return x - x.mean()


# -- checks ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Check:
    channel: str
    key: str
    what: str
    measured: float | None  # None: not measured
    limit: float
    unit: str = ""  # the channel's unit for the drift-left keys (the *_mg keys read in it)
    decisive: bool = True  # a configured threshold: its pass counts towards PASS

    @property
    def ok(self) -> bool:
        return self.measured is not None and passes(self.key, self.measured, self.limit)

    @property
    def name(self) -> str:
        return f"{self.channel} {self.key} ({self.what})"

    @property
    def limit_text(self) -> str:
        t = THRESHOLDS[self.key]
        unit = self.unit if t.unit == "mg" and self.unit else t.unit
        return f"{'<=' if t.bound == 'max' else '>='} {_num(self.limit)} {unit}".strip()


def _value(left: DriftLeft | None, kind: str) -> float | None:
    """RMS or maximum of one branch ("", "heating_", "cooling_"); None when it has no samples."""
    if left is None:
        return None
    branch, stat = kind.rsplit(":", 1)
    samples = {"": left.samples, "heating_": left.heating_samples, "cooling_": left.cooling_samples}[branch]
    if samples == 0:
        return None
    return float(getattr(left, f"{branch}{'rms_mg' if stat == 'rms' else 'max_abs_mg'}"))


def checks(report: ChannelReport, thresholds: dict[str, float]) -> list[Check]:
    """One check per configured threshold (and per branch for the branch keys)."""
    whole = report.scores.whole.model
    held = (
        None if report.scores.held_out is None or report.held_out_in_sample else report.scores.held_out.model
    )
    held_what = (
        "held-out part, in-sample: the model was trained on it" if report.held_out_in_sample else "held-out"
    )
    cost = report.cost
    measured: dict[str, list[tuple[str, float | None]]] = {
        "residual_rms_mg": [("all samples", _value(whole, ":rms"))],
        "residual_max_mg": [("all samples", _value(whole, ":max"))],
        "branch_rms_mg": [(b, _value(whole, f"{b}_:rms")) for b in ("heating", "cooling")],
        "branch_max_mg": [(b, _value(whole, f"{b}_:max")) for b in ("heating", "cooling")],
        "holdout_rms_mg": [(held_what, _value(held, ":rms"))],
        "holdout_max_mg": [(held_what, _value(held, ":max"))],
        "min_coverage": [("trained range", report.coverage)],
        "max_verify_mismatches": [("codegen verify", _verify_count(report))],
        "max_flash_bytes": [
            (
                "module",
                None
                if cost.flash_bytes is None or cost.flash_bytes[1] == TABLES_ONLY
                else cost.flash_bytes[0],
            )
        ],
        "max_ram_bytes": [("module", None if cost.ram_bytes is None else cost.ram_bytes[0])],
        "max_instructions_per_sample": [
            ("module", None if cost.instructions_per_sample is None else cost.instructions_per_sample[0])
        ],
    }
    if report.verify is not None and "max_verify_mismatches" not in thresholds:
        # a verified module is a decisive fact without a --config, as in trainer fleet (one verdict):
        # the C is bit-exact or it is not
        thresholds = {**thresholds, "max_verify_mismatches": 0.0}
    return [
        Check(report.label, key, what, value, limit, report.unit)
        for key, limit in thresholds.items()
        for what, value in measured[key]
    ]


def unit_verdict(reports: Sequence[ChannelReport], thresholds: dict[str, float]) -> Verdict:
    """The unit's verdict: every channel's threshold checks and its guard against uncompensated."""
    return verdict(
        {r.label: r.figures_for_verdict for r in reports},
        [c for r in reports for c in checks(r, thresholds)],
        [reason for r in reports for reason in r.review],
    )


def _verify_count(report: ChannelReport) -> float | None:
    """Mismatching samples, a differing final state counting as one more; None (not measured) without
    a verify result or with one of another model."""
    v = report.verify
    if v is None or v.model_id != report.model_id:
        return None
    return float(v.mismatches + (0 if v.state_equal else 1))


# -- figures -----------------------------------------------------------------------------------


# Limit lines drawn on the drift-left figure: threshold key -> line style. The branch and whole-run
# limits hold everywhere; the held-out one only over the held-out part.
LIMIT_STYLES: dict[str, Literal["--", ":", "-."]] = {
    "residual_max_mg": "--",
    "branch_max_mg": ":",
    "holdout_max_mg": "-.",
}
HELD_OUT_COLOUR = "tab:orange"


def write_figures(
    report: ChannelReport,
    rec: Recording,
    model: Compensator,
    compensated: np.ndarray,
    smoothing_s: float,
    out_dir: Path,
    thresholds: dict[str, float],
    held_out: slice | None = None,
) -> list[str]:
    """``CHANNEL_drift.png`` (the drift and the model's fit against temperature) and
    ``CHANNEL_residual.png`` (the drift left against temperature by branch, and against time).

    ``held_out``: the rows of the held-out part, shaded with a label (its span of time, and of
    temperature on the temperature axes); every limit line of ``thresholds`` is in the legend."""
    temp = np.asarray(rec.temp_c, dtype=np.float64)
    branch = thermal_branch(temp, rec.sample_rate_hz)
    predicted = model.predict_drift(rec.without_truth())
    measured = smooth_for_scoring(rec.accel_mg, rec.sample_rate_hz, smoothing_s)
    constant = float(np.mean(measured - predicted))
    lo, hi = report.trained_range_c
    names = [f"{report.stem}_drift.png", f"{report.stem}_residual.png"]
    held_time = None if held_out is None else rec.time_s[held_out]
    held_temp = None if held_out is None else temp[held_out]

    fig = new_figure((8, 5), 110)
    ax = fig.add_subplot()
    _by_branch(ax, temp, measured - constant, branch, "measured")
    if registry.REGISTRY[report.method].family == registry.MEMORYLESS:
        order = np.argsort(temp, kind="stable")
        ax.plot(temp[order], predicted[order], color="black", linewidth=1.0, label=f"{report.name} fit")
    else:  # a function of the temperature history: one point per sample
        ax.scatter(temp, predicted, s=1, color="black", label=f"{report.name} fit")
    _shade_held_out(ax, held_temp, held_time, "temperature")
    _finish(
        ax, lo, hi, f"drift ({report.unit}, measured minus its constant)", f"{report.label}: drift and fit"
    )
    fig.tight_layout()
    save_figure(fig, out_dir / names[0])

    left = drift_left(rec, compensated, smoothing_s)
    fig = new_figure((8, 8), 110)
    ax, over_time = fig.subplots(2, 1, height_ratios=(3, 2))
    _by_branch(ax, temp, left, branch, "drift left")
    _limit_lines(ax, thresholds, report.unit, held_out=False)
    _shade_held_out(ax, held_temp, held_time, "temperature")
    _finish(ax, lo, hi, f"drift left ({report.unit})", f"{report.label}: drift left by branch")
    over_time.plot(rec.time_s / 60.0, left, color="0.3", linewidth=0.6, label="drift left")
    _limit_lines(over_time, thresholds, report.unit, held_out=False)
    if held_time is not None:
        _limit_lines(over_time, thresholds, report.unit, held_out=True, span_min=held_time / 60.0)
    _shade_held_out(over_time, held_temp, held_time, "time")
    over_time.set_xlabel("time (min)")
    over_time.set_ylabel(f"drift left ({report.unit})")
    over_time.set_title(f"{report.label}: drift left over time")
    over_time.grid(True, alpha=0.3)
    over_time.legend(loc="best", fontsize=8)
    fig.tight_layout()
    save_figure(fig, out_dir / names[1])
    return names


def _limit_lines(
    ax: Axes, thresholds: dict[str, float], unit: str, *, held_out: bool, span_min: np.ndarray | None = None
) -> None:
    """The configured |drift left| limits as +-lines, labelled once each in the legend; the held-out
    limit (``held_out``) only over the held-out part's time span (``span_min``, minutes)."""
    for key, style in LIMIT_STYLES.items():
        if key not in thresholds or (key == "holdout_max_mg") != held_out:
            continue
        label = f"limit {key}: +-{_num(thresholds[key])} {unit}"
        for sign in (1, -1):
            value, shown = sign * thresholds[key], label if sign > 0 else "_nolegend_"
            if span_min is None:
                ax.axhline(value, color="gray", linestyle=style, linewidth=0.8, label=shown)
            else:
                ax.hlines(
                    value, float(span_min[0]), float(span_min[-1]), "gray", style, linewidth=0.8, label=shown
                )


def _shade_held_out(ax: Axes, temp: np.ndarray | None, time_s: np.ndarray | None, axis: str) -> None:
    """Shade the held-out part: its time span on a time axis, its temperatures on a temperature axis."""
    if temp is None or time_s is None or len(time_s) == 0:
        return
    when = f"t = {time_s[0]:g} .. {time_s[-1]:g} s"
    if axis == "time":
        lo, hi, label = time_s[0] / 60.0, time_s[-1] / 60.0, f"held-out part ({when})"
    else:
        lo, hi = float(np.min(temp)), float(np.max(temp))
        label = f"held-out part's temperatures ({lo:.1f} .. {hi:.1f} degC, {when})"
    ax.axvspan(lo, hi, color=HELD_OUT_COLOUR, alpha=0.15, linewidth=0, label=label)


def _by_branch(ax: Axes, temp: np.ndarray, values: np.ndarray, branch: np.ndarray, what: str) -> None:
    styles = ((HEATING, "heating", "tab:red"), (COOLING, "cooling", "tab:blue"), (0, "neither", "0.6"))
    for value, label, color in styles:
        mask = branch == value
        if mask.any():
            ax.scatter(temp[mask], values[mask], s=3, color=color, label=f"{what}, {label}")


def _finish(ax: Axes, lo: float, hi: float, ylabel: str, title: str) -> None:
    for index, edge in enumerate((lo, hi)):
        ax.axvline(
            edge, color="green", linestyle="--", linewidth=0.8, label=None if index else "trained range"
        )
    ax.set_xlabel("temperature (degC); dashed green: trained range")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8, markerscale=3)


# -- the document ------------------------------------------------------------------------------
def _mg(value: float) -> str:
    return "n/a" if not math.isfinite(value) else f"{value:.4g}"


def _num(value: float) -> str:
    return f"{value:.4g}"


def render(
    unit: str,
    reports: Sequence[ChannelReport],
    thresholds: dict[str, float],
    *,
    recordings: Sequence[str],
    config: str | None,
    smoothing_s: float,
    version: str,
) -> str:
    """The Markdown document (figures referenced by file name, beside it)."""
    all_checks = [c for r in reports for c in checks(r, thresholds)]
    decided = unit_verdict(reports, thresholds)
    lines = [
        f"# Sign-off report: {unit}",
        "",
        f"Generated by mems-tdc {version} (`trainer report`) from {', '.join(f'`{r}`' for r in recordings)}; "
        f"thresholds: {f'`{config}`' if config else 'none'}. Drift left = the compensated output, smoothed "
        f"over {smoothing_s:g} s, minus one constant (its mean): on a static chamber run everything else "
        "is drift the model left (docs/real-data.md). Branches from the temperature rate (60 s slope, "
        "+-0.2 degC/min dead band).",
        "",
        f"## Verdict: {_status(decided)}",
        "",
    ]
    lines += [
        f"- {r.label}: {worse_than_uncompensated(r.label, r.figures_for_verdict).detail}" for r in reports
    ]
    lines += [f"- review: {reason}" for reason in decided.review]
    lines.append("")
    if all_checks:
        rows = [
            [
                c.channel,
                f"`{c.key}` ({c.what})",
                NOT_MEASURED if c.measured is None else _num(c.measured),
                c.limit_text,
                "PASS" if c.ok else "FAIL",
            ]
            for c in all_checks
        ]
        lines += [markdown_table(["channel", "check", "measured", "threshold", "result"], rows, "llrrl"), ""]
        if any(c.key.startswith("holdout_") for c in all_checks):
            lines += [
                "Each part is scored about its own mean (the drift a constant calibration leaves there): "
                "the held-out part's maximum can exceed the whole recording's.",
                "",
            ]
    for r in reports:
        lines += _channel_section(r)
    lines += [
        "## Sign-off",
        "",
        "| role | name | date | signature |",
        "|---|---|---|---|",
        "| prepared |  |  |  |",
        "| reviewed |  |  |  |",
        "",
    ]
    return "\n".join(lines)


def _channel_section(r: ChannelReport) -> list[str]:
    lo, hi = r.trained_range_c
    rlo, rhi = r.recording_range_c
    lines = [
        f"## Channel {r.label}",
        "",
        f"- Model: `{r.model_path}`, method `{r.name}`, id `{r.model_id}`",
        f"- Coverage: trained {lo:.2f} .. {hi:.2f} degC; recording {rlo:.2f} .. {rhi:.2f} degC; "
        f"{100 * r.coverage:.1f} % of the recording's span inside the trained range",
    ]
    if r.held_out:
        lines.append(f"- Held-out data: {r.held_out}")
    lines += [f"- Note: {n}" for n in r.notes]
    lines += [f"- Not determined by the training run (review): {u}" for u in r.undetermined]
    if r.crossval is not None:
        from trainer.selection import record_lines

        lines += ["", "### Cross-validation (how `--method auto` chose this model; the verdict uses it)", ""]
        lines += record_lines(r.crossval)
    lines.append("")
    lines += [f"![{name}]({name})" for name in r.figures]
    lines.append("")
    u = r.unit
    header = ["part / branch", "samples", f"RMS ({u})", f"max ({u})", f"uncompensated RMS ({u})"]
    header.append(f"uncompensated max ({u})")
    lines += [
        markdown_table(header, score_rows(r.scores), "lrrrrr"),
        "",
        f"Noise floor (no compensator removes it): {_mg(r.scores.whole.noise_floor_mg)} {u} RMS"
        + (
            ""
            if r.scores.held_out is None
            else f" (held-out part: {_mg(r.scores.held_out.noise_floor_mg)} {u} RMS)"
        )
        + ".",
        "",
    ]
    v = r.verify
    if v is None:
        lines.append(f"- codegen verify: {NOT_MEASURED}")
    else:
        state = "identical" if v.state_equal else "DIFFERENT"
        lines.append(
            f"- codegen verify (`{v.source}`): {v.mismatches} mismatches in {v.samples} samples, final "
            f"state {state}: {'bit-exact' if v.ok else 'NOT bit-exact'}; module rate "
            + (
                f"{v.rate_millihz / 1000:g} Hz"
                if v.rate_millihz
                else "any (nothing in it depends on the sample rate)"
            )
            + (f", recording resampled from {v.resampled_from_hz:g} Hz" if v.resampled_from_hz else "")
            + ("" if v.model_id == r.model_id else f"; WARNING: the module is of model {v.model_id}")
        )
        if v.schedule != "step":
            lines.append(
                f"- schedule `{v.schedule}`: the estimate takes effect {v.latency_samples} samples later than "
                f"with `step` (nothing is removed on the first {v.latency_samples} samples after init or reset)"
                + (
                    ""
                    if v.delayed_equal is None
                    else f"; drift removed = the step schedule's delayed by {v.latency_samples} samples on "
                    f"every sample: {'yes' if v.delayed_equal else 'NO'}"
                )
                + (
                    "; drift left by the fixed-point module, each schedule over the samples that hold the same "
                    f"estimates (the step schedule's first n - {v.latency_samples}, the spread one's last): "
                    + ", ".join(f"{k} {_mg(sc.rms_mg)} {r.unit} RMS" for k, sc in v.schedule_scores)
                    if v.schedule_scores
                    else ""
                )
            )
    for label, item, unit in (
        ("flash", r.cost.flash_bytes, "B"),
        ("RAM", r.cost.ram_bytes, "B"),
        ("instructions per sample (Cortex-M4)", r.cost.instructions_per_sample, ""),
    ):
        text = NOT_MEASURED if item is None else f"{item[0]:.0f} {unit} ({item[1]})".replace("  ", " ")
        lines.append(f"- {label}: {text}")
    lines.append("")
    return lines


def _branch_cells(model: DriftLeft, raw: DriftLeft) -> list[list[str]]:
    """samples, RMS and max of the model then of the uncompensated output: all, heating, cooling."""
    rows = []
    for label, branch in (("all", ""), ("heating", "heating_"), ("cooling", "cooling_")):
        samples = {"": model.samples, "heating_": model.heating_samples, "cooling_": model.cooling_samples}
        cells = [label, str(samples[branch])]
        for left in (model, raw):
            cells += [_mg(getattr(left, f"{branch}rms_mg")), _mg(getattr(left, f"{branch}max_abs_mg"))]
        rows.append(cells)
    return rows


def _part_rows(part: PartScores, prefix: str) -> list[list[str]]:
    rows = [[prefix + row[0], *row[1:]] for row in _branch_cells(part.model, part.uncompensated)]
    if part.model_in_range is not None and part.uncompensated_in_range is not None:
        cells = _branch_cells(part.model_in_range, part.uncompensated_in_range)[0]
        # the samples inside the range, scored about their own constant (so its max can exceed "all"'s)
        rows.append([f"{prefix}in trained range (about its own constant)", *cells[1:]])
    return rows


def score_rows(scores: UnitScores) -> list[list[str]]:
    """The drift-left table: whole recording, then the held-out part (``held-out ...`` rows)."""
    rows = _part_rows(scores.whole, "")
    if scores.held_out is not None:
        rows += _part_rows(scores.held_out, "held-out ")
    return rows


def _status(decided: Verdict) -> str:
    return "NO VERDICT (no thresholds given: --config)" if decided.status == NO_VERDICT else decided.status


def summary_line(unit: str, reports: Sequence[ChannelReport], thresholds: dict[str, float]) -> str:
    decided = unit_verdict(reports, thresholds)
    failed = f" (failed: {', '.join(decided.failed)})" if decided.failed else ""
    review = f" (review: {'; '.join(decided.review)})" if decided.review else ""
    return f"{unit}: {_status(decided)}{failed}{review}"
