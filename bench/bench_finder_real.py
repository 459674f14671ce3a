"""Benchmark of ``trainer diagnose`` on effects concealed in a real recording.

Simulated recordings carry the simulator's physics and noise; a real run carries its own. This
bench adds known catalogue effects (through the catalogue's own formulas,
``physics.effects.effect_contribution``) to one channel of an imported real recording, diagnoses
the clean channel and every clean + effect case without ``--sim``, and scores:

* named: every added instance is matched by a finding of its effect with the checked parameters
  within 25 % (a step's time within two blocks);
* duplicates: two findings of one effect whose parameters coincide within the data's resolution
  (periods within ``1/duration`` in frequency, step times within two blocks);
* lost: findings of the clean run that are missing from the case's findings ("said": the case's
  report names the effect in an ambiguity, e.g. absorbed by a confounder on this profile, or as a
  near miss below the criterion). Why it is lost, in two measured numbers: the BIC drop the finding
  earns on the clean run itself once the case's added effects are in the clean model
  (``diagnose.detection.evidence_beside``; below the criterion the added effect is not elsewhere but
  shares the finding's signature on this run: a step just after a reversal beside a filtered rate
  term that switches there), and, on the case's data, the BIC of the clean findings plus the added
  instances against what the finder named (at or below minus the criterion the finder missed a
  model it would accept: the search's loss; above it the case's data prefer what was named, or the
  clean description by less than the criterion asks). The totals count both kinds apart;
* ambiguous: an added effect not named but reported as ambiguous (an implausible best fit or its
  plausible alternative) or not identifiable;
* extra: findings that are neither the clean run's nor an added instance;
* size / limit: each added instance's size over the clean run's detection limit for its own shape
  (``diagnose.detection.shape_limit``: the size at which the criterion names it beside the clean
  model, the noise re-estimated on both sides as the finder does). Every
  case is sized by it: ``--multiples`` (default 2 and 4) times the limit, so that a case asks the
  same of a quiet run and a noisy one, and a fixed size does not sit at the edge of detection on
  one channel and far above it on another (at the limit the criterion names an instance half of
  the time);
* run's own / limit: the clean run's own amplitude of each instance's shape beyond the clean model
  (``diagnose.detection.shape_content``, signed as the instance is; below the limit, so not named),
  over the limit. The case holds the sum, so the finder is also scored against it ("within 25 % of
  size + own"): a miss there is the finder's, a miss only against the added size is the run's own
  content of that shape;
* silent: an added effect neither named nor reported (ambiguity, not identifiable, or the
  report's "smallest size this run names");
* not scored: the profile cannot identify the effect (a branch offset without a reversal), the
  clean run already carries the effect or is unsettled about it (a found
  hysteresis excludes a branch offset, an ambiguity lists it: the sizes merge), or the smallest
  multiple of its limit is above the largest size asked, the catalogue's plausible maximum over
  1.25 (this run cannot be asked to name it at a plausible size; it runs at that size). A larger
  multiple above it runs at that size and is scored (within 25 % of it the estimate stays
  plausible; at the maximum itself half of the estimates would be an implausible best fit). The
  totals are given for the scored and the other cases apart;
* time per diagnosis.

    trainer import ../shared/data/real/tofupilot_imu_chamber_cycle.tsv --preset tofupilot \\
        --channels all -o /tmp/imu.csv
    python bench/bench_finder_real.py /tmp/imu.csv                       # every case
    python bench/bench_finder_real.py /tmp/imu.csv --cases step,periodic # names containing these
    python bench/bench_finder_real.py --simulated 3001 --cases step         # a clean generated run
    python bench/bench_finder_real.py --simulated 3001 --hidden hysteresis  # ... with its own finding
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np

from trainer.commands.diagnose_cmd import every_output
from trainer.data.channels import ALL, channel_view, select_channels
from trainer.data.recording import Recording
from trainer.data.recording_io import read_recording
from trainer.diagnose import diagnose
from trainer.diagnose.detection import evidence_beside, shape_content, shape_limit
from trainer.diagnose.model import Term, fit_model
from trainer.diagnose.result import Diagnosis
from trainer.diagnose.scenarios import make_scenario
from trainer.diagnose.select import THRESHOLD
from trainer.errors import run_cli
from trainer.physics.catalogue import (
    DEFINITIONS,
    bias_step,
    excluded,
    flagged_range,
    hysteresis_offset,
    periodic,
    temp_rate,
    warmup,
)
from trainer.physics.effects import EffectConfig, effect_contribution

STEP = bias_step.DEFINITION.identifier
PERIODIC = periodic.DEFINITION.identifier
WARMUP = warmup.DEFINITION.identifier
RATE = temp_rate.DEFINITION.identifier
BRANCH = hysteresis_offset.DEFINITION.identifier
CHECKED = {
    STEP: ("step_mg",),
    PERIODIC: ("amp_mg", "period_s"),
    WARMUP: ("amp_mg", "tau_s"),
    RATE: ("k_mg_per_c_per_min",),
    BRANCH: ("amp_mg",),
}
TOLERANCE = 0.25
STEP_BLOCKS = 2.0  # step times closer than this many blocks are one instant


@dataclass(frozen=True)
class Case:
    """Instances added together; each amplitude is a multiple of the clean run's detection limit for
    the instance's own shape (its sign carried by ``added``), so that a case asks the same of a quiet
    run and a noisy one."""

    name: str
    added: tuple[EffectConfig, ...]
    multiple: float


MULTIPLES = (2.0, 4.0)  # sizes over the detection limit: the limit names an instance half of the time


def cases(duration_s: float, multiples: Sequence[float] = MULTIPLES) -> list[Case]:
    """Additive effects the run can identify, at each of ``multiples`` of their detection limits, and
    pairs of instances of one effect (at the smallest multiple).

    Amplitudes here are signs only (sized by :func:`sized`). The rate term reads the temperature
    through a 60 s filter (the measured thermometer's first samples jump by 0.5 degC, a raw derivative
    would be a spike); step times and periods lie away from the bundled run's own findings (steps at
    1022 s and 4199 s on z, 1446 s on x).
    """
    d = duration_s
    out = []
    for multiple in multiples:
        label = f"{multiple:g}x"
        out += [
            Case(f"step {label}", (EffectConfig(STEP, {"t_s": 0.55 * d, "step_mg": 1.0}),), multiple),
            Case(
                f"periodic 300 s {label}",
                (EffectConfig(PERIODIC, {"amp_mg": 1.0, "period_s": 300.0, "phase_rad": 0.7}),),
                multiple,
            ),
            Case(
                f"periodic 600 s {label}",
                (EffectConfig(PERIODIC, {"amp_mg": 1.0, "period_s": 600.0, "phase_rad": 0.7}),),
                multiple,
            ),
            Case(f"warmup {label}", (EffectConfig(WARMUP, {"amp_mg": 1.0, "tau_s": 400.0}),), multiple),
            Case(
                f"temp_rate {label}",
                (EffectConfig(RATE, {"k_mg_per_c_per_min": 1.0, "tau_s": 60.0}),),
                multiple,
            ),
            Case(
                f"branch offset {label}", (EffectConfig(BRANCH, {"amp_mg": 1.0, "width_c": 10.0}),), multiple
            ),
        ]
    pair = min(multiples)
    out += [
        Case(
            "two steps",
            (
                EffectConfig(STEP, {"t_s": 0.4 * d, "step_mg": 1.0}),
                EffectConfig(STEP, {"t_s": 0.7 * d, "step_mg": -1.0}),
            ),
            pair,
        ),
        Case(
            "two periodics",
            (
                EffectConfig(PERIODIC, {"amp_mg": 1.0, "period_s": 600.0, "phase_rad": 0.7}),
                EffectConfig(PERIODIC, {"amp_mg": 1.0, "period_s": 150.0, "phase_rad": -1.0}),
            ),
            pair,
        ),
    ]
    return out


def multiples_list(text: str) -> tuple[float, ...]:
    """``--multiples``: comma-separated positive numbers (argparse turns the error into one line)."""
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: comma-separated numbers, e.g. 2,4") from None
    if not values or not all(math.isfinite(v) and v > 0 for v in values):
        raise argparse.ArgumentTypeError(f"{text!r}: positive multiples of the detection limit, e.g. 2,4")
    return values


def amplitude_name(effect: str) -> str:
    return CHECKED[effect][0]


def plausible_max(effect: str, clean: Diagnosis) -> float:
    """The largest plausible amplitude of ``effect`` on the clean run's channel, as the finder flags
    it (in mg the catalogue's; on a gyroscope or barometer bounded by the channel's drift span)."""
    bounds = flagged_range(effect, amplitude_name(effect), clean.scale)
    return math.inf if bounds is None else bounds[1]


def largest_size(effect: str, clean: Diagnosis) -> float:
    """The largest size the bench asks: the plausible maximum over ``1 + TOLERANCE``, so that every
    estimate within the tolerance is plausible (at the maximum itself half of the estimates lie
    above it and are reported as an implausible best fit, not named: a 5 mg step on z found at
    5.16 mg)."""
    return plausible_max(effect, clean) / (1.0 + TOLERANCE)


@dataclass(frozen=True)
class Sized:
    """A case at its sizes: each instance's limit, and whether its largest size keeps it below
    the smallest multiple of that limit the bench asks (then this run cannot be asked to name it)."""

    case: Case
    limits: tuple[float, ...]
    unaskable: tuple[bool, ...]
    floor: float
    owns: tuple[float, ...]  # the clean run's own amplitude of each instance's shape (:func:`own_of`)


def sized(case: Case, clean: Diagnosis, rec: Recording, floor: float) -> Sized:
    """``case`` with every amplitude set to ``multiple`` x its clean-run limit, at most
    :func:`largest_size` (a larger one would be reported as implausible, not named); an instance
    held below ``floor`` x its limit by it is not asked of this run."""
    added, limits, unaskable, owns = [], [], [], []
    for effect in case.added:
        name = amplitude_name(effect.identifier)
        limit = limit_of(effect, clean, rec)
        size = min(case.multiple * limit, largest_size(effect.identifier, clean))
        added.append(
            EffectConfig(effect.identifier, {**effect.params, name: math.copysign(size, effect.params[name])})
        )
        limits.append(limit)
        unaskable.append(size < floor * limit * (1.0 - 1e-9))
        owns.append(own_of(effect, clean, rec))
    return Sized(
        Case(case.name, tuple(added), case.multiple), tuple(limits), tuple(unaskable), floor, tuple(owns)
    )


def contribution(rec: Recording, effect: EffectConfig) -> np.ndarray:
    """One instance's catalogue contribution on the recording's time axis and temperature."""
    return effect_contribution(
        effect.identifier, effect.params, rec.time_s - rec.time_s[0], rec.temp_c, rec.temp_c
    )


def add_effects(rec: Recording, added: Sequence[EffectConfig]) -> Recording:
    """The recording with the catalogue contribution of every ``added`` instance on its channel."""
    extra = sum((contribution(rec, e) for e in added), np.zeros(rec.time_s.size))
    columns = dict(rec.columns)
    columns["accel_mg"] = rec.accel_mg + extra
    return Recording(columns, dict(rec.meta), rec.source)


def key_of(effect: str, params: dict[str, float]) -> float | None:
    """The parameter that tells instances of one effect apart (step time, frequency)."""
    if effect == STEP:
        return params["t_s"]
    if effect == PERIODIC:
        return 1.0 / params["period_s"]
    return None


def same_instance(effect: str, a: dict[str, float], b: dict[str, float], d: Diagnosis) -> bool:
    """Whether two parameter sets of ``effect`` coincide within the data's resolution."""
    ka, kb = key_of(effect, a), key_of(effect, b)
    if ka is None or kb is None:
        return True
    resolution = STEP_BLOCKS * d.data.block_s if effect == STEP else 1.0 / d.data.duration_s
    return abs(ka - kb) <= resolution


