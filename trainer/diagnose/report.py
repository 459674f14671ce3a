"""The diagnosis as files: JSON (machine-readable), Markdown (for people), PNG plots, augmented TOML.

A report directory is built in a temporary sibling directory and renamed into place only when
every file is written, so a failure never leaves a half-written report.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from trainer.data.channels import UNIT_LABELS
from trainer.diagnose import document
from trainer.diagnose.detection import DetectionLimit
from trainer.diagnose.document import json_text
from trainer.diagnose.next_steps import markdown_lines as next_steps_lines
from trainer.diagnose.next_steps import next_steps
from trainer.diagnose.profile import Region
from trainer.diagnose.result import Ambiguity, Diagnosis, LeftOut, Suggestive
from trainer.diagnose.select import MAX_ADDED, SUGGESTIVE, THRESHOLD
from trainer.diagnose.shared import shared_text
from trainer.diagnose.verdict import moves_text
from trainer.diagnose.where import AllanWhere
from trainer.errors import UserError, atomic_output, raise_write_error
from trainer.physics.catalogue.units import channel_param_name
from trainer.physics.config import config_to_toml
from trainer.scoring.markdown import markdown_table
from trainer.scoring.plots import new_figure, save_figure

REPORT_MARKER = "diagnosis.json"
BRANCH_COLOURS = {1: ("tab:red", "heating"), -1: ("tab:blue", "cooling"), 0: ("0.55", "hold")}


def _kind(a: Ambiguity) -> str:
    """What kind of ambiguity a line of the report's list is, when it is not a tie."""
    if a.absorbed:
        return " (absorbed, not a tie)"
    return " (undetermined by this run, not a tie)" if a.undetermined else ""


def write_json(diagnosis: Diagnosis, path: str | os.PathLike[str]) -> None:
    with atomic_output(path) as tmp:
        tmp.write_text(json_text(diagnosis), encoding="utf-8")


# ------------------------------------------------------------------------------------ Markdown


def _fmt_params(params: dict[str, float]) -> str:
    return ", ".join(f"`{k}` = {value_text(v)}" for k, v in params.items())


def _fmt_where(where: list[Region | AllanWhere]) -> str:
    parts = []
    for w in where:
        if isinstance(w, AllanWhere):
            parts.append(f"Allan tau {w.tau_range_s[0]:.3g}..{w.tau_range_s[1]:.3g} s")
            continue
        parts.append(
            f"{w.t_start_s:.0f}..{w.t_end_s:.0f} s ({w.segment}, {w.branch}, "
            f"{w.temp_min_c:.1f}..{w.temp_max_c:.1f} degC)"
        )
    return "; ".join(parts) or "-"


def _left_out_lines(entry: LeftOut, d: Diagnosis) -> list[str]:
    ev = entry.evidence
    lines = [
        f"- **{entry.effect}**{d.label}: {_fmt_params(d.params(entry.params))}. Evidence: BIC -{ev.delta_bic_when_added:.1f} "
        f"when added, +{ev.delta_bic_when_dropped:.1f} when dropped from the final model. "
        f"Where: {_fmt_where(entry.where)}."
    ]
    if entry.ambiguous_with:
        lines.append(f"  Could also be: {', '.join(entry.ambiguous_with)} (see below).")
    if entry.absorbs:
        lines.append(
            f"  A {' or '.join(entry.absorbs)} in the data would be merged into it on this profile (see below)."
        )
    if entry.flags:
        lines.append("  Note: " + "; ".join(entry.flags) + ".")
    if entry.advice:
        lines.append(f"  In practice: {entry.advice}.")
    return lines


def _percent(value: float | None) -> str:
    return str(None if value is None else round(value, 2))


