"""``OUTDIR/report.md``, its figures and ``OUTDIR/fleet.json``: the fleet as a production engineer reads it.

Sections: the sign-off table (one row per unit, the verdict of ``trainer report``,
:func:`trainer.scoring.verdict.verdict`: FAIL when a stage failed, an export did not verify or a
method leaves more drift than no compensation on the scored data, REVIEW when out of family, when a
model carries a parameter its run does not determine or when a unit is scored entirely outside its
trained range),
the failed units with their one-line errors, the exports that
failed to verify, the out-of-family units with the reason, the effects the finder named and how
often, and the distributions of each method's drift left and of every fitted physical parameter.
The report holds no wall times, so identical runs write identical reports.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from trainer.data.channels import ONE_AXIS_CHANNEL
from trainer.errors import atomic_output
from trainer.fleet.manifest import Manifest
from trainer.fleet.outliers import (
    COMMON_SHARE,
    DRIFT_PREFIX,
    MIN_UNITS,
    RARE_SHARE,
    Z_LIMIT,
    Finding,
    drift_feature,
    find_out_of_family,
    named_effects,
    unit_features,
    unit_label,
)
from trainer.fleet.result import Failure, UnitResult, json_bytes
from trainer.fleet.stages import DRIFT_LEFT_KEYS, SMOOTHING_S
from trainer.scoring.markdown import markdown_table
from trainer.scoring.plots import new_figure, save_figure
from trainer.scoring.verdict import (
    FAIL,
    PASS,
    REVIEW,
    Figures,
    Verdict,
    outside_trained_range,
    undetermined_reason,
    verdict,
)
from trainer.stale_files import remove_stale_parts, report_removed

FIGURES_DIR = "figures"


def remove_stale_report_parts(out_dir: Path) -> None:
    """Remove the temporary report, summary and figure files a killed run left (their writer is
    gone): a restart may not write the same figures, so they are not left for it to replace."""
    for folder in (out_dir, out_dir / FIGURES_DIR):
        report_removed(folder, remove_stale_parts(folder))


def verify_state(summary: dict[str, Any]) -> str:
    """``yes`` (0 mismatches), ``NO`` (mismatches or export error), ``n/a`` (no code generator), ``-`` (no fit)."""
    verify = summary.get("verify")
    if not isinstance(verify, dict):
        return "-"
    passed = verify.get("passed")
    return "n/a" if passed is None else ("yes" if passed else "NO")


@dataclass(frozen=True)
class PipelineCheck:
    """A stage of the unit's pipeline (processing, a module's verification): passed or not."""

    name: str
    ok: bool
    decisive: bool = True


def _figures(summary: dict[str, Any], basis: str, unit: str) -> Figures | None:
    """A method's figures from ``result.json``, in the unit's channel unit (None: not scored)."""
    values = [summary.get(k) for k in DRIFT_LEFT_KEYS]
    if not isinstance(values[0], int | float):
        return None
    model, raw, model_in, raw_in, floor = (
        float(v) if isinstance(v, int | float) else math.nan for v in values
    )
    return Figures(basis, model, raw, model_in, raw_in, floor, unit)


def unit_verdict(uid: str, result: UnitResult | None, findings: list[Finding]) -> Verdict:
    """The unit's verdict: processed, every export verified, every method better than uncompensated
    on the scored data (the guard of ``trainer report``); out of family asks for REVIEW."""
    if result is None:
        return verdict({}, [PipelineCheck(f"{uid}: no result", False)])
    checks = [PipelineCheck(f"{uid} {e.stage}: {e.error}", False) for e in result.errors]
    if not checks:  # a stage's failure above says what failed; this check only when none did
        checks.append(PipelineCheck(f"{uid} processed", result.ok))
    methods = result.methods
    checks += [
        PipelineCheck(f"{uid} / {m} C module verified", verify_state(s) != "NO") for m, s in methods.items()
    ]
    figures = {
        f"{uid} / {m}": f
        for m, s in methods.items()
        if (f := _figures(s, result.evaluated_on or "scored part", unit_label(result))) is not None
    }
    undetermined = [
        reason
        for m, s in methods.items()
        if (reason := undetermined_reason(f"{uid} / {m}", s.get("undetermined", [])))
    ]
    outside = [
        reason
        for m, s in methods.items()
        if isinstance(s.get("coverage"), int | float)
        and (reason := outside_trained_range(f"{uid} / {m}", float(s["coverage"])))
    ]
    return verdict(figures, checks, [*undetermined, *outside, *(f.reason for f in findings)])


def _mg(value: Any, unit: str = "") -> str:
    return f"{value:.4g}{unit}" if isinstance(value, int | float) else "-"


def _channel(result: UnitResult | None) -> str:
    """``gyro0_z (deg/s)``: the unit's channel and unit (results written before they were kept: mg)."""
    if result is None or (not result.channel and not result.ok):
        return "-"  # failed before its recording was read
    return f"{result.channel or ONE_AXIS_CHANNEL} ({unit_label(result)})"


