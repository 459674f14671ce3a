"""The sign-off report of one unit (``trainer report``): per channel what a reviewer signs.

Per channel (one model on its recording): the drift against temperature with the model's fit, the
drift left against temperature by heating and cooling branch, its RMS and maximum per branch and on
the held-out part (:mod:`trainer.scoring.static`, :mod:`trainer.data.holdout`), the coverage of the
recording's temperatures by the trained range, the model id, the ``codegen verify`` result, the
module's flash, RAM and instructions, and pass/fail against the thresholds
(:mod:`trainer.scoring.thresholds`). Everything is a function of the inputs: no dates, no paths
other than those given, so the same inputs give the same document.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes

from trainer import methods as registry
from trainer.compensator import Compensator
from trainer.data.recording import Recording
from trainer.scoring.evaluate import smooth_for_scoring
from trainer.scoring.markdown import markdown_table
from trainer.scoring.plots import new_figure, save_figure
from trainer.scoring.static import COOLING, HEATING, noise_floor_mg, summarise, thermal_branch
from trainer.scoring.thresholds import THRESHOLDS, passes

BRANCHES = (("all", None), ("heating", HEATING), ("cooling", COOLING))
NOT_MEASURED = "not measured"


@dataclass(frozen=True)
class Score:
    """Drift left (about one constant) over a set of samples, mg; NaN when there are none."""

    samples: int
    rms_mg: float
    max_abs_mg: float


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
    schedule_scores: tuple[tuple[str, Score], ...] = ()

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
    model_path: str
    model_id: str
    method: str
    trained_range_c: tuple[float, float]
    recording_range_c: tuple[float, float]
    scores: dict[str, Score]  # "all", "heating", "cooling", then "held-out ..." with --holdout
    noise_floor_mg: float
    held_out: str | None = None  # how the held-out part was chosen
    verify: VerifySummary | None = None
    cost: Cost = field(default_factory=Cost)
    notes: list[str] = field(default_factory=list)
    figures: list[str] = field(default_factory=list)

    @property
    def label(self) -> str:
        return f"{self.channel} / {self.method}"

    @property
    def stem(self) -> str:
        """File-name stem of the channel's figures."""
        return f"{self.channel}_{self.method}".replace("/", "_")

    @property
    def coverage(self) -> float:
        """Share of the recording's temperature span inside the trained range (1: all of it)."""
        lo, hi = self.recording_range_c
        t_lo, t_hi = self.trained_range_c
        if hi <= lo:
            return 1.0 if t_lo <= lo <= t_hi else 0.0
        return max(0.0, min(hi, t_hi) - max(lo, t_lo)) / (hi - lo)


def branch_scores(
    rec: Recording, compensated: np.ndarray, smoothing_s: float, prefix: str = ""
) -> dict[str, Score]:
    """Drift left of a static recording (about its one mean) overall and per thermal branch."""
    rate = rec.sample_rate_hz
    x = smooth_for_scoring(np.asarray(compensated, dtype=np.float64), rate, smoothing_s)
    residual = x - x.mean()
    branch = thermal_branch(rec.temp_c, rate)
    out = {}
    for label, value in BRANCHES:
        mask = np.ones(residual.size, dtype=bool) if value is None else branch == value
        if not mask.any():
            out[prefix + label] = Score(0, math.nan, math.nan)
            continue
        left = summarise(residual[mask], branch[mask])
        out[prefix + label] = Score(int(mask.sum()), left.rms_mg, left.max_abs_mg)
    return out


def drift_left(rec: Recording, compensated: np.ndarray, smoothing_s: float) -> np.ndarray:
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

    @property
    def ok(self) -> bool:
        return self.measured is not None and passes(self.key, self.measured, self.limit)


