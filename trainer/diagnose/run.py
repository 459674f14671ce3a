"""The finder end to end: calibrate the user's model, search, locate, and compare before/after.

The steps live in their modules: locating in :mod:`.where` (on the scans of :mod:`.locate`), the
fit summaries in :mod:`.fit_summary`, the held-out check in :mod:`.holdout`, the augmented
simulation in :mod:`.augmented`; the result types in :mod:`.result`, their JSON in :mod:`.document`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from functools import partial
from typing import cast

import numpy as np

from trainer.data.channels import channel_unit
from trainer.data.recording import Recording
from trainer.diagnose.augmented import augmented_config
from trainer.diagnose.baseline import build_baseline
from trainer.diagnose.blocks import DEFAULT_MAX_BLOCKS, BlockData, build_blocks
from trainer.diagnose.detection import detection_limit
from trainer.diagnose.fit_summary import FitSummary, summarise
from trainer.diagnose.holdout import holdout_check
from trainer.diagnose.implausible import prefer_plausible, resolve_implausible
from trainer.diagnose.model import (
    ModelFit,
    catalogue_effects,
    fit_model,
)
from trainer.diagnose.profile import Profile, Region, analyse_profile, in_unit
from trainer.diagnose.result import (
    Ambiguity,
    Diagnosis,
    Evidence,
    LeftOut,
    NotIdentifiable,
    NotSupported,
    Suggestive,
    Tested,
)
from trainer.diagnose.select import (
    THRESHOLD,
    NearMiss,
    Selection,
    baseline_support,
    final_indices,
    forward_select,
    near_misses,
    resolve,
    stopped_full,
)
from trainer.diagnose.shared import shared_signatures
from trainer.diagnose.threads import single_blas_thread
from trainer.diagnose.where import (
    AllanWhere,
    locate_mismatch,
    noise_cov,
    noise_where,
    special_where,
    where_regions,
)
from trainer.errors import UserError
from trainer.physics.catalogue import (  # the finder's order and advice, per effect
    ADVICE,
    CANDIDATE_ORDER,
    DEFINITIONS,
    EFFECTS,
    MULTI_INSTANCE,
)
from trainer.physics.catalogue.base import catalogue_params
from trainer.physics.catalogue.plausibility import implausible
from trainer.physics.catalogue.units import ChannelScale
from trainer.physics.config import PhysicsConfig
from trainer.physics.effects import EFFECT_PARAMETERS, EffectConfig
from trainer.progress import progress_bar


def _param_flags(effect: EffectConfig, scale: ChannelScale | None = None) -> list[str]:
    """One line per parameter outside its plausible range (the rule the physics fit applies too)."""
    return list(implausible(effect.identifier, effect.params, scale).values())


def channel_scale(rec: Recording, data: BlockData) -> ChannelScale | None:
    """What a non-mg channel's amplitudes are judged against (None on an mg channel)."""
    unit = channel_unit(rec)
    if unit == "mg":
        return None
    return ChannelScale.measure(unit, data.temperature(True), data.accel, data.rate(True))


# ------------------------------------------------------------------------------------ main


def diagnose(
    rec: Recording,
    sim: PhysicsConfig | None = None,
    *,
    holdout_fraction: float = 0.25,
    max_blocks: int = DEFAULT_MAX_BLOCKS,
    progress: bool = False,
    report_search: bool = True,
) -> Diagnosis:
    """Find what the user's simulation ``sim`` leaves out of recording ``rec``.

    ``rec`` may contain ``true_*`` columns; they are removed before anything is read.
    ``report_search``: the search a report wants, with pairs of steps placed jointly when nothing
    single passes, the near misses listed and the detection limits of the weak effects not named
    (a few noise fits each). The physics compensator turns it off: it reads only the named
    structure, and on the bundled run's accel z a step pair named in one training fold made that
    fold's held-out drift worse (4.90 against 4.15 mg on the heating segment).
    """
    with single_blas_thread():
        return _diagnose(
            rec,
            sim,
            holdout_fraction=holdout_fraction,
            max_blocks=max_blocks,
            progress=progress,
            report_search=report_search,
        )


