"""The physics golden model still reports every overflow the C's proofs rule out, wherever in a run it
happens: it checks its bounds on the values it recorded, block by block, not at every step, so a value
beyond its int32 / int64 bound at one sample (the first, one inside a later block, the last) must be
reported as the per-sample check did; a value at its bound is not. A throwaway term (patched into the
registry and into a quantised model) puts the value there."""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable

import numpy as np
import pytest

from codegen.export import load_for_codegen
from codegen.families.physics.golden import BLOCK, GoldenPhysics
from codegen.families.physics.quantise import QPhysics, QTerm
from codegen.fixedpoint import INT32_MAX, INT32_MIN
from tests import testmodels as tm
from trainer.data.recording import Recording
from trainer.physics.catalogue import streamed
from trainer.physics.catalogue.streaming import (
    ADDITIVE,
    HI_BITS,
    FixedPoint,
    GoldenStep,
    IntSample,
    IntTerm,
    StateWord,
    StreamedEffect,
)

RATE_HZ = 10.0
SPIKE = "test_spike"
WORD = "spike"
N = 2 * BLOCK + 100  # three blocks, the last a short one
AT = (0, BLOCK + 7, N - 1)  # where in the run the value is put


@pytest.fixture(scope="module")
def quantised(tmp_path_factory: pytest.TempPathFactory) -> QPhysics:
    """The test models' physics model with every term the C export carries, at 10 Hz over -10..50 degC."""
    t = np.arange(600) / RATE_HZ
    rec = Recording(
        {"time_s": t, "temp_c": np.linspace(-10.0, 50.0, t.size), "accel_mg": np.zeros(t.size)},
        {"sample_rate_hz": f"{RATE_HZ:g}"},
        "bounds",
    )
    path = tmp_path_factory.mktemp("bounds") / "m.pt"
    tm.save_checkpoint(tm.physics_checkpoint(rec), path)
    q = load_for_codegen(path).quantised
    assert isinstance(q, QPhysics) and len(q.terms) == 4
    return q


def _vectors() -> tuple[np.ndarray, np.ndarray]:
    """N samples: temperature ramps across the range and beyond it (mdegC), zero acceleration."""
    temp = np.round(1000 * (20.0 + 40.0 * np.sin(np.arange(N) / 3000.0))).astype(np.int64)
    return np.zeros(N, dtype=np.int64), temp


def _with_spike(
    monkeypatch: pytest.MonkeyPatch, q: QPhysics, wide: bool, at: int, word: int = 0, term: int = 0
) -> GoldenPhysics:
    """The model with one more term after the others: its state word (int64 filter state when
    ``wide``, else int32) follows x, except at sample ``at`` of the run where it is ``word`` (when
    not 0); its drift term is 0 except there, where it is ``term``."""

    samples = itertools.count()  # over the whole run (each chunk binds the step anew)

    def golden(_: IntTerm) -> GoldenStep:
        def step(v: dict[str, int], s: IntSample) -> int:
            here = next(samples) == at
            v[WORD] = word if here and word else (s.x << HI_BITS if wide else s.x)
            return term if here else 0

        return step

    effect = StreamedEffect(
        identifier=SPIKE,
        phase=ADDITIVE,
        state=(WORD,),
        prepare=lambda p, dt_s: (),
        step=lambda p, c, v, s: 0.0,
        fixed=FixedPoint(name=WORD, state=(StateWord(WORD, wide, "a test's spike"),), golden=golden),
    )
    monkeypatch.setitem(streamed.STREAMED, SPIKE, effect)
    model = dataclasses.replace(q, terms=(*q.terms, QTerm(SPIKE, None, None, None)))
    golden_model = GoldenPhysics(model)
    golden_model.init()
    return golden_model


def _run(golden: GoldenPhysics) -> np.ndarray:
    accel, temp = _vectors()
    return np.concatenate(
        [
            golden.run(accel[: BLOCK + 50], temp[: BLOCK + 50]),
            golden.run(accel[BLOCK + 50 :], temp[BLOCK + 50 :]),
        ]
    )


@pytest.mark.parametrize("at", AT)
@pytest.mark.parametrize(
    ("wide", "word", "match"),
    [
        (True, 1 << 62, "state word spike beyond its int64 bound"),
        (True, -(1 << 62), "state word spike beyond its int64 bound"),
        (True, 1 << 63, "beyond int64"),
        (False, INT32_MAX + 1, "state word spike beyond its int32 bound"),
        (False, INT32_MIN, "state word spike beyond its int32 bound"),
    ],
)
def test_a_state_word_beyond_its_bound_at_one_sample_is_reported(
    monkeypatch: pytest.MonkeyPatch, quantised: QPhysics, wide: bool, word: int, match: str, at: int
) -> None:
    with pytest.raises(AssertionError, match=match):
        _run(_with_spike(monkeypatch, quantised, wide, at, word=word))


@pytest.mark.parametrize("at", AT)
def test_a_drift_term_beyond_the_accumulator_bound_at_one_sample_is_reported(
    monkeypatch: pytest.MonkeyPatch, quantised: QPhysics, at: int
) -> None:
    beyond = quantised.bound + (quantised.horner_bounds[0] << HI_BITS) + 1  # whatever the cubic adds
    with pytest.raises(AssertionError, match="the drift accumulator beyond its bound"):
        _run(_with_spike(monkeypatch, quantised, True, at, term=beyond))
    with pytest.raises(AssertionError, match="beyond int64"):
        _run(_with_spike(monkeypatch, quantised, True, at, term=-(1 << 64)))


def test_values_at_their_bounds_are_taken_and_change_nothing_else(
    monkeypatch: pytest.MonkeyPatch, quantised: QPhysics
) -> None:
    """The checks are the C's bounds, not stricter: a word at its bound and a zero term run, and the
    output is the model's without the extra term (it adds nothing)."""
    plain = GoldenPhysics(quantised)
    plain.init()
    expected = _run(plain)
    runs: list[Callable[[], GoldenPhysics]] = [
        lambda: _with_spike(monkeypatch, quantised, True, BLOCK + 7, word=(1 << 62) - 1),
        lambda: _with_spike(monkeypatch, quantised, True, BLOCK + 7, word=-(1 << 62) + 1),
        lambda: _with_spike(monkeypatch, quantised, False, N - 1, word=INT32_MAX),
        lambda: _with_spike(monkeypatch, quantised, False, 0, word=-INT32_MAX),
    ]
    for make in runs:
        np.testing.assert_array_equal(_run(make()), expected)


def test_a_horner_step_beyond_int32_is_reported(quantised: QPhysics) -> None:
    """Coefficients whose cubic leaves int32 at the hot end of the range (a broken quantiser)."""
    broken = GoldenPhysics(dataclasses.replace(quantised, coefficients_q=(0, 0, INT32_MAX, INT32_MAX)))
    broken.init()
    with pytest.raises(AssertionError, match="a Horner step beyond int32"):
        _run(broken)