def unit_coverage(result: UnitResult | None) -> tuple[float, list[float], list[float]] | None:
    """(coverage, scored range, trained range) of a unit's scored part: the smallest coverage of its
    methods (all are fitted on the same run), or None when no method was scored."""
    found = [
        (float(s["coverage"]), list(s["scored_range_c"]), list(s["trained_range_c"]))
        for s in (result.methods if result is not None else {}).values()
        if isinstance(s, dict) and isinstance(s.get("coverage"), int | float)
    ]
    return min(found, key=lambda item: item[0]) if found else None


def _coverage_cell(result: UnitResult | None) -> str:
    covered = unit_coverage(result)
    return "-" if covered is None else f"{100 * covered[0]:.0f} %"


def _coverage_lines(units: list[str], results: dict[str, UnitResult]) -> list[str]:
    """The units scored partly outside their trained range: a PASS there includes extrapolation."""
    lines = ["## Coverage", ""]
    partial = []
    for u in units:
        covered = unit_coverage(results.get(u))
        if covered is not None and covered[0] < 1.0:
            share, (s_lo, s_hi), (t_lo, t_hi) = covered
            partial.append(
                f"- **{u}**: scored {s_lo:.2f} .. {s_hi:.2f} degC, trained {t_lo:.2f} .. {t_hi:.2f} degC: "
                f"{100 * share:.1f} % of the scored span inside the trained range; outside it the model "
                "extrapolates (or holds its end value), which its drift left includes"
            )
    lines += [
        "`scored in trained range`: the share of the scored part's temperature span inside the range the "
        "unit was trained on (`trainer report`'s coverage). A sign-off is only as good as that share: "
        "outside it, nothing was calibrated.",
        "",
        *(partial or ["Every scored part lies inside its unit's trained range."]),
        "",
    ]
    return lines


def strip_plot(
    path: Path, columns: list[tuple[str, dict[str, float]]], flagged: set[str], title: str, units: list[str]
) -> Path:
    """One panel per column (a feature): every unit a dot at its own x position, labelled with its id
    on the x axis (manifest order), out-of-family units in red and named beside their dot, median line."""
    count = max(1, len(columns))
    per_row = min(4, count)
    rows = (count + per_row - 1) // per_row
    width = max(3.2, 0.14 * len(units) + 0.8)  # room for one id label per unit
    figure = new_figure((width * per_row, 3.2 * rows), dpi=100)
    axes = figure.subplots(rows, per_row, squeeze=False)
    label_size = 7 if len(units) <= 30 else 5
    for index, ax in enumerate(axes.flat):
        if index >= len(columns):
            ax.set_visible(False)
            continue
        name, values = columns[index]
        shown = [u for u in units if u in values]
        x = np.array([units.index(u) for u in shown], dtype=float)
        y = np.array([values[u] for u in shown])
        colours = ["tab:red" if u in flagged else "tab:blue" for u in shown]
        ax.scatter(x, y, c=colours, s=14)
        ax.axhline(float(np.median(y)), color="grey", lw=0.8, label="fleet median")
        for xi, yi, u in zip(x, y, shown, strict=True):
            if u in flagged:
                ax.annotate(
                    u, (xi, yi), fontsize=7, color="tab:red", xytext=(4, 0), textcoords="offset points"
                )
        ax.set_xlim(-0.8, len(units) - 0.2)
        ax.set_xticks(range(len(units)), units, rotation=90, fontsize=label_size)
        ax.set_xlabel("unit", fontsize=7)
        ax.set_title(name, fontsize=8)
        ax.tick_params(axis="y", labelsize=7)
    figure.suptitle(f"{title} (red: out of family)", fontsize=10)
    figure.tight_layout()
    return save_figure(figure, path)


