"""trainer/physics/catalogue/streamed.py is the one list of streamed effects: a new one is its own unit
(a catalogue definition and a :class:`StreamedEffect`) plus one register() call. A throwaway
first-order effect, registered here only, is streamed by the physics compensator and carried by the
C export (one-channel and IMU modules) bit for bit as the golden model computes it."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np
import pytest

from codegen.export import export
from codegen.families.physics.quantise import QPhysics
from codegen.golden_select import golden_for
from codegen.hostbuild import find_compiler, load_module
from codegen.imu import export_imu, imu_golden, load_imu
from codegen.imu_verify import host_run
from codegen.quantize import ACCEL_PER_MG
from tests import testmodels as tm
from tests.golden_checks import assert_states_equal
from trainer.data.recording import Recording
from trainer.errors import UserError
from trainer.greybox.compensator import PhysicsCompensator
from trainer.greybox.stream import PhysicsStream
from trainer.physics import catalogue
from trainer.physics.catalogue import streamed, thermal_lag
from trainer.physics.catalogue.base import Effect, Param, Signals, sample_period
from trainer.physics.catalogue.bias_poly import polynomial
from trainer.physics.catalogue.streaming import (
    ADDITIVE,
    HI_BITS,
    FixedPoint,
    GoldenStep,
    IntSample,
    IntTerm,
    Sample,
    StateWord,
    StreamedEffect,
    lowpass_call,
    lowpass_constants,
    lowpass_int,
    lowpass_step,
)
from trainer.physics.effects import EffectConfig
from trainer.physics.thermal import lowpass

RATE_HZ = 10.0
NAME = "settle"
WORD = "settle_lp"
POLY = {"c0_mg": 0.3, "c1_mg_per_c": 0.12, "c2_mg_per_c2": 8e-4, "c3_mg_per_c3": -4e-6}
PARAMS = {"gain_mg_per_c": 0.05, "tau_s": 400.0}
LAG = {"tau_s": 90.0}


# ---- the throwaway effect's unit: a settling offset gain (T - LP(T, tau_s)) ----------------------
def _contribution(p: Mapping[str, float], s: Signals) -> np.ndarray:
    return p["gain_mg_per_c"] * (s.T_die - lowpass(s.T_die, p["tau_s"], sample_period(s.t)))


DEFINITION = Effect(
    identifier="test_settling",
    compensable=True,
    params=(Param("gain_mg_per_c", unit="mg/degC"), Param("tau_s", "positive", unit="s")),
    summary="gain * (T_die - LP(T_die, tau_s)) (a test's throwaway effect)",
    contribution=_contribution,
)


def _step(p: Mapping[str, float], lp: tuple[float, ...], v: dict[str, float], s: Sample) -> float:
    v[WORD] = lowpass_step(lp, v[WORD], s)
    return p["gain_mg_per_c"] * (s.T - v[WORD])


def _golden(q: IntTerm) -> GoldenStep:
    assert q.filter is not None and q.gain is not None
    lowpass, gain = lowpass_int(q.filter), q.gain.q

    def step(v: dict[str, int], s: IntSample) -> int:
        v[WORD] = y = lowpass(v[WORD], s)
        return (s.x - (y >> HI_BITS)) * gain

    return step


STREAMED = StreamedEffect(
    identifier=DEFINITION.identifier,
    phase=ADDITIVE,
    state=(WORD,),
    prepare=lambda p, dt_s: lowpass_constants(p["tau_s"], dt_s),
    step=_step,
    fixed=FixedPoint(
        name="settle",
        state=(StateWord(WORD, True, "test_settling: the settling filter S"),),
        golden=_golden,
        after_poly=lowpass_call(WORD) + f"    acc += (int64_t)(x - tdcp_hi(state->{WORD})) * ${{q}};\n",
        tau_s=lambda p: p["tau_s"],
        filter_name=DEFINITION.identifier,
        filter_doc="test_settling: the settling filter",
        gain_mg_per_c=lambda p: p["gain_mg_per_c"],
        gain_name=DEFINITION.identifier,
        difference_text="(T - S)",
    ),
)


@pytest.fixture
def settling(monkeypatch: pytest.MonkeyPatch) -> Iterator[StreamedEffect]:
    monkeypatch.setitem(catalogue.EFFECTS, DEFINITION.identifier, DEFINITION)
    entry = streamed.register(STREAMED)
    yield entry
    streamed.unregister(DEFINITION.identifier)


# ---- a recording and the models -----------------------------------------------------------------
def _recording() -> Recording:
    """A ramp up and down with a hold: 40 min at 10 Hz, -10 .. 50 degC."""
    n = int(2400 * RATE_HZ)
    t = np.arange(n) / RATE_HZ
    temp = np.interp(t, [0, 800, 1200, 2000, 2400], [-10.0, 50.0, 50.0, 0.0, 0.0])
    return Recording(
        {"time_s": t, "temp_c": temp, "accel_mg": np.zeros(n)}, {"sample_rate_hz": f"{RATE_HZ:g}"}, "settle"
    )


def _effects(with_settling: bool = True) -> dict[str, dict[str, float]]:
    effects = {catalogue.BACKBONE: POLY, thermal_lag.DEFINITION.identifier: LAG}
    return effects | ({DEFINITION.identifier: PARAMS} if with_settling else {})


def _checkpoint(rec: Recording, path: Path, *, with_settling: bool = True, channel: str = "") -> Path:
    checkpoint = tm.physics_checkpoint(rec, _effects(with_settling))
    if channel:
        checkpoint["train_stats"] |= {"channel": channel, "unit": "mg"}
    tm.save_checkpoint(checkpoint, path)
    return path


def _vectors(rec: Recording) -> tuple[np.ndarray, np.ndarray]:
    """int32 accel (1/16 ug) and temperature (mdegC) of the recording, plus excursions beyond its range."""
    temp = np.concatenate([rec.temp_c, np.linspace(0.0, 80.0, 600), np.linspace(80.0, -40.0, 600)])
    accel = np.round(16000 * 0.4 * np.sin(np.arange(temp.size) / 40.0)).astype(np.int32)
    return accel, np.round(temp * 1000).astype(np.int32)


def _needs_compiler() -> None:
    try:
        find_compiler(None)
    except UserError:
        pytest.skip("no C compiler")


# ---- the tests ------------------------------------------------------------------------------------
def test_the_compensator_streams_a_registered_effect(settling: StreamedEffect) -> None:
    rec = _recording()
    model = PhysicsCompensator()
    model.effects = tuple(EffectConfig(k, dict(v)) for k, v in _effects().items())
    model.temp_range_c = (float(rec.temp_c.min()), float(rec.temp_c.max()))
    dt = 1.0 / RATE_HZ
    stream = PhysicsStream(model.model, dt)
    streamed_mg = np.array([stream.step(float(T)) for T in rec.temp_c])
    # independent expectation: the catalogue's formulas written out on the whole run
    proof_mass = lowpass(rec.temp_c, LAG["tau_s"], dt)
    settle = PARAMS["gain_mg_per_c"] * (rec.temp_c - lowpass(rec.temp_c, PARAMS["tau_s"], dt))
    expected = polynomial(proof_mass, *POLY.values()) + settle
    assert np.max(np.abs(streamed_mg - expected)) < 1e-9
    assert np.max(np.abs(model.predict_drift(rec) - expected)) < 1e-9  # the batch formula agrees
    assert np.ptp(settle) > 0.5  # the effect shows: half a mg and more over the run


def test_the_c_export_carries_a_registered_effect_bit_exactly(
    settling: StreamedEffect, tmp_path: Path
) -> None:
    _needs_compiler()
    rec = _recording()
    loaded, _ = export(_checkpoint(rec, tmp_path / "m.pt"), tmp_path / "out", name=NAME)
    q = loaded.quantised
    assert isinstance(q, QPhysics) and [t.identifier for t in q.terms][-1] == DEFINITION.identifier
    assert f"state->{WORD} = tdcp_lowpass(" in (tmp_path / "out" / f"{NAME}.c").read_text()
    host = load_module(tmp_path / "out", NAME, flags=("-O1",))
    accel, temp = _vectors(rec)
    state, golden = host.new_state(), golden_for(q)
    c_out = host.run(state, accel, temp)
    np.testing.assert_array_equal(c_out, golden.run(accel, temp))
    assert_states_equal(host.read_state(state), golden.state())
    # the golden model is the float stream in fixed point (docs/codegen.md's 1e-3 mg budget) ...
    model = PhysicsCompensator()
    model.effects = tuple(EffectConfig(k, dict(v)) for k, v in _effects().items())
    model.temp_range_c = (float(rec.temp_c.min()), float(rec.temp_c.max()))
    stream = PhysicsStream(model.model, 1.0 / RATE_HZ)
    float_mg = np.array([stream.step(t / 1000.0) for t in temp.tolist()])
    golden_mg = (accel.astype(np.int64) - c_out) / ACCEL_PER_MG
    assert np.max(np.abs(golden_mg - float_mg)) < 1e-3
    # ... and the effect is in it: the same model without it differs by its size
    without, _ = export(_checkpoint(rec, tmp_path / "w.pt", with_settling=False), tmp_path / "w", name=NAME)
    other_mg = (accel.astype(np.int64) - golden_for(without.quantised).run(accel, temp)) / ACCEL_PER_MG
    assert np.max(np.abs(golden_mg - other_mg)) > 0.5


def test_the_imu_module_carries_a_registered_effect_bit_exactly(
    settling: StreamedEffect, tmp_path: Path
) -> None:
    _needs_compiler()
    rec = _recording()
    paths = [
        _checkpoint(rec, tmp_path / "x.pt", channel="accel0_x"),
        _checkpoint(rec, tmp_path / "y.pt", with_settling=False, channel="accel0_y"),
    ]
    export_imu(paths, tmp_path / "out", name="settleimu")
    header = (tmp_path / "out" / "settleimu.h").read_text()
    assert "settleimu_lowpass_t settle;" in header and f"int64_t {WORD};" in header
    imu = load_imu(paths)
    accel, temp = _vectors(rec)
    raw = np.column_stack([accel, -accel])
    out, flags, samples = host_run(tmp_path / "out", "settleimu", raw, temp[:, None], None, None)
    g_out, g_flags, g_samples = imu_golden(imu, raw, temp[:, None])
    np.testing.assert_array_equal(out, g_out)
    assert (flags, samples) == (g_flags, g_samples)
    drift_x, drift_y = raw[:, 0] - out[:, 0], raw[:, 1] - out[:, 1]
    assert np.max(np.abs(drift_x - drift_y)) > 0.5 * ACCEL_PER_MG  # x carries the effect, y not
