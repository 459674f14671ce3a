"""One plausibility rule, one story: `trainer fit --method physics` and `trainer diagnose` agree per effect."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from tests.methods.test_greybox import config
from trainer.cli import main
from trainer.data.recording_io import write_recording
from trainer.greybox.compensator import summary_lines, undetermined_terms
from trainer.greybox.fit import FittedPhysics
from trainer.greybox.structure import Structure, forced
from trainer.physics.catalogue import EFFECTS, PARAMETERS
from trainer.physics.catalogue.plausibility import implausible
from trainer.physics.catalogue.stress_relaxation import DEFINITION as CREEP
from trainer.physics.config import parse_config_text
from trainer.physics.effects import EffectConfig
from trainer.physics.simulate import simulate

_RANGE = PARAMETERS[(CREEP.identifier, "gain_mg_per_c")].plausible
assert _RANGE is not None
GAIN_RANGE: tuple[float, float] = _RANGE
GAIN = 10.0 * GAIN_RANGE[1]  # ten times the largest plausible creep gain
TAU_S = 3000.0  # a plausible creep time constant


def test_the_rule_is_the_catalogues_range() -> None:
    """Outside the catalogue's range is implausible, except an amplitude below it: the lower end of
    an amplitude's range is a typical size, not a physical limit (a quiet sensor shows less)."""
    lo, hi = GAIN_RANGE
    params = {"gain_mg_per_c": -0.5 * (lo + hi), "tau_s": TAU_S}  # |value| is judged: the sign is free
    assert implausible(CREEP.identifier, params) == {}
    for bad in (2.0 * hi, -2.0 * hi):
        why = implausible(CREEP.identifier, {**params, "gain_mg_per_c": bad})
        assert list(why) == ["gain_mg_per_c"] and f"{lo:g}..{hi:g}" in why["gain_mg_per_c"]
    assert implausible(CREEP.identifier, {**params, "gain_mg_per_c": 0.5 * lo}) == {}
    tau_range = PARAMETERS[(CREEP.identifier, "tau_s")].plausible
    assert tau_range is not None
    why = implausible(CREEP.identifier, {**params, "tau_s": 0.5 * tau_range[0]})
    assert list(why) == ["tau_s"] and f"{tau_range[0]:g}..{tau_range[1]:g}" in why["tau_s"]


def _fitted(
    compensated: tuple[str, ...], why: dict[str, tuple[str, ...]], rejected: dict[str, str]
) -> FittedPhysics:
    structure = Structure(tuple(EffectConfig(n, {}) for n in compensated), rejected=tuple(rejected.items()))
    return FittedPhysics((), (), {}, (), (), 0, 0.0, structure, why=why)


def test_an_effect_the_finder_rejects_is_dropped_even_when_the_refit_looks_plausible() -> None:
    rejected = {CREEP.identifier: "gain_mg_per_c = 0.5 is outside the catalogue's plausible 0.001..0.05"}
    fitted = _fitted((CREEP.identifier, "temp_rate"), {}, rejected)
    drop = undetermined_terms(fitted, rejected)
    assert list(drop) == [CREEP.identifier] and rejected[CREEP.identifier] in drop[CREEP.identifier]
    own: dict[str, tuple[str, ...]] = {
        "temp_rate": ("tau_s = 600 sits at the end of its search range 0..600",)
    }
    drop = undetermined_terms(replace(fitted, why=own), {})
    assert list(drop) == ["temp_rate"] and own["temp_rate"][0] in drop["temp_rate"]


def test_the_last_word_does_not_claim_the_run_determines_a_parameter_it_flags() -> None:
    """A structure the user forced keeps a parameter at its search bound or outside the plausible
    range (an automatic one drops it); its summary's last line then names it instead of saying that
    the compensator carries only what the run determines, which the warnings above it contradict."""
    report = {
        "structure": "forced: --effects hysteresis_offset",
        "effects": ["bias_poly", "hysteresis_offset"],
        "params": {"bias_poly": {"c0_mg": 0.0}, "hysteresis_offset": {"amp_mg": 11.4, "width_c": 60.3}},
        "std": {},
        "nuisance": [],
        "at_bound": [],
        "implausible": ["hysteresis_offset.width_c"],
        "notes": [],
        "dropped": {},
    }
    flagged = summary_lines(report)[-1]
    assert flagged.strip().startswith("compensates: bias_poly + hysteresis_offset")
    assert "does not determine hysteresis_offset.width_c" in flagged and "only physics" not in flagged
    determined = summary_lines({**report, "implausible": []})[-1]
    assert "only physics this run determines" in determined


def test_a_structure_fixed_by_auto_says_so_not_that_the_user_forced_it() -> None:
    """``--effects`` is the user's; ``physics-branch`` is auto's candidate with the same structure, and
    its summary names the candidate (it read "forced: --effects hysteresis_offset" though no one typed
    that option)."""
    from trainer.fitting import make_compensator
    from trainer.greybox.compensator import PhysicsCompensator
    from trainer.selection import candidate

    branch = candidate("physics-branch")
    model = make_compensator(branch.method, branch.options)
    assert isinstance(model, PhysicsCompensator) and model.forced is not None
    assert (
        forced(model.forced, model.given_by).how
        == "forced: hysteresis_offset (auto's candidate physics-branch)"
    )
    assert forced(("thermal_lag", "temp_rate")).how == "forced: --effects thermal_lag,temp_rate"


@pytest.mark.slow  # one diagnose and one physics fit: about 25 s of CPU
def test_fit_and_diagnose_give_the_same_verdict_per_effect(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    creep = f"[effects.{CREEP.identifier}]\ngain_mg_per_c = {GAIN}\ntau_s = {TAU_S}\n"
    rec_path = tmp_path / "creep.csv"
    write_recording(simulate(parse_config_text(config(creep, noise=True)), 5).without_truth(), rec_path)
    assert main(["diagnose", str(rec_path), "--holdout", "0", "--json", str(tmp_path / "d.json")]) == 0
    diagnosis = json.loads((tmp_path / "d.json").read_text())
    capsys.readouterr()
    assert main(["fit", "--method", "physics", str(rec_path), "-o", str(tmp_path / "m.pt")]) == 0
    fit_out = capsys.readouterr().out

    named = {e["effect"] for e in diagnosis["left_out"] if not e.get("flags")}
    called_implausible = {a["best_fit"]["effect"] for a in diagnosis["ambiguous"] if "best_fit" in a}
    called_implausible |= {e["effect"] for e in diagnosis["left_out"] if e.get("flags")}
    assert called_implausible == {CREEP.identifier}  # the case this test is about happened
    kept_line = next(line for line in fit_out.splitlines() if line.strip().startswith("compensates:"))
    kept = set(kept_line.split(":", 1)[1].split("(")[0].replace("+", " ").split())
    dropped = {
        line.split()[1].rstrip(":") for line in fit_out.splitlines() if line.strip().startswith("dropped ")
    }
    compensable = {k for k, d in EFFECTS.items() if d.compensable}
    for effect in compensable:
        if effect in called_implausible:
            assert effect not in kept, f"{effect}: diagnose calls it implausible, the fit keeps it"
        if effect in kept:
            assert effect not in dropped and effect not in called_implausible
        if effect in named:
            assert effect in kept or effect in dropped  # named by the finder: the fit says what it did
    # not carried, and said: dropped from the structure, or not added by the cross-validated stage
    assert CREEP.identifier in dropped or f"{CREEP.identifier} not added" in fit_out
    # one story: no line claims to keep what the model does not carry
    assert "the fit keeps" not in fit_out
    assert all(f"dropped {effect}" not in fit_out for effect in kept)