def findings(d: Diagnosis) -> list[tuple[str, dict[str, float]]]:
    return [(e.effect, dict(e.params)) for e in d.left_out]


def within(true: dict[str, float], found: dict[str, float], names: Sequence[str]) -> bool:
    return all(abs(found[n] - true[n]) <= TOLERANCE * abs(true[n]) for n in names)


def carried(clean: Diagnosis) -> set[str]:
    """Effects the clean run already carries or is unsettled about: an added instance merges with the
    run's own (a found hysteresis, an ambiguity), so its size cannot be scored. Steps and periodics
    are instances of their own and are always scored."""
    own = {e for e, p in findings(clean) if key_of(e, p) is None}
    unsettled = {x for a in clean.ambiguous for x in a.effects}
    return {
        effect
        for effect in CHECKED
        if effect in own | unsettled or any(excluded(effect, other) for other in own)
    }


def nonlinear_names(effect: str) -> list[str]:
    """The effect's nonlinear parameters, in the order of the finder's terms."""
    return [name for name, _ in DEFINITIONS[effect].finder.nonlinear]


def as_term(added: EffectConfig) -> Term:
    """An added instance as the finder's term, at its nonlinear parameters (free)."""
    return Term(added.identifier, tuple(added.params[n] for n in nonlinear_names(added.identifier)))