def checks(report: ChannelReport, thresholds: dict[str, float]) -> list[Check]:
    """One check per configured threshold (and per branch for the branch keys)."""
    s = report.scores

    def score(label: str, kind: str) -> float | None:
        found = s.get(label)
        if found is None or found.samples == 0:
            return None
        return found.rms_mg if kind == "rms" else found.max_abs_mg

    cost = report.cost
    measured: dict[str, list[tuple[str, float | None]]] = {
        "residual_rms_mg": [("all samples", score("all", "rms"))],
        "residual_max_mg": [("all samples", score("all", "max"))],
        "branch_rms_mg": [(b, score(b, "rms")) for b in ("heating", "cooling")],
        "branch_max_mg": [(b, score(b, "max")) for b in ("heating", "cooling")],
        "holdout_rms_mg": [("held-out", score("held-out all", "rms"))],
        "holdout_max_mg": [("held-out", score("held-out all", "max"))],
        "min_coverage": [("trained range", report.coverage)],
        "max_verify_mismatches": [("codegen verify", _verify_count(report))],
        "max_flash_bytes": [("module", None if cost.flash_bytes is None else cost.flash_bytes[0])],
        "max_ram_bytes": [("module", None if cost.ram_bytes is None else cost.ram_bytes[0])],
        "max_instructions_per_sample": [
            ("module", None if cost.instructions_per_sample is None else cost.instructions_per_sample[0])
        ],
    }
    return [
        Check(report.label, key, what, value, limit)
        for key, limit in thresholds.items()
        for what, value in measured[key]
    ]


def _verify_count(report: ChannelReport) -> float | None:
    """Mismatching samples, a differing final state counting as one more; None (not measured) without
    a verify result or with one of another model."""
    v = report.verify
    if v is None or v.model_id != report.model_id:
        return None
    return float(v.mismatches + (0 if v.state_equal else 1))


# -- figures -----------------------------------------------------------------------------------


def write_figures(
    report: ChannelReport,
    rec: Recording,
    model: Compensator,
    compensated: np.ndarray,
    smoothing_s: float,
    out_dir: Path,
    thresholds: dict[str, float],
) -> list[str]:
    """``CHANNEL_drift.png`` (the drift and the model's fit against temperature) and
    ``CHANNEL_residual.png`` (the drift left against temperature by branch)."""
    temp = np.asarray(rec.temp_c, dtype=np.float64)
    branch = thermal_branch(temp, rec.sample_rate_hz)
    predicted = model.predict_drift(rec.without_truth())
    measured = smooth_for_scoring(rec.accel_mg, rec.sample_rate_hz, smoothing_s)
    constant = float(np.mean(measured - predicted))
    lo, hi = report.trained_range_c
    names = [f"{report.stem}_drift.png", f"{report.stem}_residual.png"]

    fig = new_figure((8, 5), 110)
    ax = fig.add_subplot()
    _by_branch(ax, temp, measured - constant, branch, "measured")
    if registry.REGISTRY[report.method].family == registry.MEMORYLESS:
        order = np.argsort(temp, kind="stable")
        ax.plot(temp[order], predicted[order], color="black", linewidth=1.0, label=f"{report.method} fit")
    else:  # a function of the temperature history: one point per sample
        ax.scatter(temp, predicted, s=1, color="black", label=f"{report.method} fit")
    _finish(ax, lo, hi, "drift (mg, measured minus its constant)", f"{report.label}: drift and fit")
    fig.tight_layout()
    save_figure(fig, out_dir / names[0])

    fig = new_figure((8, 5), 110)
    ax = fig.add_subplot()
    _by_branch(ax, temp, drift_left(rec, compensated, smoothing_s), branch, "drift left")
    for key, style in (("residual_max_mg", "--"), ("branch_max_mg", ":")):
        if key in thresholds:
            for sign in (1, -1):
                ax.axhline(sign * thresholds[key], color="gray", linestyle=style, linewidth=0.8)
    _finish(ax, lo, hi, "drift left (mg)", f"{report.label}: drift left by branch")
    fig.tight_layout()
    save_figure(fig, out_dir / names[1])
    return names


def _by_branch(ax: Axes, temp: np.ndarray, values: np.ndarray, branch: np.ndarray, what: str) -> None:
    styles = ((HEATING, "heating", "tab:red"), (COOLING, "cooling", "tab:blue"), (0, "neither", "0.6"))
    for value, label, color in styles:
        mask = branch == value
        if mask.any():
            ax.scatter(temp[mask], values[mask], s=3, color=color, label=f"{what}, {label}")