NOISE_FREE_RATIO = 1e-7  # block residual over the channel's spread below which nothing is measured


def _require_noise(baseline_fit: ModelFit, rec: Recording) -> None:
    """Refuse a channel the baseline explains to rounding: every criterion weighs evidence against
    the sensor's noise, and without any it names structure of 1e-5 mg with a BIC of -1e11."""
    spread = float(np.std(baseline_fit.data.accel))
    left = float(np.std(baseline_fit.residual))
    if spread > 0.0 and left >= NOISE_FREE_RATIO * spread:
        return
    unit = channel_unit(rec)
    raise UserError(
        f"{rec.source}: the baseline model explains the channel to {left:.2g} {unit} (its spread {spread:.3g} "
        f"{unit}): no sensor noise to weigh evidence against (a simulation without noise, or a column computed "
        "from the temperature?); diagnose a measured channel"
    )


def _diagnose(
    rec: Recording,
    sim: PhysicsConfig | None,
    *,
    holdout_fraction: float,
    max_blocks: int,
    progress: bool,
    report_search: bool,
) -> Diagnosis:
    started = time.perf_counter()
    rec = rec.without_truth()
    user_sim = sim
    if sim is not None:  # a gyroscope's or barometer's physics is its [channels.<name>] table
        sim = sim.for_channel(rec.meta.get("channel"), channel_unit(rec))
    stages = progress_bar(progress=progress, total=5, desc="diagnose", unit="stage", leave=False)
    t_axis = np.asarray(rec.time_s, dtype=np.float64) - float(rec.time_s[0])
    probe = build_blocks(rec, max_blocks=max_blocks)
    baseline = build_baseline(sim, t_axis, probe.lattice_lsb_c)
    data = (
        probe
        if baseline.known_input is None
        else build_blocks(rec, known_input=baseline.known_input, max_blocks=max_blocks)
    )
    profile = analyse_profile(data, rec.meta, baseline.input_varies)
    profile.identifiability = in_unit(profile.identifiability, channel_unit(rec))
    ident = profile.identifiability
    stages.update()

    baseline_fit = fit_model(baseline.terms, baseline.noise_terms, data)
    if report_search:  # the compensator's search reads structure only, and cross-validation judges it
        _require_noise(baseline_fit, rec)
    stages.update()

    present = set(baseline.identifiers)
    candidates = [
        c for c in CANDIDATE_ORDER if c not in present and ident.get(c, None) and ident[c].identifiable
    ]
    scale = channel_scale(rec, data)
    flags = partial(_param_flags, scale=scale)

    def implausible_term(fit: ModelFit, index: int) -> bool:
        return bool(flags(_term_effect(fit, index)))

    selection = forward_select(
        baseline_fit,
        data,
        candidates,
        progress=progress,
        pairs=report_search,
        swap=report_search,
        implausible=implausible_term,
    )
    identifiable = {c for c in CANDIDATE_ORDER if ident.get(c) and ident[c].identifiable}
    resolve(selection, data, identifiable, progress=progress, implausible=implausible_term)
    # A report's search: an implausible term whose plausible confounder fits better in its place
    # gives way to it (the compensator's search offers such confounders to cross-validation instead).
    while report_search and (better := prefer_plausible(selection, data, identifiable, implausible_term)):
        selection = better
        resolve(selection, data, identifiable, progress=progress, implausible=implausible_term)
    stages.update()

    final = selection.final
    cov_final = noise_cov(final)
    # Both models at the same (reference) noise covariance: their BICs compare, and the baseline's
    # residual is not distorted by a noise fit that absorbed the missing effect.
    baseline_common = fit_model(baseline_fit.terms, final.noise.terms, data, gls=final.gls, refit_noise=False)
    before = summarise(baseline_common, profile, baseline_fit.noise_params(), own=baseline_fit)
    before.bic_common = baseline_common.bic
    after = summarise(final, profile, selection.final_ml.noise_params(), own=selection.final_ml)
    after.bic_common = final.bic

    left_out = _left_out(selection, data, profile, baseline_common, cov_final, before, flags)
    # An implausible best fit is not named: its plausible confounders are fitted in its place.
    left_out, implausible = resolve_implausible(selection, data, identifiable, left_out, flags)
    mismatch = locate_mismatch(baseline_common, data, profile, cov_final, before.allan)
    unexplained = locate_mismatch(final, data, profile, cov_final, after.allan)
    stages.update()

    not_identifiable = [
        NotIdentifiable(effect, info.reason, info.test)
        for effect, info in ident.items()
        if not info.identifiable
        and effect not in present
        and not DEFINITIONS[effect].finder.absent_when_unidentifiable
    ]
    tested = [Tested(t.effect, delta_bic=t.delta_bic, how=t.note) for t in selection.tested_first_round]
    ambiguous = _ambiguous(selection, implausible) + implausible
    said = {e.effect for e in left_out} | {x for a in ambiguous for x in a.effects}
    undetected = []
    for effect, info in ident.items():
        if info.identifiable and info.weak and effect in candidates:
            tested.append(Tested(effect, note=f"weakly identifiable: {info.reason}; {info.test}"))
            if (
                report_search
                and effect not in said
                and (limit := detection_limit(final, effect, info.reason, info.test, scale))
            ):
                undetected.append(limit)
    misses = near_misses(final, data, candidates, full=stopped_full(selection)) if report_search else []
    suggestive = listed_near_misses(misses, said, flags, final)
    not_supported = [
        NotSupported(cast(str, n["effect"]), cast(float, n["delta_bic"]), cast(str, n["reason"]))
        for n in baseline_support(baseline_common, data)
    ]
    augmented = augmented_config(user_sim, selection.final_ml, data, profile, rec)
    holdout = holdout_check(baseline_common, final, data, holdout_fraction) if holdout_fraction > 0 else None
    stages.update()
    stages.close()
    notes = []
    found = [e.effect for e in left_out]
    for identifier, definition in EFFECTS.items():  # shown by the recording, not kept by the fit
        unused_note = definition.finder.unused_note
        if unused_note is None or identifier in found or identifier in present:
            continue
        if note := unused_note(data):
            notes.append(note)
    return Diagnosis(
        source=rec.source,
        data=data,
        profile=profile,
        baseline=baseline,
        baseline_fit=baseline_common,
        baseline_effects=catalogue_effects(baseline_common),
        selection=selection,
        left_out=left_out,
        ambiguous=ambiguous,
        not_identifiable=not_identifiable,
        undetected=undetected,
        not_supported=not_supported,
        mismatch=mismatch,
        unexplained=unexplained,
        before=before,
        after=after,
        tested=tested,
        augmented=augmented,
        holdout=holdout,
        seconds=time.perf_counter() - started,
        notes=notes,
        suggestive=suggestive,
        channel=rec.meta.get("channel"),
        unit=channel_unit(rec),
        scale=scale,
    )