def unit_shape(added: EffectConfig, rec: Recording) -> tuple[np.ndarray, tuple[float, ...]]:
    """The contribution of ``added`` per unit of its amplitude, and its nonlinear parameters."""
    unit = EffectConfig(added.identifier, {**added.params, amplitude_name(added.identifier): 1.0})
    nl = as_term(added).nl
    return contribution(rec, unit), nl


def limit_of(added: EffectConfig, clean: Diagnosis, rec: Recording) -> float:
    """The clean run's detection limit for the shape of ``added``: the amplitude at which the
    criterion would name it beside the clean model, at the clean run's noise."""
    shape, nl = unit_shape(added, rec)
    return shape_limit(clean.selection.final, added.identifier, shape, nl).amplitude


def own_of(added: EffectConfig, clean: Diagnosis, rec: Recording) -> float:
    """The clean run's own amplitude of the shape of ``added`` beyond the clean model (below its
    limit, so not named): the case's data hold the sum of this and the added size."""
    shape, nl = unit_shape(added, rec)
    return shape_content(clean.selection.final, added.identifier, shape, nl)[0]


def evidence_beside_added(
    effect: str, params: dict[str, float], clean: Diagnosis, added: Sequence[EffectConfig]
) -> float | None:
    """The BIC drop a finding of the clean run earns there once the case's added effects are in the
    clean model too (:func:`evidence_beside`): below the criterion the added effect is not elsewhere,
    it shares the finding's signature on this run, and no selection can keep both. None for a noise
    term."""
    final = clean.selection.final
    index = next(
        (
            k
            for k, t in enumerate(final.terms)
            if t.identifier == effect
            and (
                key_of(effect, params) is None
                or same_instance(effect, params, dict(zip(nonlinear_names(effect), t.nl, strict=True)), clean)
            )
        ),
        None,
    )
    if index is None:
        return None
    return evidence_beside(final, index, [as_term(a) for a in added])


