"""The compensator structure the finder proposes names each effect once: a named effect that is
ambiguous with others is one term with its alternatives ("hysteresis (or thermal_lag)"), not the
effect and then the effect again (the bundled accel x with a rate term added read "temp_rate +
hysteresis + hysteresis (or thermal_lag)")."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any, cast

import numpy as np

from trainer.diagnose.next_steps import next_steps
from trainer.diagnose.result import Ambiguity, Diagnosis
from trainer.physics.effects import EffectConfig


def _diagnosis(
    named: list[str],
    ambiguous: list[Ambiguity],
    unit: str = "mg",
    profile: Any = None,
    simulated: tuple[list[str], list[str], list[str]] = ([], [], []),
) -> Diagnosis:
    """``simulated``: the --sim's effects, those the recording does not support, those calibrated
    implausibly."""
    effects, unsupported, implausible = simulated
    residual = SimpleNamespace(residual_block=np.zeros(4))
    bare = SimpleNamespace(
        branch=np.zeros(4, dtype=int),
        identifiability={},
        holds_after_ramp_s=0.0,
        ramp_rates=[1.0],
        reversals=0,
        known_input_varies=False,
    )
    fake: Any = SimpleNamespace(
        left_out=[SimpleNamespace(effect=e, peak_visible_mg=1.0) for e in named],
        ambiguous=ambiguous,
        before=residual,
        after=residual,
        profile=bare if profile is None else profile,
        not_identifiable=[],
        signal=SimpleNamespace(label=unit),
        baseline_effects=[EffectConfig(e, {}) for e in effects],
        not_supported=[SimpleNamespace(effect=e) for e in unsupported],
        implausible_baseline=lambda: [(EffectConfig(e, {}), ["outside"]) for e in implausible],
    )
    return cast(Diagnosis, fake)


def test_an_ambiguous_named_effect_is_one_term_with_its_alternatives() -> None:
    ambiguous = [
        Ambiguity(("hysteresis", "thermal_lag"), 13.3, "hysteresis", "r"),
        Ambiguity(("hysteresis", "stress_relaxation"), 4.0, "hysteresis", "r"),
        Ambiguity(("warmup", "temp_rate"), 2.0, "warmup", "r"),  # preferred but not named: added
    ]
    structure = next_steps(_diagnosis(["temp_rate", "hysteresis"], ambiguous)).structure
    terms = structure.split(": ", 1)[1].split(" + ")
    assert terms[1:] == [
        "temp_rate",
        "hysteresis (or thermal_lag / stress_relaxation)",
        "warmup (or temp_rate)",
    ]


def test_the_after_figure_says_when_it_includes_terms_the_compensator_does_not_carry() -> None:
    """The per-branch "after" is the finder's whole model: with a bias step (an event) in it, it is not
    what the compensator would leave, and the report and the terminal say so."""
    from trainer.diagnose.next_steps import markdown_lines, terminal_lines

    plain = next_steps(_diagnosis(["temp_rate"], []))
    assert plain.fit_only == [] and plain.after_text() == "what the compensator would leave"
    steps = next_steps(_diagnosis(["temp_rate", "bias_step"], []))
    assert steps.fit_only == ["bias_step"]
    for text in ("\n".join(markdown_lines(steps)), "\n".join(terminal_lines(steps))):
        assert "bias_step included, which the compensator does not carry" in text, text
    assert "what the compensator would leave" not in "\n".join(markdown_lines(steps))


def test_the_second_input_the_profile_asks_for_is_the_channel_s_own() -> None:
    """A gyroscope's next steps asked to flip the accelerometer (+1 g / -1 g): each channel's profile
    names the known second input of its own sensor, and only that one."""
    inputs = {"mg": "+1 g / -1 g", "deg/s": "rate table", "Pa": "second pressure"}
    for unit, wanted in inputs.items():
        generic = next_steps(_diagnosis(["temp_rate"], [], unit)).profile[-1]
        assert wanted in generic and not any(other in generic for other in inputs.values() if other != wanted)


def test_the_scale_factor_test_a_channel_is_told_is_its_own_sensor_s() -> None:
    """A gyroscope's diagnosis listed every sensor's second input (flip the accelerometer, a rate
    table, a second pressure) as the test that would identify its scale-factor tempco."""
    from trainer.diagnose.profile import in_unit
    from trainer.physics.catalogue.scale_factor_tc import DEFINITION

    rule = DEFINITION.finder.identifiability
    assert rule is not None
    written = {"s": rule(SimpleNamespace(known_input_varies=False))}  # type: ignore[arg-type]
    inputs = {"mg": "+1 g / -1 g", "dps": "rate table", "pa": "second pressure"}
    for unit, wanted in inputs.items():
        test = in_unit(written, unit)["s"].test
        assert wanted in test and not any(other in test for other in inputs.values() if other != wanted), test


def test_the_generic_profile_asks_only_for_what_the_run_lacks() -> None:
    """A run with 1.5 h holds after its ramps, two ramp rates and a reversal was told to add exactly
    those: the profile's own features decide which parts of the generic test are asked for."""

    def generic(**features: Any) -> str:
        run = dict(holds_after_ramp_s=0.0, ramp_rates=[1.0], reversals=0, known_input_varies=False)
        run.update(features)
        profile = SimpleNamespace(branch=np.zeros(4, dtype=int), identifiability={}, **run)
        return next_steps(_diagnosis(["temp_rate"], [], "mg", profile)).profile[-1]

    bare = generic()
    for wanted in ("holds of >= 1 h", "two ramp rates", "reversal", "+1 g / -1 g"):
        assert wanted in bare and "already" not in bare
    chamber = generic(holds_after_ramp_s=5400.0, ramp_rates=[0.5, 1.0], reversals=3)
    asked, had = chamber.split(" (this run already has ")
    assert "+1 g / -1 g" in asked and "holds" not in asked and "ramp rates" not in asked
    assert all(part in had for part in ("holds of >= 1 h", "two ramp rates", "reversal"))
    short_hold = generic(holds_after_ramp_s=1800.0, ramp_rates=[0.5, 1.0], reversals=3)
    assert short_hold.startswith("holds of >= 1 h")
    everything = generic(
        holds_after_ramp_s=5400.0, ramp_rates=[0.5, 1.0], reversals=1, known_input_varies=True
    )
    assert everything.startswith("this run already has") and "second run" in everything


def test_the_simulations_own_supported_effects_are_terms_of_the_compensator() -> None:
    """With --sim holding the lag, the rate term and the branch offset, all calibrated, nothing is
    left out and the advice said the bias polynomial alone: the simulation's compensable effects that
    the recording supports, calibrated plausibly, are terms; an unsupported or implausible one and an
    event (a step) are not."""
    sim = (
        ["thermal_lag", "temp_rate", "hysteresis_offset", "bias_step"],
        ["temp_rate"],
        ["hysteresis_offset"],
    )
    structure = next_steps(_diagnosis(["periodic"], [], simulated=sim)).structure
    terms = structure.split(": ", 1)[1].split(" + ")
    assert terms == ["bias_poly (bias polynomial) in the lagged (proof-mass) temperature", "thermal_lag"], (
        terms
    )
    alone = next_steps(_diagnosis([], [])).structure.split(": ", 1)[1].split(" + ")
    assert alone == ["bias_poly (bias polynomial) in the die temperature"]
