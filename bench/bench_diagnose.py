"""Benchmark of ``trainer diagnose``: identification accuracy, false findings, parameter errors, speed.

Generates concealed-effect draws with :mod:`trainer.diagnose.scenarios` (varied seeds, protocols,
ramp rates, sample rates, noise levels and parameter draws): every catalogue effect of the
finder's test list alone, pairs of effects (the pairs real runs show together first), and clean
recordings. Every draw is diagnosed both ways (``--sim-modes``): with the user's simulation (the
truth without the concealed effects) and with no ``--sim`` at all. Per effect and for pairs it
scores:

* named: every concealed effect is named in ``left_out``;
* false findings: anything named that was not concealed, noise terms included (clean: any name);
* parameter errors: relative error of the checked time constants and amplitudes (25 % target);
* held-out improvement: block RMS on the last quarter, least-squares refit extrapolated bare
  (the report's one held-out figure), before versus after the named effects;
* run time per case, and one diagnosis of a 2 h, 200 Hz paper-oven recording (under a minute).

    python bench/bench_diagnose.py                        # 100 draws x 2 ways + timing, 2 processes
    python bench/bench_diagnose.py --quick                # 20 draws x 2 ways, no 200 Hz timing
    python bench/bench_diagnose.py --sim-modes truth --json out.json
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from typing import Any

import numpy as np

from trainer.commands.diagnose_cmd import every_output
from trainer.diagnose import diagnose
from trainer.diagnose.document import document
from trainer.diagnose.scenarios import CHECKED_PARAMS, HIDDEN_EFFECTS, make_scenario
from trainer.physics.catalogue import rate_random_walk
from trainer.physics.config import PhysicsConfig

RANDOM_WALK = rate_random_walk.DEFINITION.identifier
# How the user's simulation is handed to the finder: ``truth`` (the truth minus the concealed
# effects), ``no-rrw`` (as a user would write it: bias polynomial, white noise and bias instability
# but no random walk; the recordings are then generated without a random walk too), ``none`` (no
# ``--sim``: the finder's default physics, which includes a random walk, as the starting model).
SIM_MODES = ("truth", "no-rrw", "none")
DEFAULT_SIM_MODES = ("truth", "none")


def without_random_walk(config: PhysicsConfig) -> PhysicsConfig:
    return replace(config, noise=tuple(n for n in config.noise if n.identifier != RANDOM_WALK))


# The pairs real runs show together first (lag with rate, hysteresis with lag, a step with a
# quantised thermometer, warm-up with anything), then other combinations.
PAIRS: tuple[tuple[str, str], ...] = (
    ("thermal_lag", "temp_rate"),
    ("hysteresis", "thermal_lag"),
    ("bias_step", "temp_quantization"),
    ("warmup", "thermal_lag"),
    ("warmup", "hysteresis"),
    ("warmup", "bias_step"),
    ("thermal_lag", "periodic"),
    ("stress_relaxation", "periodic"),
    ("thermal_lag", "temp_quantization"),
)


def concealable(effect: str, sim_mode: str) -> bool:
    """Whether ``effect`` can be concealed from the finder's starting model in ``sim_mode``.

    Without ``--sim`` the default physics already has a random walk, and in ``no-rrw`` the
    recordings have none: either way there is no random walk to conceal.
    """
    return not (effect == RANDOM_WALK and sim_mode in ("no-rrw", "none"))


def draw_list(per_effect: int, clean: int, pairs: int, offset: int) -> list[tuple[tuple[str, ...], int]]:
    """The draws: (concealed effects, seed); every seed is used once."""
    draws: list[tuple[tuple[str, ...], int]] = []
    seed = 1000 + offset
    for effect in HIDDEN_EFFECTS:
        for _ in range(per_effect):
            draws.append(((effect,), seed))
            seed += 1
    for k in range(pairs):
        draws.append((PAIRS[k % len(PAIRS)], seed))
        seed += 1
    for _ in range(clean):
        draws.append(((), seed))
        seed += 1
    return draws


def case_list(
    draws: list[tuple[tuple[str, ...], int]], sim_modes: tuple[str, ...]
) -> list[tuple[tuple[str, ...], int, str]]:
    """Every draw diagnosed each way it can be (see :func:`concealable`)."""
    return [
        (effects, seed, mode)
        for effects, seed in draws
        for mode in sim_modes
        if all(concealable(e, mode) for e in effects)
    ]


def relative_errors(hidden: list[dict[str, Any]], found: list[dict[str, Any]]) -> dict[str, float]:
    out: dict[str, float] = {}
    for h in hidden:
        matches = [f for f in found if f["effect"] == h["effect"]]
        if not matches:
            continue
        for name in CHECKED_PARAMS[h["effect"]]:
            true = h["params"][name]
            best = min(abs(m["params"].get(name, math.inf) - true) / abs(true) for m in matches)
            out[f"{h['effect']}.{name}"] = best
    return out


def run_case(effects: tuple[str, ...], seed: int, sim_mode: str = "truth") -> dict[str, Any]:
    scenario = make_scenario(list(effects), seed, rates=(5.0, 10.0, 20.0, 50.0))
    sim: PhysicsConfig | None = scenario.sim
    if sim_mode == "no-rrw":
        scenario = replace(scenario, truth=without_random_walk(scenario.truth))
        sim = without_random_walk(scenario.sim)
    elif sim_mode == "none":
        sim = None
    rec = scenario.recording()
    started = time.perf_counter()
    result = diagnose(rec, sim)
    seconds = time.perf_counter() - started
    every_output(result)  # a finding an output cannot take fails here
    doc = document(result)
    hidden = [{"effect": h.identifier, "params": dict(h.params)} for h in scenario.hidden]
    found = [{"effect": e["effect"], "params": e["params"]} for e in doc["left_out"]]
    names = {f["effect"] for f in found}
    holdout = doc["holdout"]
    return {
        "case": scenario.name,
        "seed": seed,
        "sim_mode": sim_mode,
        "effects": list(effects),
        "rate_hz": scenario.truth.recording.sample_rate_hz,
        "rows": len(rec),
        "identified": all(h["effect"] in names for h in hidden),
        "missed": [h["effect"] for h in hidden if h["effect"] not in names],
        "extra": sorted(names - {h["effect"] for h in hidden}),
        "ambiguous": [a["effects"] for a in doc["ambiguous"]],
        "errors": relative_errors(hidden, found),
        "bic_before": doc["fit"]["before"]["bic"],
        "bic_after": doc["fit"]["after"]["bic"],
        "holdout_improvement_percent": None if holdout is None else holdout.get("improvement_percent_ols"),
        "seconds": seconds,
    }


def identifiability_control(effects: tuple[str, ...], seed: int) -> dict[str, Any]:
    """Whether each effect of a pair draw is identifiable from the profile.

    For every concealed effect the same recording is diagnosed with the *other* concealed effects
    handed over in the user's simulation (their true parameters). An effect the finder cannot
    name even then is not identifiable in this draw: the concealment noise set by its partner,
    or the partner's physics (a long lag filters a quantised thermometer's staircase away), hides
    it. Pairs are scored on the draws where both effects pass this control.
    """
    scenario = make_scenario(list(effects), seed, rates=(5.0, 10.0, 20.0, 50.0))
    rec = scenario.recording()
    order = [e.identifier for e in scenario.truth.effects]
    out: dict[str, bool] = {}
    for effect in effects:
        known = [h for h in scenario.hidden if h.identifier != effect and h.identifier in order]
        sim = replace(
            scenario.sim,
            effects=tuple(sorted((*scenario.sim.effects, *known), key=lambda e: order.index(e.identifier))),
        )
        doc = document(diagnose(rec, sim, holdout_fraction=0.0))
        out[effect] = effect in {e["effect"] for e in doc["left_out"]}
    return {"seed": seed, "effects": list(effects), "identifiable": out}


def timing_2h_200hz() -> dict[str, Any]:
    """One diagnosis of the paper's recording size: 2 h at 200 Hz (1.44 M rows), default physics."""
    from trainer.physics.config import load_config
    from trainer.physics.effects import EffectConfig
    from trainer.physics.simulate import simulate

    cfg = load_config(None)
    truth = replace(
        cfg,
        effects=(
            *cfg.effects,
            EffectConfig("periodic", {"amp_mg": 0.05, "period_s": 300.0, "phase_rad": 0.0}),
        ),
    )
    rec = simulate(truth, 7)
    started = time.perf_counter()
    result = diagnose(rec, cfg)
    seconds = time.perf_counter() - started
    return {
        "rows": len(rec),
        "seconds": round(seconds, 2),
        "found": [e["effect"] for e in document(result)["left_out"]],
    }