def _finish(ax: Axes, lo: float, hi: float, ylabel: str, title: str) -> None:
    for edge in (lo, hi):
        ax.axvline(edge, color="green", linestyle="--", linewidth=0.8)
    ax.set_xlabel("temperature (degC); dashed green: trained range")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8, markerscale=3)


# -- the document ------------------------------------------------------------------------------
def _mg(value: float) -> str:
    return "n/a" if not math.isfinite(value) else f"{value:.3f}"


def _num(value: float) -> str:
    return f"{value:.4g}"


def verdict(all_checks: Sequence[Check]) -> str:
    if not all_checks:
        return "NO VERDICT (no thresholds given: --config)"
    return "PASS" if all(c.ok for c in all_checks) else "FAIL"


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
    lines = [
        f"# Sign-off report: {unit}",
        "",
        f"Generated by mems-tdc {version} (`trainer report`) from {', '.join(f'`{r}`' for r in recordings)}; "
        f"thresholds: {f'`{config}`' if config else 'none'}. Drift left = the compensated output, smoothed "
        f"over {smoothing_s:g} s, minus one constant (its mean): on a static chamber run everything else "
        "is drift the model left (docs/real-data.md). Branches from the temperature rate (60 s slope, "
        "+-0.2 degC/min dead band).",
        "",
        f"## Verdict: {verdict(all_checks)}",
        "",
    ]
    if all_checks:
        rows = [
            [
                c.channel,
                f"`{c.key}` ({c.what})",
                NOT_MEASURED if c.measured is None else _num(c.measured),
                f"{'<=' if THRESHOLDS[c.key].bound == 'max' else '>='} {_num(c.limit)} {THRESHOLDS[c.key].unit}".strip(),
                "PASS" if c.ok else "FAIL",
            ]
            for c in all_checks
        ]
        lines += [markdown_table(["channel", "check", "measured", "threshold", "result"], rows, "llrrl"), ""]
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
        f"- Model: `{r.model_path}`, method `{r.method}`, id `{r.model_id}`",
        f"- Coverage: trained {lo:.2f} .. {hi:.2f} degC; recording {rlo:.2f} .. {rhi:.2f} degC; "
        f"{100 * r.coverage:.1f} % of the recording's span inside the trained range",
    ]
    if r.held_out:
        lines.append(f"- Held-out data: {r.held_out}")
    lines += [f"- Note: {n}" for n in r.notes]
    lines.append("")
    lines += [f"![{name}]({name})" for name in r.figures]
    lines.append("")
    rows = [[label, str(s.samples), _mg(s.rms_mg), _mg(s.max_abs_mg)] for label, s in r.scores.items()]
    lines += [
        markdown_table(["part / branch", "samples", "RMS (mg)", "max (mg)"], rows, "lrrr"),
        "",
        f"Noise floor (no compensator removes it): {_mg(r.noise_floor_mg)} mg RMS.",
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
            + (f"{v.rate_millihz / 1000:g} Hz" if v.rate_millihz else "any (memoryless)")
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
                    + ", ".join(f"{k} {_mg(sc.rms_mg)} mg RMS" for k, sc in v.schedule_scores)
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


def summary_line(unit: str, reports: Sequence[ChannelReport], thresholds: dict[str, float]) -> str:
    all_checks = [c for r in reports for c in checks(r, thresholds)]
    failed = [f"{c.channel} {c.key} ({c.what})" for c in all_checks if not c.ok]
    return f"{unit}: {verdict(all_checks)}" + (f" (failed: {', '.join(failed)})" if failed else "")


def noise_floor(rec: Recording, smoothing_s: float) -> float:
    from trainer.data.smoothing import window_samples

    n = window_samples(smoothing_s, rec.sample_rate_hz) if smoothing_s > 0 else 1
    return noise_floor_mg(rec.accel_mg, n)