def listed_near_misses(
    misses: list[NearMiss],
    said: set[str],
    param_flags: Callable[[EffectConfig], list[str]],
    final: ModelFit,
) -> list[Suggestive]:
    """The near misses as the report lists them, one entry per instance (a pair of steps: both,
    with their joint evidence); an effect the report already names or lists as ambiguous is not
    repeated, unless the catalogue allows another instance of it (a second step). One below the
    criterion carries the effects of ``final`` it shares its signature with (:func:`shared_signatures`)."""
    out = []
    for miss in misses:
        if miss.effect in said and miss.effect not in MULTI_INSTANCE:
            continue
        shares = shared_signatures(final, miss.fit) if miss.delta_bic < THRESHOLD else ()
        indices = [k for k, term in enumerate(miss.fit.terms) if term.identifier == miss.effect]
        for index in indices[-miss.instances :]:
            effect = _term_effect(miss.fit, index)
            out.append(
                Suggestive(
                    miss.effect,
                    dict(effect.params),
                    miss.delta_bic,
                    param_flags(effect),
                    miss.instances,
                    shares,
                )
            )
    return out


def _ambiguous(selection: Selection, implausible: list[Ambiguity]) -> list[Ambiguity]:
    """The selection's confounded pairs, typed. An absorbed confounder of an implausible best fit
    that its ambiguity already lists (with its BIC in that fit's place) is not repeated."""
    listed = {(a.effects[0], other) for a in implausible for other in a.effects[1:]}
    out = []
    for a in selection.ambiguous:
        first, second = cast(list[str], a["effects"])
        if a.get("absorbed") and (first, second) in listed:
            continue
        out.append(
            Ambiguity(
                (first, second),
                cast(float, a["delta_bic"]),
                cast(str, a["preferred"]),
                cast(str, a["reason"]),
                absorbed=bool(a.get("absorbed")),
                moves=tuple(cast(list[tuple[str, str, float, float]], a.get("moves", []))),
                another=bool(a.get("another")),
                undetermined=bool(a.get("undetermined")),
            )
        )
    return out