def markdown(diagnosis: Diagnosis, files: dict[str, str] | None = None) -> str:
    d = diagnosis
    data = d.data
    lines = [
        f"# Physics mismatch report: {Path(d.source).name}",
        "",
        f"{data.full_t.size} rows at {data.fs:g} Hz, {data.duration_s:.0f} s; analysed as {data.n} "
        f"block means of {data.block_s:.3g} s. Starting model: {', '.join(d.baseline.identifiers)}.",
        "",
        *(
            [
                f"Channel {d.channel} in {UNIT_LABELS[d.unit]}: every amplitude is in {UNIT_LABELS[d.unit]} "
                f"(`{channel_param_name('amp_mg', d.unit)}`, ...), plausible up to the channel's cubic drift span"
                + (f" of {d.scale.drift_span:.4g} {UNIT_LABELS[d.unit]} over the run." if d.scale else "."),
                "",
            ]
            if d.label
            else []
        ),
        "Criterion: " + document.CRITERION + f"; an effect is added when the BIC drops by at least "
        f"{THRESHOLD:g}.",
        "",
        "## What was left out",
        "",
    ]
    if not d.left_out:
        lines.append("Nothing: the recording shows no structure beyond the calibrated simulation.")
    for entry in d.left_out:
        lines += _left_out_lines(entry, d)
    lines += ["", "## Ambiguous", ""]
    lines += [
        f"- {' vs '.join(a.effects)}{d.label}{_kind(a)}: {a.reason}"
        + (f"{moves_text(a, d.unit)}." if a.moves else "")
        for a in d.ambiguous
    ] or ["None."]
    lines += ["", "## Not identifiable from this temperature profile", ""]
    lines += [
        f"- {n.effect}{d.label}: {n.reason}."
        + (f" Test that would identify it: {n.recommended_test}." if n.recommended_test else "")
        for n in d.not_identifiable
    ] or ["None."]
    if d.undetected:
        lines += ["", "## Weakly identifiable, not named: the smallest size this run names", ""]
        lines += [_undetected_line(u, d.unit) for u in d.undetected]
    if d.suggestive:
        full = any(m.delta_bic >= THRESHOLD for m in d.suggestive)  # the search stopped at its limit
        heading = "strong evidence, not named" if full else "strong evidence, below the criterion (not named)"
        lines += ["", f"## Near misses: {heading}", ""]
        lines += [_near_miss_line(m, d) for m in d.suggestive]
    if d.not_supported:
        lines += ["", "## In the simulation but not supported by the data", ""]
        lines += [f"- {n.effect}{d.label}: {n.reason}" for n in d.not_supported]
    if flagged := d.implausible_baseline():
        lines += ["", "## In the simulation, calibrated outside the plausible range", ""]
        lines += [
            f"- {effect.identifier}{d.label}: {_fmt_params(d.params(effect.params))}; {'; '.join(flags)}."
            for effect, flags in flagged
        ]
    before, after = d.before, d.after
    u = d.signal.label
    lines += [
        "",
        f"## Fit before and after: {d.signal.heading}",
        "",
    ]
    rows = [
        [f"residual RMS, full rate ({u})", f"{before.rms_mg:.5f}", f"{after.rms_mg:.5f}"],
        [f"residual RMS, block means ({u})", f"{before.rms_block_mg:.5f}", f"{after.rms_block_mg:.5f}"],
        ["BIC", f"{before.bic:.1f}", f"{after.bic:.1f}"],
    ]
    rows += [
        [
            f"{b_seg.segment} {b_seg.t_start_s:.0f}..{b_seg.t_end_s:.0f} s, block RMS ({u})",
            f"{b_seg.rms_block_mg:.5f}",
            f"{a_seg.rms_block_mg:.5f}",
        ]
        for b_seg, a_seg in zip(before.per_segment, after.per_segment, strict=True)
    ]
    lines.append(markdown_table(["", "before", "after"], rows, align="lrr"))
    if d.holdout:
        h = d.holdout
        hb, ha = h.before, h.after
        lines += [
            "",
            f"Held-out check (both models fitted on 0..{h.train_t_end_s:.0f} s, scored on "
            f"{h.test_t_start_s:.0f}..{h.test_t_end_s:.0f} s): block RMS {hb.test_rms_block_mg_ols:.5f} -> "
            f"{ha.test_rms_block_mg_ols:.5f} {u} ({_percent(h.improvement_percent_ols)} % better), both "
            "refitted by least squares and extrapolated bare, as a compensator would be (the JSON also "
            "has the GLS forecast, which includes the noise model's prediction of the tail).",
        ]
        if h.note:
            lines.append(f"({h.note}.)")
    lines += ["", "## Where the starting model's residual is structured", ""]
    lines += [_region_line(r, d.unit) for r in d.mismatch] or ["Nowhere beyond the modelled noise."]
    lines += ["", "## Still unexplained after the additions", ""]
    lines += [_region_line(r, d.unit) for r in d.unexplained] or ["Nothing."]
    notes = d.notes + d.baseline.notes
    if notes:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in notes]
    if files:
        lines += ["", "## Files", ""] + [f"- `{name}`: {what}" for name, what in files.items()]
    lines += ["", *next_steps_lines(next_steps(d))]
    return "\n".join(lines) + "\n"