def clean_description_on_case(clean: Diagnosis, d: Diagnosis, added: Sequence[EffectConfig]) -> float:
    """BIC, on the case's data, of the clean run's findings plus the added instances (free terms, at
    the case's noise terms) minus that of what the finder named there. At or below minus the
    criterion the finder missed a model it would have accepted (the search's loss); above it the case's
    data prefer what was named, or the clean description by less than the criterion asks."""
    final = d.selection.final
    terms = clean.selection.final.terms + tuple(as_term(a) for a in added)
    kept = fit_model(terms, final.noise.terms, final.data, start=final.noise)
    return kept.bic - final.bic


def score(at: Sized, d: Diagnosis, clean: Diagnosis) -> dict[str, object]:
    case = at.case
    found = findings(d)
    used: set[int] = set()
    named = params_ok = params_ok_own = 0
    for added, own in zip(case.added, at.owns, strict=True):
        name = amplitude_name(added.identifier)
        with_own = {**added.params, name: added.params[name] + own}
        matches = [
            k
            for k, (effect, p) in enumerate(found)
            if effect == added.identifier and k not in used and same_instance(effect, p, added.params, d)
        ]
        if effect_near := [
            k for k in matches if within(added.params, found[k][1], CHECKED[added.identifier])
        ]:
            matches = effect_near
        if matches:
            used.add(matches[0])
            named += 1
            params_ok += within(added.params, found[matches[0]][1], CHECKED[added.identifier])
            params_ok_own += within(with_own, found[matches[0]][1], CHECKED[added.identifier])
    duplicates = sum(
        1
        for i, (ei, pi) in enumerate(found)
        for j, (ej, pj) in enumerate(found)
        if i < j and ei == ej and same_instance(ei, pi, pj, d) and key_of(ei, pi) is not None
    )
    lost_found = [
        (effect, p)
        for effect, p in findings(clean)
        if not any(e == effect and same_instance(effect, p, q, d) for e, q in found)
    ]
    lost = [effect for effect, _ in lost_found]
    beside = [evidence_beside_added(effect, p, clean, case.added) for effect, p in lost_found]
    kept_description = clean_description_on_case(clean, d, case.added) if lost_found else math.nan
    extra = [
        effect
        for k, (effect, p) in enumerate(found)
        if k not in used
        and not any(e == effect and same_instance(effect, p, q, d) for e, q in findings(clean))
    ]
    reported = (
        {x for a in d.ambiguous for x in a.effects}
        | {n.effect for n in d.not_identifiable}
        | {u.effect for u in d.undetected}
        | {m.effect for m in d.suggestive}
    )
    unnamed = {a.identifier for a in case.added} - {e for e, _ in found}
    unscored = (
        [
            f"{a.identifier}: {at.floor:g}x its limit ({limit:.3g}) is above {largest_size(a.identifier, clean):.3g} "
            f"(the plausible {plausible_max(a.identifier, clean):.3g} / {1 + TOLERANCE:g})"
            for a, limit, unaskable in zip(case.added, at.limits, at.unaskable, strict=True)
            if unaskable
        ]
        + [
            f"{a.identifier}: the run's own (found or unsettled)"
            for a in case.added
            if a.identifier in carried(clean)
        ]
        + [
            f"{a.identifier}: not identifiable on this profile ({info.reason})"
            for a in case.added
            if (info := clean.profile.identifiability.get(a.identifier)) is not None and not info.identifiable
        ]
    )
    return {
        "scored": not unscored,
        "size_to_limit": [
            abs(a.params[amplitude_name(a.identifier)]) / lim
            for a, lim in zip(case.added, at.limits, strict=True)
        ],
        "unscored": unscored,
        "silent": sorted(unnamed - reported),
        "ambiguous": sorted(unnamed & reported),
        "lost_said": [effect for effect in lost if effect in reported],
        "lost_beside": beside,
        "lost_sharing": [
            sorted(
                {
                    x.effect
                    for m in d.suggestive
                    if m.effect == effect and same_instance(effect, p, m.params, d)
                    for x in m.shares
                }
            )
            for effect, p in lost_found
        ],
        "lost_shared": [e for e, b in zip(lost, beside, strict=True) if b is not None and b < THRESHOLD],
        "clean_on_case": kept_description,
        "lost_missed": lost if kept_description <= -THRESHOLD else [],
        "named": named,
        "added": len(case.added),
        "params_ok": params_ok,
        "params_ok_own": params_ok_own,
        "own_to_limit": [own / lim for own, lim in zip(at.owns, at.limits, strict=True)],
        "duplicates": duplicates,
        "lost": lost,
        "extra": extra,
    }


