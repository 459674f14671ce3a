"""``--method auto``'s rule on hand-made cross-validation tables: what a user meets, one held-out
segment at a time, and no shape judged on less than a cycle."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trainer import methods
from trainer.data.recording import Recording
from trainer.scoring.crossval import (
    UNCOMPENSATED,
    CrossValidation,
    FoldScore,
    MethodCV,
    Segment,
    folds_of,
    own_run_figures,
)
from trainer.scoring.verdict import NOISE_MARGIN, REVIEW, verdict, worse_on_a_segment
from trainer.selection import (
    FULL_CYCLE_SEGMENTS,
    NONE,
    POOLED_GAIN,
    TOLERANCE,
    Selection,
    choose,
    cross_validated_figures,
    full_cycle,
    own_run_failure,
    record_lines,
    select,
    selection_record,
    worst_ratio,
)

CYCLE = ("cooling", "heating", "cooling")  # the bundled real run's segments


def table(labels: tuple[str, ...], figures: dict[str, list[float]]) -> CrossValidation:
    """A cross-validation whose held-out figures (warm = cold, one per segment) are ``figures``."""
    segments = [Segment(i * 100, (i + 1) * 100, label, 0.0, 0.0, 0.0, 0.0) for i, label in enumerate(labels)]
    results = {
        name: MethodCV(
            name,
            [FoldScore(v, v, v, v, 1.0) for v in values],
            [s.start == 0 for s in segments],
            [s.stop - s.start for s in segments],
        )
        for name, values in figures.items()
    }
    return CrossValidation("run", "mg", segments, results)


def cv_of(figures: dict[str, list[float]], name: str) -> float:
    return table(CYCLE, figures).results[name].cv_rms


def test_on_a_cycle_a_candidate_that_wins_on_average_but_loses_one_segment_is_not_chosen() -> None:
    figures = {
        UNCOMPENSATED: [10.0, 10.0, 10.0],
        "poly2": [1.2, 1.2, 1.2],
        methods.CUBIC: [1.0, 1.0, 1.0],
        methods.PLA: [0.2, 0.2, 1.5],  # pooled 0.88: the lowest, but 1.5x the cubic on the last segment
    }
    cv = table(CYCLE, figures)
    assert cv.results[methods.PLA].cv_rms < cv.results[methods.CUBIC].cv_rms  # the old rule's choice
    assert worst_ratio(cv, methods.PLA) == pytest.approx(1.5)
    assert choose(cv)[0] == methods.CUBIC
    figures[methods.PLA] = [
        0.99,
        0.99,
        1.0 + TOLERANCE / 2,
    ]  # as safe, and pooled within 2 %: the simpler cubic
    assert choose(table(CYCLE, figures))[0] == methods.CUBIC
    figures[methods.PLA] = [0.9, 0.9, 1.0 + TOLERANCE / 2]  # as safe, 6 % less pooled: within chance
    assert cv_of(figures, methods.PLA) > (1.0 - POOLED_GAIN) * cv_of(figures, methods.CUBIC)
    assert choose(table(CYCLE, figures))[0] == methods.CUBIC
    figures[methods.PLA] = [0.2, 0.2, 1.0 + TOLERANCE / 2]  # as safe, and far less pooled
    assert choose(table(CYCLE, figures))[0] == methods.PLA
    figures[methods.PLA][2] = 0.9  # better than the cubic on every segment
    label, reason = choose(table(CYCLE, figures))
    assert label == methods.PLA and "at worst 0.9x" in reason and "least drift" in reason


def test_segments_where_every_candidate_ties_do_not_keep_the_cubic() -> None:
    """A run with dwells: on a dwell every model leaves the noise, so every worst ratio is 1 there; the
    one that leaves far less on the ramps is chosen (the realistic experiment's gyroscope)."""
    dwell_cycle = ("dwell", "heating", "dwell", "cooling", "dwell")
    figures = {
        UNCOMPENSATED: [0.013, 0.33, 0.03, 0.32, 0.022],
        methods.CUBIC: [0.013, 0.096, 0.027, 0.096, 0.020],
        methods.PHYSICS: [0.013, 0.0133, 0.0131, 0.0133, 0.0132],
        "poly2": [0.013, 0.16, 0.026, 0.12, 0.020],
    }
    cv = table(dwell_cycle, figures)
    assert worst_ratio(cv, methods.PHYSICS) == pytest.approx(1.0) == worst_ratio(cv, methods.CUBIC)
    assert choose(cv)[0] == methods.PHYSICS


def test_the_reference_is_the_better_of_cubic_and_none_on_each_segment() -> None:
    figures = {
        UNCOMPENSATED: [0.1, 5.0, 0.1],  # nothing to remove on the coolings, a drift on the heating
        methods.CUBIC: [0.3, 1.0, 0.3],
        "poly2": [0.1, 1.0, 0.3],
    }
    cv = table(CYCLE, figures)
    assert worst_ratio(cv, methods.CUBIC) == pytest.approx(3.0)
    assert worst_ratio(cv, NONE) == pytest.approx(5.0)
    assert worst_ratio(cv, "poly2") == pytest.approx(3.0)
    assert choose(cv)[0] == "poly2"  # as good as the cubic at its worst, and simpler


def test_on_less_than_a_cycle_only_the_cubic_or_none_is_chosen() -> None:
    figures = {UNCOMPENSATED: [4.0, 4.0], methods.CUBIC: [1.0, 1.0], methods.PLA: [0.5, 0.5]}
    two = table(("cooling", "heating"), figures)
    assert not full_cycle(two.segments) and len(two.segments) < FULL_CYCLE_SEGMENTS
    label, reason = choose(two)
    assert label == methods.CUBIC and "less than a cycle" in reason
    assert "1 cooling and 1 heating segment" in reason and "a branch it was not trained on" in reason
    ramp_thirds = table(
        ("cooling 1/3", "cooling 2/3", "cooling 3/3"), {k: [*v, v[0]] for k, v in figures.items()}
    )
    assert not full_cycle(ramp_thirds.segments)  # three parts of one ramp are not a cycle
    label, reason = choose(ramp_thirds)
    assert label == methods.CUBIC  # and the reason says why three segments are not a cycle
    assert "does not reverse (cooling only; its 3 folds are parts of its temperature span)" in reason
    assert "beyond the range it was trained on" in reason
    figures[methods.CUBIC] = [5.0, 4.5]  # the cubic leaves more than no compensation pooled
    assert choose(table(("cooling", "heating"), figures))[0] == NONE


def test_never_a_choice_that_leaves_more_than_no_compensation_pooled() -> None:
    # the best worst-ratio candidate still leaves more than no compensation pooled
    figures = {UNCOMPENSATED: [1.0, 1.0, 9.0], methods.CUBIC: [9.0, 9.0, 9.5], methods.PLA: [3.0, 3.0, 9.0]}
    cv = table(CYCLE, figures)
    assert worst_ratio(cv, methods.PLA) == pytest.approx(3.0) and worst_ratio(cv, NONE) == pytest.approx(1.0)
    assert choose(cv)[0] == NONE
    # the worst ratio's reference names what was tried: without the cubic it is no compensation alone
    without_cubic = table(CYCLE, {UNCOMPENSATED: [4.0, 4.0, 4.0], methods.PLA: [2.0, 3.0, 1.0]})
    label, reason = choose(without_cubic)
    assert (
        label == methods.PLA
        and "at worst 0.75x uncompensated (the cubic is not among --candidates)" in reason
    )
    assert "better of (cubic" not in reason
    flat = {UNCOMPENSATED: [1.0, 1.0, 1.0], methods.CUBIC: [1.01, 0.99, 1.03]}
    label, reason = choose(table(CYCLE, flat))
    assert (
        label == NONE
        and "left uncompensated" in reason
        and not math.isnan(worst_ratio(table(CYCLE, flat), NONE))
    )


def test_select_on_less_than_a_cycle_judges_only_the_cubic_and_none() -> None:
    rate_hz = 2.0
    temp = np.concatenate([np.linspace(50.0, -10.0, 2400), np.linspace(-10.0, 60.0, 2800)])  # cool, heat
    d = temp - 25.0
    rng = np.random.default_rng(7)
    columns = {
        "time_s": np.arange(temp.size) / rate_hz,
        "temp_c": temp,
        "accel_mg": 0.2 * d + 4e-3 * d**2 + rng.normal(0.0, 0.05, temp.size),
    }
    rec = Recording(columns, {"sample_rate_hz": str(rate_hz)}, "two-ramps")
    selection = select(rec, labels=("none", "poly2", methods.CUBIC, methods.PLA))
    assert [s.label for s in selection.cv.segments] == ["cooling", "heating"]
    assert set(selection.cv.results) == {UNCOMPENSATED, methods.CUBIC}
    assert set(selection.cv.skipped) == {"poly2", methods.PLA}
    assert selection.chosen == methods.CUBIC  # the drift is real: the cubic beats no compensation
    lines = record_lines(selection_record(selection))
    assert sum("not judged" in line for line in lines) == 1  # one line for both, with the reason
    assert any(line.startswith("- poly2, pla: not judged") for line in lines)
    assert "auto keeps to the cubic unless" in selection.reason
    # without the cubic among the candidates the reason does not claim to keep to it
    narrowed = select(rec, labels=("none", "pla"))
    assert narrowed.chosen == "none" and "the cubic is not among --candidates" in narrowed.reason
    assert "keeps to the cubic" not in narrowed.reason


def test_a_candidate_worse_than_none_inside_the_training_range_is_never_chosen() -> None:
    figures = {UNCOMPENSATED: [4.0, 4.0], methods.CUBIC: [1.0, 1.0]}
    cv = table(("cooling", "heating"), figures)
    assert choose(cv)[0] == methods.CUBIC
    # the same whole-segment figures, but inside the training range the cubic leaves more than none
    cubic = cv.results[methods.CUBIC]
    cubic.folds = [FoldScore(1.0, 1.0, 5.0, 5.0, 0.5) for _ in cubic.folds]
    assert cubic.cv_rms < cv.results[UNCOMPENSATED].cv_rms < cubic.cv_in_range_rms
    label, reason = choose(cv)
    assert label == NONE and "poly3 left more than no compensation" in reason
    # the figure that refused it, which the table does not show, with both values
    assert "inside the training range (5 against 4; 1 against 4 over the whole segments)" in reason


def test_a_flat_channel_is_left_uncompensated_without_dividing_by_zero() -> None:
    # a stuck or perfectly quiet channel: every segment's uncompensated drift left is exactly 0
    figures = {UNCOMPENSATED: [0.0, 0.0, 0.0], methods.CUBIC: [0.0, 0.0, 0.1], "poly2": [0.0, 0.0, 0.0]}
    cv = table(CYCLE, figures)
    assert worst_ratio(cv, methods.CUBIC) == math.inf and worst_ratio(cv, "poly2") == 1.0
    assert choose(cv)[0] == NONE


def test_a_model_better_pooled_but_worse_on_one_segment_asks_for_a_review() -> None:
    """The bundled run's gyro x: poly2 leaves less than none pooled but 1.86x none on the last
    cooling; the sign-off's guard passes it (pooled) and the review reason names that segment."""
    figures = {UNCOMPENSATED: [0.1571, 0.3304, 0.1064], "poly2": [0.1375, 0.1667, 0.1983]}
    cv = table(CYCLE, figures)
    record = {"chosen": "poly2", "crossval": cv.to_dict()}
    pooled = cross_validated_figures(record)
    assert pooled.model < pooled.uncompensated  # the guard's figure: better
    assert [s.model_rms for s in pooled.per_segment] == figures["poly2"]
    reason = worse_on_a_segment("gyro0_x / poly2", pooled.per_segment, 0.014, "deg/s")
    assert reason is not None and cv.segments[2].name in reason and f"{0.1983 / 0.1064:.2f}x" in reason
    # none worse: no reason; worse only within the noise margin of the floor: no reason either
    assert worse_on_a_segment("x", pooled.per_segment[:2], 0.014, "deg/s") is None
    assert worse_on_a_segment("x", pooled.per_segment, 0.1983 / NOISE_MARGIN, "deg/s") is None
    assert verdict({}, [_Passed()], [reason]).status == REVIEW


class _Passed:
    ok = True
    decisive = True
    name = "a threshold met"


def test_a_candidate_refused_on_its_own_run_is_not_chosen_and_the_reason_says_why() -> None:
    figures = {
        UNCOMPENSATED: [10.0, 10.0, 10.0],
        methods.CUBIC: [1.0, 1.0, 1.0],
        methods.PLA: [0.2, 0.2, 0.9],
    }
    assert choose(table(CYCLE, figures))[0] == methods.PLA
    label, reason = choose(table(CYCLE, figures), {methods.PLA: "pla fitted on the whole run left more"})
    assert label == methods.CUBIC and reason.count("pla fitted on the whole run left more") == 1


def test_a_fit_of_the_whole_run_that_loses_to_none_on_a_segment_of_it_is_refused() -> None:
    """Cross-validation scores the folds' fits; the model shipped is fitted on the whole run, where
    the physics finder can choose another structure (the bundled run's gyro z): it must not leave
    more than no compensation on any segment of the run it was fitted on."""
    rate_hz = 2.0
    temp = np.concatenate(
        [np.linspace(50.0, -10.0, 2400), np.linspace(-10.0, 60.0, 2800), np.linspace(60.0, 20.0, 1600)]
    )
    drift = 0.2 * (temp - 25.0)
    rng = np.random.default_rng(3)
    columns = {
        "time_s": np.arange(temp.size) / rate_hz,
        "temp_c": temp,
        "accel_mg": drift + rng.normal(0, 0.05, temp.size),
    }
    rec = Recording(columns, {"sample_rate_hz": str(rate_hz)}, "cycle")
    segments = folds_of(rec)
    assert [x.label for x in segments] == list(CYCLE)
    results = {
        UNCOMPENSATED: MethodCV(
            UNCOMPENSATED, [FoldScore(1, 1, 1, 1, 1)] * 3, [True, False, False], [1, 1, 1]
        )
    }
    selection = Selection(CrossValidation("cycle", "mg", segments, results), methods.PLA, "")
    assert own_run_failure(selection, drift, rec, 0.5) is None  # it removes the drift everywhere
    wrong = drift.copy()
    second = segments[1]
    wrong[second.start : second.stop] *= -1.0  # twice the drift left on the heating
    why = own_run_failure(selection, wrong, rec, 0.5)
    assert why is not None and why.startswith("pla fitted on the whole run") and second.name in why
    assert (
        own_run_failure(Selection(selection.cv, NONE, ""), wrong, rec, 0.5) is None
    )  # none is never refused
    # right within each segment, but a level moved between them: each segment about its own constant
    # cannot see it, the run about its one constant does
    moved = drift.copy()
    moved[second.start :] -= 30.0
    per_segment = own_run_figures(rec, moved, segments, 0.5)[: len(segments)]
    none_per_segment = own_run_figures(rec, np.zeros(len(rec)), segments, 0.5)[: len(segments)]
    assert all(m < r for (_, m), (_, r) in zip(per_segment, none_per_segment, strict=True))
    why = own_run_failure(selection, moved, rec, 0.5)
    assert why is not None and "about its one constant" in why, why