def value_text(x: float) -> str:
    """A fitted value as the report and the terminal print it: 4 significant digits, whole numbers from
    1000 up (a tau of 16982 s, not 1.698e+04: the JSON's figure, to the second)."""
    return f"{x:.0f}" if abs(x) >= 1000 else f"{x:.4g}"


def limit_sizes(u: DetectionLimit) -> str:
    """``1.33 at 60, 2.06 at 140.4, ... (tau_s)``: the smallest amplitude named along the time
    constant (the report's and the terminal's one wording)."""
    return (
        ", ".join(
            f"{'> ' if lim.at_least else ''}{lim.amplitude:.3g} at {value_text(lim.nl_value)}"
            for lim in u.limits
        )
        + f" ({u.nl_name})"
    )


def _near_miss_line(m: Suggestive, d: Diagnosis) -> str:
    """One near miss: what it is, its evidence against the criterion, and that it is not used."""
    added = "the final model" + (
        f" together with the {m.joint - 1} other instance{'s' if m.joint > 2 else ''} placed jointly with it"
        if m.joint > 1
        else ""
    )
    verdict = (
        f"{added}, which already holds the {MAX_ADDED} effects the search adds: above the criterion "
        f"({THRESHOLD:g}), not named."
        if m.delta_bic >= THRESHOLD
        else f"{added} ({SUGGESTIVE:g} is strong evidence, the criterion needs {THRESHOLD:g}): "
        + (
            f"{shared}."
            if (shared := shared_text(m.shares))
            else "a spurious component is possible at this evidence, and no single named effect takes "
            "its place (without any one of them it still earns less than the criterion)."
        )
    )
    note = f" Note: {'; '.join(m.flags)}." if m.flags else ""
    return (
        f"- {m.effect}{d.label}: {_fmt_params(d.params(m.params))}. BIC -{m.delta_bic:.1f} when added to "
        f"{verdict} Not in the compensator.{note}"
    )


def _undetected_line(u: DetectionLimit, unit: str) -> str:
    """One weakly identifiable effect: the amplitude the criterion needs along its time constant."""
    amp = channel_param_name(u.amp_name, unit)
    absorbed = [100 * lim.absorbed for lim in u.limits]
    beyond = [lim.nl_value for lim in u.limits if lim.amplitude > u.plausible_amp[1]]
    out = (
        f"- {u.effect}: {u.reason}. Named from `{amp}` = {limit_sizes(u)}; weighted by the fitted "
        f"noise, {min(absorbed):.0f}..{max(absorbed):.0f} % of its shape is taken by the model's other "
        "columns (the temperature polynomial and the terms found). A smaller one can be present unseen."
    )
    if beyond:
        where = (
            value_text(beyond[0])
            if len(beyond) == 1
            else f"{value_text(min(beyond))}..{value_text(max(beyond))}"
        )
        out += (
            f" Beyond the catalogue's plausible {u.plausible_amp[1]:g} at `{u.nl_name}` {where}: not "
            "identifiable there at a plausible size."
        )
    return out + (f" Test that would identify it: {u.recommended_test}." if u.recommended_test else "")


def _region_line(r: Region, unit: str) -> str:
    """A region's line, its statistics named in the channel's unit (``mean_residual_dps``) as in the JSON."""
    sig = ", ".join(
        f"{channel_param_name(k, unit)} {v}" for k, v in document.significance(r.significance).items()
    )
    note = f" {r.note}." if r.note else ""
    return (
        f"- {r.kind}: {r.t_start_s:.0f}..{r.t_end_s:.0f} s ({r.segment}, {r.branch}, "
        f"{r.temp_min_c:.1f}..{r.temp_max_c:.1f} degC), {sig}.{note}"
    )


# ------------------------------------------------------------------------------------ plots


def _scatter_by_branch(ax: Any, x: np.ndarray, y: np.ndarray, branch: np.ndarray) -> None:
    for code, (colour, label) in BRANCH_COLOURS.items():
        mask = branch == code
        if np.any(mask):
            ax.plot(x[mask], y[mask], ".", ms=2.5, color=colour, label=label)