def describe(d: Diagnosis) -> str:
    parts = []
    for effect, p in findings(d):
        shown = ", ".join(f"{k} {v:.4g}" for k, v in d.params(p).items() if k != "phase_rad")  # channel names
        parts.append(f"{effect} ({shown})")
    return "; ".join(parts) or "-"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "recording", nargs="?", help="an imported multi-channel recording (trainer import --channels all)"
    )
    parser.add_argument(
        "--simulated", type=int, metavar="SEED", help="instead: the clean generated recording of this seed"
    )
    parser.add_argument(
        "--hidden",
        default="",
        metavar="EFFECTS",
        help="with --simulated: effects concealed in the generated 'clean' run (its own findings)",
    )
    parser.add_argument(
        "--channel",
        default="accel0_z",
        help="a channel, a comma-separated list, or all (a summary over them at the end)",
    )
    parser.add_argument("--cases", default="", help="comma-separated substrings of case names (default: all)")
    parser.add_argument(
        "--multiples",
        type=multiples_list,
        default=MULTIPLES,
        help=f"sizes over each instance's detection limit on the clean run (default: {','.join(f'{m:g}' for m in MULTIPLES)})",
    )
    args = parser.parse_args(argv)
    if args.simulated is not None:
        hidden = tuple(h for h in args.hidden.split(",") if h)
        generated = make_scenario(hidden, args.simulated).recording().without_truth()
        runs = [(f"simulated #{args.simulated} ({'+'.join(hidden) or 'nothing'} concealed)", generated)]
    elif args.recording:
        full = read_recording(args.recording)
        wanted_channels = (ALL,) if args.channel == ALL else tuple(args.channel.split(","))
        runs = [(c.name, channel_view(full, c)) for c in select_channels(full, wanted_channels)]
    else:
        parser.error("give a recording or --simulated SEED")
    wanted = [w.strip() for w in args.cases.split(",") if w.strip()]
    grand = {group: dict.fromkeys(TOTAL_KEYS, 0) for group in GROUPS}
    for label, rec in runs:
        totals = bench_channel(label, rec, wanted, args.multiples)
        for group in GROUPS:
            for k in TOTAL_KEYS:
                grand[group][k] += totals[group][k]
    if len(runs) > 1:
        print(f"\nall {len(runs)} channels ({', '.join(label for label, _ in runs)}):")
        print_totals(grand)
    print(
        "\n(not scored: an added effect the profile cannot identify, one the clean run already carries or is unsettled about (its size merges "
        f"with the run's own), or one whose largest size asked (the plausible maximum / {1 + TOLERANCE:g}) is "
        "below the smallest multiple of its detection limit on this run (it runs at that size))"
    )
    return 0