def _left_out(
    selection: Selection,
    data: BlockData,
    profile: Profile,
    baseline_fit: ModelFit,
    cov: np.ndarray,
    before: FitSummary,
    param_flags: Callable[[EffectConfig], list[str]],
) -> list[LeftOut]:
    final = selection.final
    effects_by_index = {}
    catalogue = catalogue_effects(final)
    term_positions = [k for k, term in enumerate(final.terms) if term.identifier in EFFECT_PARAMETERS]
    for position, effect in zip(term_positions, catalogue, strict=True):
        effects_by_index[position] = effect
    noise_params = selection.final_ml.noise_params()
    out = []
    seen: dict[str, int] = {}
    indices = final_indices(selection)
    for step in selection.steps:
        occurrence = seen.get(step.effect, 0)
        seen[step.effect] = occurrence + 1
        index = indices[(step.effect, occurrence)]
        importance, reduced = selection.drop_one.get(
            (step.effect, occurrence), (step.delta_bic, baseline_fit)
        )
        where: list[Region | AllanWhere]
        peak_visible: float | None = None
        flags: list[str] = []
        if index is None:
            params = dict(noise_params.get(step.effect, {}))
            where = list(noise_where(step.effect, noise_params, data, profile, before.allan))
        else:
            effect = effects_by_index.get(index) or _term_effect(final, index)
            params = dict(effect.params)
            visible = final.prediction - reduced.prediction
            special = special_where(effect, data, profile, baseline_fit.residual, cov, step.evidence)
            if special is None:
                special = where_regions(visible, data, profile, baseline_fit.residual, cov)
            where = list(special)
            peak_visible = float(np.max(np.abs(visible)))
            flags = param_flags(effect)
        confounded = [a for a in selection.ambiguous if cast(list[str], a["effects"])[0] == step.effect]
        ambiguous_with = [
            cast(list[str], a["effects"])[1]
            for a in confounded
            if not a.get("absorbed") and not a.get("undetermined")
        ]
        absorbs = [cast(list[str], a["effects"])[1] for a in confounded if a.get("absorbed")]
        out.append(
            LeftOut(
                effect=step.effect,
                params=params,
                where=where,
                evidence=Evidence(step.delta_bic, importance, step.evidence),
                advice=ADVICE.get(step.effect, ""),
                peak_visible_mg=peak_visible,
                flags=flags,
                ambiguous_with=ambiguous_with,
                absorbs=absorbs,
            )
        )
    out.sort(key=lambda e: -e.evidence.delta_bic_when_dropped)
    return out


def _term_effect(fit: ModelFit, index: int) -> EffectConfig:
    """One model term as an effect with its catalogue parameters: a catalogue effect, or a noise
    term's deterministic trend (``rate_ramp``, which :func:`catalogue_effects` leaves out) reported
    like one."""
    term = fit.terms[index]
    return EffectConfig(
        term.identifier, catalogue_params(DEFINITIONS[term.identifier], term, fit.linear(index))
    )