def _group_summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Named, false findings, parameter errors, held-out improvement of one group of cases."""
    errs = [v for r in rows for v in r["errors"].values()]
    gains = [r["holdout_improvement_percent"] for r in rows if r["holdout_improvement_percent"] is not None]
    return {
        "cases": len(rows),
        "named": sum(r["identified"] for r in rows),
        "with_false_finding": sum(bool(r["extra"]) for r in rows),
        "params_within_25pct": f"{sum(e <= 0.25 for e in errs)}/{len(errs)}",
        "param_err_median": float(np.median(errs)) if errs else None,
        "param_err_max": float(np.max(errs)) if errs else None,
        "holdout_improvement_percent_median": float(np.median(gains)) if gains else None,
        "seconds_median": float(np.median([r["seconds"] for r in rows])) if rows else None,
    }


def summarise(results: list[dict[str, Any]]) -> dict[str, Any]:
    """One way of running the finder (one ``sim_mode``): per effect, pairs, singles, clean, in all."""
    singles = [r for r in results if len(r["effects"]) == 1]
    pair_rows = [r for r in results if len(r["effects"]) > 1]
    clean_rows = [r for r in results if not r["effects"]]
    effect_rows = singles + pair_rows
    groups = {
        effect: _group_summary([r for r in singles if r["effects"] == [effect]])
        for effect in HIDDEN_EFFECTS
        if any(r["effects"] == [effect] for r in singles)
    }
    groups["pairs"] = _group_summary(pair_rows)
    # Pairs where the control found both effects identifiable (see identifiability_control).
    both = [r for r in pair_rows if all(r.get("identifiable", {}).values())]
    groups["pairs, both identifiable"] = _group_summary(both)
    groups["clean"] = _group_summary(clean_rows)

    def fraction(k: int, n: int) -> str:
        return f"{k}/{n} ({100.0 * k / n:.1f} %)" if n else "0/0"

    return {
        "cases": len(results),
        "singles_named": fraction(sum(r["identified"] for r in singles), len(singles)),
        "pairs_named": fraction(sum(r["identified"] for r in pair_rows), len(pair_rows)),
        "pairs_named_where_both_identifiable": fraction(sum(r["identified"] for r in both), len(both)),
        "clean_with_finding": fraction(sum(bool(r["extra"]) for r in clean_rows), len(clean_rows)),
        "effect_cases_without_extra": fraction(sum(not r["extra"] for r in effect_rows), len(effect_rows)),
        "per_group": groups,
    }


def markdown(summaries: dict[str, dict[str, Any]]) -> str:
    """The per-group table of every way the finder ran, for the docs and the closing note."""
    lines = [
        "| way | group | cases | named | false findings | params within 25 % | held-out gain (median %) |",
        "|---|---|---|---|---|---|---|",
    ]
    for mode, summary in summaries.items():
        for group, g in summary["per_group"].items():
            gain = g["holdout_improvement_percent_median"]
            named = "-" if group == "clean" else str(g["named"])
            lines.append(
                f"| {mode} | {group} | {g['cases']} | {named} | {g['with_false_finding']} | "
                f"{g['params_within_25pct']} | {'-' if gain is None else f'{gain:.1f}'} |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--per-effect", type=int, default=7, help="draws per concealed effect")
    parser.add_argument("--clean", type=int, default=19, help="draws with nothing concealed")
    parser.add_argument("--pairs", type=int, default=18, help="draws with two concealed effects")
    parser.add_argument("--offset", type=int, default=0, help="shift all draw seeds (fresh draws)")
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument("--quick", action="store_true", help="1 draw per effect, 6 clean, 5 pairs, no timing")
    parser.add_argument("--no-timing", action="store_true")
    parser.add_argument("--json", help="write all results here")
    parser.add_argument(
        "--sim-modes",
        default=",".join(DEFAULT_SIM_MODES),
        help=f"comma-separated ways to run every draw, of {', '.join(SIM_MODES)}: the user's simulation "
        "is the truth minus the concealed effects (truth), the same without a random walk, recordings "
        "without one too (no-rrw), or no --sim at all (none); default: %(default)s",
    )
    args = parser.parse_args(argv)
    modes = tuple(m.strip() for m in args.sim_modes.split(",") if m.strip())
    unknown = [m for m in modes if m not in SIM_MODES]
    if unknown or not modes:
        parser.error(f"--sim-modes: unknown way(s) {unknown}; choose from {', '.join(SIM_MODES)}")
    if args.quick:
        args.per_effect, args.clean, args.pairs, args.no_timing = 1, 6, 5, True
    draws = draw_list(args.per_effect, args.clean, args.pairs, args.offset)
    cases = case_list(draws, modes)
    started = time.perf_counter()
    results: list[dict[str, Any]] = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        controls = [pool.submit(identifiability_control, e, seed) for e, seed in draws if len(e) > 1]
        futures = [pool.submit(run_case, effects, seed, mode) for effects, seed, mode in cases]
        for done, future in enumerate(futures, 1):
            row = future.result()
            results.append(row)
            flag = "ok " if row["identified"] and not row["extra"] else "BAD"
            errs = ", ".join(f"{k}={v:.0%}" for k, v in row["errors"].items())
            print(
                f"[{done:3d}/{len(cases)}] {flag} {row['sim_mode']:<6} {row['case']:<34} "
                f"{row['rate_hz']:>4g} Hz missed={row['missed']} extra={row['extra']} {errs} "
                f"({row['seconds']:.1f} s)",
                file=sys.stderr,
            )
    identifiable = {c["seed"]: c["identifiable"] for c in (f.result() for f in controls)}
    for row in results:
        if row["seed"] in identifiable:
            row["identifiable"] = identifiable[row["seed"]]
    summaries = {mode: summarise([r for r in results if r["sim_mode"] == mode]) for mode in modes}
    out: dict[str, Any] = {
        "draws": len(draws),
        "cases": len(results),
        "machine": f"{os.cpu_count()} cores, {platform.processor() or platform.machine()}",
        "wall_seconds": round(time.perf_counter() - started, 1),
        "by_way": summaries,
    }
    if not args.no_timing:
        out["timing_2h_200hz"] = timing_2h_200hz()
    print(json.dumps(out, indent=2))
    print(markdown(summaries))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump({"summary": out, "cases": results}, handle, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