GROUPS = ("scored", "not scored")
TOTAL_KEYS = (
    "named",
    "added",
    "params_ok",
    "params_ok_own",
    "duplicates",
    "lost",
    "lost_said",
    "lost_shared",
    "lost_missed",
    "silent",
)


def bench_channel(
    label: str, rec: Recording, wanted: Sequence[str], multiples: Sequence[float]
) -> dict[str, dict[str, int]]:
    """The clean diagnosis and every case of one channel, a table row each; the totals per group."""
    started = time.perf_counter()
    clean = diagnose(rec, holdout_fraction=0.0)
    clean_s = time.perf_counter() - started
    every_output(clean)
    print(f"\nclean {label}: {describe(clean)} ({clean_s:.1f} s)\n", flush=True)
    chosen = [
        c for c in cases(clean.data.duration_s, multiples) if not wanted or any(w in c.name for w in wanted)
    ]
    print(
        "| case | named | params within 25 % | duplicates | lost clean findings | extra | ambiguous "
        "| size / limit | run's own / limit | within 25 % of size + own | silent | not scored | s | findings |"
    )
    print("|---|--:|--:|--:|---|---|---|--:|--:|--:|---|---|--:|---|")
    totals = {group: dict.fromkeys(TOTAL_KEYS, 0) for group in GROUPS}
    for case in chosen:
        started = time.perf_counter()
        at = sized(case, clean, rec, min(multiples))
        d = diagnose(add_effects(rec, at.case.added), holdout_fraction=0.0)
        seconds = time.perf_counter() - started
        every_output(d)  # a finding an output cannot take fails here
        s = score(at, d, clean)
        total = totals["scored" if s["scored"] else "not scored"]
        for k in ("named", "added", "params_ok", "params_ok_own", "duplicates"):
            total[k] += int(s[k])  # type: ignore[call-overload]
        for k in ("lost", "lost_said", "lost_shared", "lost_missed", "silent"):
            total[k] += len(s[k])  # type: ignore[arg-type]
        ratios = cast(list[float], s["size_to_limit"])
        lost = lost_labels(s)
        sizes = ", ".join(f"{abs(a.params[amplitude_name(a.identifier)]):.3g}" for a in at.case.added)
        print(
            f"| {case.name} ({sizes}) | {s['named']}/{s['added']} | {s['params_ok']}/{s['added']} | {s['duplicates']} "
            f"| {', '.join(lost) or '-'} | {', '.join(s['extra']) or '-'} | {', '.join(s['ambiguous']) or '-'} "  # type: ignore[arg-type]
            f"| {' / '.join(f'{r:.2f}' for r in ratios)} "
            f"| {' / '.join(f'{r:+.2f}' for r in cast(list[float], s['own_to_limit']))} "
            f"| {s['params_ok_own']}/{s['added']} | {', '.join(s['silent']) or '-'} "  # type: ignore[arg-type]
            f"| {'; '.join(s['unscored']) or '-'} | {seconds:.0f} | {describe(d)} |",  # type: ignore[arg-type]
            flush=True,
        )
    print_totals(totals)
    return totals