def plot_residuals(diagnosis: Diagnosis, directory: Path) -> dict[str, str]:
    """Residual over time and over temperature, before and after, branches coloured."""
    data, profile = diagnosis.data, diagnosis.profile
    signal = diagnosis.signal
    t_min = data.t / 60.0
    temp = data.temperature(True)
    pairs = (("before", diagnosis.before.residual_block), ("after", diagnosis.after.residual_block))
    files = {}
    fig = new_figure((11, 6.5), 110)
    axes = fig.subplots(2, 1, sharex=True, sharey=True)
    for ax, (name, res) in zip(axes, pairs, strict=True):
        _scatter_by_branch(ax, t_min, res, profile.branch)
        for entry in diagnosis.left_out:
            for w in entry.where:
                if isinstance(w, Region) and name == "before":
                    ax.axvspan(w.t_start_s / 60.0, w.t_end_s / 60.0, color="gold", alpha=0.15)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_ylabel(signal.axis(f"residual {name}"))
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize=7, markerscale=3)
    axes[-1].set_xlabel("time (min)")
    found = ", ".join(e.effect for e in diagnosis.left_out) or "nothing"
    axes[0].set_title(signal.title(f"block-mean residual ({data.block_s:.3g} s blocks); added: {found}"))
    fig.tight_layout()
    save_figure(fig, directory / "residual_time.png")
    files["residual_time.png"] = "block-mean residual over time, before and after (found regions shaded)"
    fig = new_figure((11, 4.5), 110)
    axes = fig.subplots(1, 2, sharey=True)
    for ax, (name, res) in zip(axes, pairs, strict=True):
        _scatter_by_branch(ax, temp, res, profile.branch)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel("temperature (degC)")
        ax.set_title(f"residual {name}")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize=7, markerscale=3)
    axes[0].set_ylabel(signal.axis("block-mean residual"))
    fig.suptitle(signal.title("residual over temperature"))
    fig.tight_layout()
    save_figure(fig, directory / "residual_temperature.png")
    files["residual_temperature.png"] = "residual over temperature, heating red, cooling blue, holds grey"
    fig = new_figure((7.5, 5), 110)
    ax = fig.subplots()
    for name, summary, colour in (
        ("before", diagnosis.before, "tab:orange"),
        ("after", diagnosis.after, "tab:green"),
    ):
        a = summary.allan
        ax.errorbar(
            a.taus_s, a.adev, yerr=a.adev_err, fmt="o-", ms=3, lw=1, color=colour, label=f"residual {name}"
        )
        ax.loglog(a.taus_s, a.model, "--", color=colour, lw=1, label=f"modelled noise ({name})")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("tau (s)")
    ax.set_ylabel(signal.axis("Allan deviation"))
    ax.set_title(signal.title("Allan deviation of the residual"))
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, directory / "allan.png")
    files["allan.png"] = "Allan deviation of the residual before/after against the modelled noise"
    return files


# ------------------------------------------------------------------------------------ directory


def check_report_target(directory: str | os.PathLike[str]) -> tuple[Path, Path]:
    """(directory, its parent) when :func:`write_report` may write there: a new directory, an empty
    one or an earlier diagnosis report (``trainer diagnose`` asks before its analysis, not after)."""
    target = Path(directory)
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.is_dir():
        raise UserError(f"{target}: parent directory {parent} does not exist")
    if target.exists() and not target.is_dir():
        raise UserError(f"{target}: exists and is not a directory")
    if target.is_dir() and any(target.iterdir()) and not (target / REPORT_MARKER).is_file():
        raise UserError(
            f"{target}: directory exists and is not an earlier diagnosis report; choose another --report"
        )
    return target, parent


def write_report(diagnosis: Diagnosis, directory: str | os.PathLike[str]) -> None:
    """Write the report directory atomically (build beside it, then rename into place).

    An existing directory is replaced only if it is an earlier diagnosis report (it holds
    ``diagnosis.json``) or empty; anything else is refused so a typo cannot delete user files.
    """
    target, parent = check_report_target(directory)
    staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".part", dir=parent))
    try:
        files = {"diagnosis.json": "the machine-readable result (same as --json)"}
        (staging / "diagnosis.json").write_text(json_text(diagnosis), encoding="utf-8")
        (staging / "augmented.toml").write_text(config_to_toml(diagnosis.augmented), encoding="utf-8")
        files["augmented.toml"] = (
            "the simulation with the fitted and found effects: `trainer simulate --config augmented.toml`"
        )
        files.update(plot_residuals(diagnosis, staging))
        (staging / "report.md").write_text(markdown(diagnosis, files), encoding="utf-8")
        os.chmod(staging, 0o755)
        if target.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".old", dir=parent))
            os.rename(target, old / "report")
            os.rename(staging, target)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.rename(staging, target)
    except BaseException as exc:
        shutil.rmtree(staging, ignore_errors=True)
        raise_write_error(exc, target)
        raise
