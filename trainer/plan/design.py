"""The design: the shortest candidate program whose Monte Carlo meets the target.

Candidates are tried shortest first. A few screening draws reject a candidate at its first failed
draw (cheap); a candidate that passes them gets the full Monte Carlo (its screening draws are its
first draws), and the first to meet the target wins. If none does, the candidate that identified the
most in screening (then the least drift left, then the shortest) gets the full Monte Carlo, and the
report says what it does not reach.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from trainer.plan.montecarlo import DrawResult, DrawTask, Runner
from trainer.plan.priors import Prior
from trainer.plan.programs import Program
from trainer.plan.summary import Summary, Target, identified, summarise

MakeTasks = Callable[[Program, range], list[DrawTask]]


class _Tried(list[tuple[Program, str]]):
    """The candidates looked at, each decision logged as it is taken (a search can take hours)."""

    def __init__(self, log: Callable[[str], None]) -> None:
        super().__init__()
        self.log = log

    def append(self, item: tuple[Program, str]) -> None:
        super().append(item)
        self.log(f"candidate {item[0].name} ({item[0].duration_s / 3600:.2f} h): {item[1]}")


@dataclass(frozen=True)
class Choice:
    program: Program
    summary: Summary
    tried: tuple[tuple[Program, str], ...]  # every candidate looked at and what became of it

    def met(self, target: Target) -> bool:
        return self.summary.meets(target)


def _screen(
    program: Program, make: MakeTasks, runner: Runner, screen: int, target: Target
) -> list[DrawResult]:
    """Screening draws in batches of the runner's width, stopping after a batch with a failure."""
    results: list[DrawResult] = []
    while len(results) < screen:
        batch = range(len(results), min(screen, len(results) + runner.width))
        results += runner.map(make(program, batch), f"screen {program.name}")
        if not all(identified(r, target) and r.ratio <= target.vs_cubic for r in results):
            break
    return results


def choose(
    candidates: list[Program],
    make: MakeTasks,
    runner: Runner,
    priors: tuple[Prior, ...],
    target: Target,
    *,
    draws: int,
    screen: int,
    log: Callable[[str], None] = print,
) -> Choice:
    tried = _Tried(log)
    screened: list[tuple[Program, list[DrawResult]]] = []
    for program in candidates:
        results = _screen(program, make, runner, min(screen, draws), target)
        first = summarise(program.name, program.duration_s, results, priors, target)
        if not first.meets(target) or len(results) < min(screen, draws):
            tried.append(
                (program, "rejected in screening: " + "; ".join(first.short_of(target) or ["a draw failed"]))
            )
            screened.append((program, results))
            continue
        full = results + runner.map(make(program, range(len(results), draws)), f"Monte Carlo {program.name}")
        summary = summarise(program.name, program.duration_s, full, priors, target)
        if summary.meets(target):
            tried.append((program, f"target {summary.verdict_label(target)}: chosen"))
            return Choice(program, summary, tuple(tried))
        tried.append(
            (
                program,
                "passed screening, missed in the full Monte Carlo: " + "; ".join(summary.short_of(target)),
            )
        )
        screened.append((program, full))
    if not screened:
        raise ValueError("no candidate program to try")

    def merit(item: tuple[Program, list[DrawResult]]) -> tuple[float, float, float]:
        s = summarise(item[0].name, item[0].duration_s, item[1], priors, target)
        return (sum(s.identified.values()), -s.ratio_median, -item[0].duration_s)

    program, results = max(screened, key=merit)
    full = results + runner.map(make(program, range(len(results), draws)), f"Monte Carlo {program.name}")
    summary = summarise(program.name, program.duration_s, full, priors, target)
    tried.append((program, f"best within the limits (target {summary.verdict_label(target)}): reported"))
    return Choice(program, summary, tuple(tried))