def lost_labels(s: dict[str, object]) -> list[str]:
    """Each lost finding with "said" when the case's report names it, the effects its near miss says it
    shares its signature with (:mod:`trainer.diagnose.shared`), its BIC drop beside the added
    effects on the clean run (below the criterion they share its signature) and, once per case, the
    BIC of the clean description plus the added on the case's data against what was named."""
    said = cast(list[str], s["lost_said"])
    out = []
    for effect, beside, sharing in zip(
        cast(list[str], s["lost"]),
        cast(list[float | None], s["lost_beside"]),
        cast(list[list[str]], s["lost_sharing"]),
        strict=True,
    ):
        notes = (
            (["said"] if effect in said else [])
            + ([f"the report: shares its signature with {' and '.join(sharing)}"] if sharing else [])
            + ([] if beside is None else [f"{beside:.1f} beside the added on the clean run"])
        )
        out.append(f"{effect} ({'; '.join(notes)})" if notes else effect)
    if out:
        out[-1] += f"; clean + added on the case {cast(float, s['clean_on_case']):+.1f}"
    return out


def print_totals(totals: dict[str, dict[str, int]]) -> None:
    for group, t in totals.items():
        print(
            f"\n{group}: named {t['named']}/{t['added']}, params within 25 % {t['params_ok']}/{t['added']} "
            f"(of the added size plus the run's own content of its shape: {t['params_ok_own']}/{t['added']}), "
            f"duplicates {t['duplicates']}, lost clean findings {t['lost']} ({t['lost_said']} of them "
            f"said out loud: in an ambiguity, e.g. absorbed by a confounder, or as a near miss; {t['lost_shared']} of them "
            f"below the criterion ({THRESHOLD:g}) beside the added effects on the clean run itself: the added effect is not "
            f"elsewhere, it shares the finding's signature; {t['lost_missed']} where the clean findings plus the added "
            f"fit the case lower in BIC by the criterion or more: the search's), added effects neither named "
            f"nor reported {t['silent']}"
        )


if __name__ == "__main__":
    sys.exit(run_cli(main, sys.argv[1:]))  # a bad recording or channel: one line, not a traceback