def _effects_plot(path: Path, counts: Counter[str], n: int) -> Path:
    figure = new_figure((6.0, 0.5 + 0.35 * max(1, len(counts))), dpi=100)
    ax = figure.add_subplot()
    names = sorted(counts, key=lambda e: (-counts[e], e))
    ax.barh(names[::-1], [counts[e] for e in names[::-1]], color="tab:blue")
    ax.set_xlim(0, max(1, n))
    ax.set_xlabel(f"units where the finder names the effect (of {n})")
    figure.tight_layout()
    return save_figure(figure, path)


def _distribution_rows(columns: list[tuple[str, dict[str, float]]]) -> list[list[str]]:
    rows = []
    for name, values in columns:
        y = np.array(list(values.values()))
        p10, p50, p90 = np.percentile(y, [10, 50, 90])
        rows.append(
            [name, str(y.size), f"{p50:.4g}", f"{p10:.4g}", f"{p90:.4g}", f"{y.min():.4g}", f"{y.max():.4g}"]
        )
    return rows


def write_report(manifest: Manifest, out_dir: Path, results: dict[str, UnitResult]) -> Path:
    """Write ``report.md``, ``figures/*.png`` and ``fleet.json``; returns the report's path."""
    units = [u.id for u in manifest.units]
    methods = list(dict.fromkeys(m for u in manifest.units for m in u.methods))
    findings = find_out_of_family({u: results[u] for u in units if u in results})
    by_unit: dict[str, list[Finding]] = {u: [f for f in findings if f.unit == u] for u in units}
    decided = {u: unit_verdict(u, results.get(u), by_unit[u]) for u in units}
    verdicts = {u: v.status for u, v in decided.items()}
    ok = [u for u in units if u in results and results[u].ok]
    flagged = {f.unit for f in findings}

    features = {u: unit_features(results[u]) for u in ok}
    labels = list(dict.fromkeys(unit_label(results[u]) for u in ok)) or ["mg"]
    drift_names = [drift_feature(m, label) for m in methods for label in labels]
    drift_columns = [(n, {u: features[u][n] for u in ok if n in features[u]}) for n in drift_names]
    drift_columns = [(n, v) for n, v in drift_columns if v]
    parameter_names = sorted({n for f in features.values() for n in f if not n.startswith(DRIFT_PREFIX)})
    parameter_columns = [(n, {u: features[u][n] for u in ok if n in features[u]}) for n in parameter_names]
    counts: Counter[str] = Counter(e for u in ok for e in named_effects(results[u]))

    figures_dir = out_dir / FIGURES_DIR
    figures_dir.mkdir(exist_ok=True)
    figures = []
    if drift_columns:
        figures.append(
            strip_plot(figures_dir / "drift_left.png", drift_columns, flagged, "Drift left per method", ok)
        )
    if parameter_columns:
        figures.append(
            strip_plot(
                figures_dir / "parameters.png",
                parameter_columns,
                flagged,
                "Fitted physical parameters",
                ok,
            )
        )
    if counts:
        figures.append(_effects_plot(figures_dir / "effects.png", counts, len(ok)))

    tally = Counter(verdicts.values())
    lines = [
        f"# Fleet report: {manifest.source.name}",
        "",
        f"{len(units)} units; {len(ok)} processed without error; sign-off: {tally[PASS]} PASS, "
        f"{tally[REVIEW]} REVIEW (out of family, a parameter its run does not determine, or scored "
        f"entirely outside the trained range), {tally[FAIL]} FAIL (a stage failed, an export did not "
        "verify or a method leaves more drift than no compensation).",
        f"Methods: {', '.join(methods)}. Drift left: RMS of the compensated output (smoothed over "
        f"{SMOOTHING_S:g} s) about one constant, scored on each unit's second run or its held-out part "
        f"(holdout {manifest.settings.holdout}), exactly as `trainer report` scores the same model, "
        "recording and hold-out; beside it the uncompensated output's.",
        "",
        "## Sign-off",
        "",
    ]
    # one unit for every figure of the table when the fleet is of one kind of channel, else per cell
    common = f" ({labels[0]})" if len(labels) == 1 else ""
    header = ["unit", "sign-off", "channel", "scored in trained range", "effects named"]
    header += [f"drift left {m}{common}" for m in methods] + [f"drift left uncompensated{common}"]
    header += [f"C verified {m}" for m in methods] + ["failed", "review"]
    rows = []
    for u in units:
        result = results.get(u)
        summaries = result.methods if result is not None else {}
        cell_unit = "" if common or result is None else f" {unit_label(result)}"
        row = [u, verdicts[u], _channel(result), _coverage_cell(result)]
        row.append(", ".join(named_effects(result)) if result is not None else "-")
        row += [_mg(summaries.get(m, {}).get("drift_left_mg"), cell_unit) for m in methods]
        raw = [s.get("drift_left_uncompensated_mg") for s in summaries.values() if isinstance(s, dict)]
        row.append(_mg(next((v for v in raw if v is not None), None), cell_unit))
        row += [verify_state(summaries.get(m, {})) for m in methods]
        row.append("; ".join(decided[u].failed) or "-")
        row.append("; ".join(decided[u].review) or ("-" if u in ok else "n/a (failed)"))
        rows.append(row)
    lines += [markdown_table(header, rows), ""]
    lines += _coverage_lines(units, results)

    failed = [u for u in units if u not in results or not results[u].ok]
    lines += ["## Failed units", ""]
    if failed:
        for u in failed:
            errors = results[u].errors if u in results else (Failure("-", "no result", False),)
            lines += [f"- **{u}** ({e.stage}): {e.error}" for e in errors]
    else:
        lines.append("None.")
    lines += ["", "## Exports that failed to verify", ""]
    unverified = [
        (u, m, results[u].methods[m]["verify"])
        for u in units
        if u in results
        for m in results[u].methods
        if verify_state(results[u].methods[m]) == "NO"
    ]
    if unverified:
        for u, m, v in unverified:
            detail = (
                v.get("error")
                or f"{v.get('mismatches')} mismatches, final state identical: {v.get('state_equal')}"
            )
            lines.append(f"- **{u}** {m}: {detail}")
    else:
        lines.append("None: every exported C module equals its golden model bit for bit (0 mismatches).")
    lines += [
        "",
        "## Out-of-family units",
        "",
        f"Robust z-score (median and 1.4826 MAD over the {len(ok)} processed units) beyond {Z_LIMIT:g} on a "
        f"fitted parameter or a drift left, or an effect that at most {100 * RARE_SHARE:g} % of the units show "
        f"(or a missing one that at least {100 * COMMON_SHARE:g} % show).",
        "",
    ]
    if len(ok) < MIN_UNITS:
        lines.append(f"Not assessed: {len(ok)} processed units are too few ({MIN_UNITS} needed).")
    elif findings:
        lines.append(markdown_table(["unit", "reason"], [[f.unit, f.reason] for f in findings]))
    else:
        lines.append("None.")
    lines += ["", "## Effects the finder names", ""]
    if counts:
        lines.append(
            markdown_table(
                ["effect", "units", "share (%)"],
                [
                    [e, str(c), f"{100 * c / len(ok):.0f}"]
                    for e, c in sorted(counts.items(), key=lambda x: (-x[1], x[0]))
                ],
                align="lrr",
            )
        )
        lines += ["", f"![effects]({FIGURES_DIR}/effects.png)"]
    else:
        lines.append("None beyond the simulation the finder started from.")
    distribution_header = ["quantity", "units", "median", "p10", "p90", "min", "max"]
    for title, columns, figure in (
        ("Drift left per method", drift_columns, "drift_left.png"),
        ("Fitted physical parameters", parameter_columns, "parameters.png"),
    ):
        lines += ["", f"## {title}", ""]
        if columns:
            lines += [
                markdown_table(distribution_header, _distribution_rows(columns), align="lrrrrrr"),
                "",
                f"![{title}]({FIGURES_DIR}/{figure})",
            ]
        else:
            lines.append("No processed unit.")
    lines.append("")

    with atomic_output(out_dir / "report.md") as tmp:
        tmp.write_text("\n".join(lines), encoding="utf-8")
    summary = {
        "manifest": str(manifest.source),
        "units": [
            {
                "id": u,
                "sign_off": verdicts[u],
                "status": results[u].status if u in results else "missing",
                "out_of_family": [f.reason for f in by_unit[u]],
                "failed": list(decided[u].failed),
                "review": list(decided[u].review),
                "channel": results[u].channel if u in results else None,
                "unit": results[u].unit if u in results else None,
                "coverage": None if (covered := unit_coverage(results.get(u))) is None else covered[0],
                "errors": [e.error for e in results[u].errors] if u in results else [],
            }
            for u in units
        ],
    }
    with atomic_output(out_dir / "fleet.json") as tmp:
        tmp.write_bytes(json_bytes(summary))
    return out_dir / "report.md"
