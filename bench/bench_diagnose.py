"""Benchmark of ``trainer diagnose``: identification accuracy, false positives, parameter errors, speed.

Generates concealed-effect cases with :mod:`trainer.diagnose.scenarios` (varied seeds, protocols,
ramp rates, sample rates, noise levels and parameter draws): every catalogue effect of the
finder's test list alone, pairs of effects, and clean recordings. For each it runs the finder
with the user's simulation (the truth without the concealed effects) and scores:

* identification: every concealed effect is named in ``left_out``;
* false positives: effects named that were not concealed (on clean cases: any name at all);
* parameter errors: relative error of the checked time constants and amplitudes (25 % target);
* run time of one diagnosis of a 2 h, 200 Hz paper-oven recording (target: under a minute).

    python bench/bench_diagnose.py                 # 66 cases + timing, 2 worker processes
    python bench/bench_diagnose.py --quick         # 20 cases, no 200 Hz timing
    python bench/bench_diagnose.py --json out.json
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from typing import Any

import numpy as np

from trainer.diagnose import diagnose
from trainer.diagnose.document import document
from trainer.diagnose.scenarios import CHECKED_PARAMS, HIDDEN_EFFECTS, make_scenario
from trainer.physics.catalogue import rate_random_walk
from trainer.physics.config import PhysicsConfig

RANDOM_WALK = rate_random_walk.DEFINITION.identifier
# How the user's simulation is handed to the finder: ``truth`` (the truth minus the concealed
# effects), ``no-rrw`` (as a user would write it: bias polynomial, white noise and bias instability
# but no random walk; the recordings are then generated without a random walk too), ``none`` (no
# ``--sim``: the finder's default physics as the starting model).
SIM_MODES = ("truth", "no-rrw", "none")


def without_random_walk(config: PhysicsConfig) -> PhysicsConfig:
    return replace(config, noise=tuple(n for n in config.noise if n.identifier != RANDOM_WALK))


PAIRS: tuple[tuple[str, str], ...] = (
    ("thermal_lag", "periodic"),
    ("hysteresis", "bias_step"),
    ("temp_rate", "warmup"),
    ("stress_relaxation", "periodic"),
    ("warmup", "bias_step"),
    ("thermal_lag", "temp_quantization"),
)


def case_list(
    per_effect: int, clean: int, pairs: int, offset: int, sim_mode: str = "truth"
) -> list[tuple[tuple[str, ...], int]]:
    cases: list[tuple[tuple[str, ...], int]] = []
    seed = 1000 + offset
    for effect in HIDDEN_EFFECTS:
        for _ in range(per_effect):
            if not (sim_mode == "no-rrw" and effect == RANDOM_WALK):  # no random walk to conceal
                cases.append(((effect,), seed))
            seed += 1
    for k in range(pairs):
        cases.append((PAIRS[k % len(PAIRS)], seed))
        seed += 1
    for _ in range(clean):
        cases.append(((), seed))
        seed += 1
    return cases


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
    result = diagnose(rec, sim, holdout_fraction=0.0)
    seconds = time.perf_counter() - started
    doc = document(result)
    hidden = [{"effect": h.identifier, "params": dict(h.params)} for h in scenario.hidden]
    found = [{"effect": e["effect"], "params": e["params"]} for e in doc["left_out"]]
    names = {f["effect"] for f in found}
    return {
        "case": scenario.name,
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
        "seconds": seconds,
    }


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
    """Cases, identified, with an extra finding, parameter errors of one group of cases."""
    errs = [v for r in rows for v in r["errors"].values()]
    return {
        "cases": len(rows),
        "identified": sum(r["identified"] for r in rows),
        "with_extra": sum(bool(r["extra"]) for r in rows),
        "param_err_median": float(np.median(errs)) if errs else None,
        "param_err_max": float(np.max(errs)) if errs else None,
        "params_within_25pct": f"{sum(e <= 0.25 for e in errs)}/{len(errs)}",
    }


def summarise(results: list[dict[str, Any]]) -> dict[str, Any]:
    effect_cases = [r for r in results if r["effects"]]
    clean_cases = [r for r in results if not r["effects"]]
    per_effect = {
        effect: _group_summary([r for r in effect_cases if r["effects"] == [effect]])
        for effect in HIDDEN_EFFECTS
    }
    pair_rows = [r for r in effect_cases if len(r["effects"]) > 1]
    all_errs = [v for r in effect_cases for v in r["errors"].values()]
    per_effect["pairs"] = _group_summary(pair_rows)
    return {
        "cases": len(results),
        "identification_accuracy": sum(r["identified"] for r in effect_cases) / max(1, len(effect_cases)),
        "pairs_identified": f"{sum(r['identified'] for r in pair_rows)}/{len(pair_rows)}",
        "clean_with_finding": f"{sum(bool(r['extra']) for r in clean_cases)}/{len(clean_cases)}",
        "false_positive_rate_clean": sum(bool(r["extra"]) for r in clean_cases) / max(1, len(clean_cases)),
        "cases_with_extra_effect": sum(bool(r["extra"]) for r in effect_cases) / max(1, len(effect_cases)),
        "param_within_25pct": sum(e <= 0.25 for e in all_errs) / max(1, len(all_errs)),
        "param_err_median": float(np.median(all_errs)) if all_errs else None,
        "seconds_per_case_median": float(np.median([r["seconds"] for r in results])),
        "per_effect": per_effect,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--per-effect", type=int, default=5)
    parser.add_argument("--clean", type=int, default=12)
    parser.add_argument("--pairs", type=int, default=9)
    parser.add_argument("--offset", type=int, default=0, help="shift all case seeds")
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument("--quick", action="store_true", help="1 case per effect, 6 clean, 5 pairs, no timing")
    parser.add_argument("--no-timing", action="store_true")
    parser.add_argument("--json", help="write all results here")
    parser.add_argument(
        "--sim-mode",
        choices=SIM_MODES,
        default="truth",
        help="the user's simulation: the truth minus the concealed effects (default), the same without "
        "a random walk (and recordings without one), or no --sim at all",
    )
    args = parser.parse_args(argv)
    if args.quick:
        args.per_effect, args.clean, args.pairs, args.no_timing = 1, 6, 5, True
    cases = case_list(args.per_effect, args.clean, args.pairs, args.offset, args.sim_mode)
    started = time.perf_counter()
    results: list[dict[str, Any]] = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futures = [pool.submit(run_case, effects, seed, args.sim_mode) for effects, seed in cases]
        for done, future in enumerate(futures, 1):
            row = future.result()
            results.append(row)
            flag = "ok " if row["identified"] and not row["extra"] else "BAD"
            errs = ", ".join(f"{k}={v:.0%}" for k, v in row["errors"].items())
            print(
                f"[{done:3d}/{len(cases)}] {flag} {row['case']:<34} {row['rate_hz']:>4g} Hz "
                f"missed={row['missed']} extra={row['extra']} {errs} ({row['seconds']:.1f} s)",
                file=sys.stderr,
            )
    summary = summarise(results)
    summary["sim_mode"] = args.sim_mode
    summary["wall_seconds"] = round(time.perf_counter() - started, 1)
    if not args.no_timing:
        summary["timing_2h_200hz"] = timing_2h_200hz()
    print(json.dumps(summary, indent=2))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as handle:
            json.dump({"summary": summary, "cases": results}, handle, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
