"""The DLSTM compensators' vectorised run equals a literal sample-by-sample stream (docs/realtime.md)."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest
import torch

from trainer.data.recording import Recording
from trainer.dlstm.compensators import Persistence, RecursiveDLSTM, TemperatureDLSTM
from trainer.dlstm.fusion import FusionSettings
from trainer.dlstm.network import PopulationDLSTM
from trainer.dlstm.realtime import FrontEnd, hold, temperature_steps
from trainer.errors import UserError

RATE = 50.0


def _recording(seconds: float = 240.0, seed: int = 0, rate: float = RATE) -> Recording:
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * rate)) / rate
    temp = -10.0 + 0.5 * t / 60.0 * 60.0 / 10.0 + rng.normal(0, 0.05, t.size)  # 3 degC/min ramp
    drift = 0.2 * (temp - 25.0) + 0.002 * (temp - 25.0) ** 2
    accel = drift + rng.normal(0, 0.3, t.size)
    return Recording(
        {"time_s": t, "temp_c": temp, "accel_mg": accel, "true_drift_mg": drift},
        {"sample_rate_hz": str(rate)},
        "synthetic.npz",
    )


def _stream(model: RecursiveDLSTM | TemperatureDLSTM, rec: Recording) -> np.ndarray:
    """A literal per-sample implementation of docs/realtime.md, written independently."""
    fe = model.frontend
    net = PopulationDLSTM.from_individuals(
        [{k: v.double() for k, v in model.weights.items()}], dtype=torch.float64
    )
    accel_window: deque[float] = deque(maxlen=fe.accel_window)
    temp_window: deque[float] = deque(maxlen=fe.temp_window)
    state = None
    held = 0.0
    previous_temp = None
    out = np.empty(len(rec))
    for n, (a, temp) in enumerate(zip(rec.accel_mg, rec.temp_c, strict=True)):
        accel_window.append(a)
        temp_window.append(temp)
        sa = sum(accel_window) / len(accel_window)
        st = sum(temp_window) / len(temp_window)
        if n % fe.decimation == 0:
            if model.kind == "recursive":
                x = [(sa - model.inputs_norm.mean[0]) / model.inputs_norm.std[0]]
            else:
                rate = (
                    0.0 if previous_temp is None else (st - previous_temp) * 60.0 * fe.rate_hz / fe.decimation
                )
                previous_temp = st
                x = [
                    (st - model.inputs_norm.mean[0]) / model.inputs_norm.std[0],
                    (rate - model.inputs_norm.mean[1]) / model.inputs_norm.std[1],
                ]
            y, state = net.step(torch.tensor([[x]], dtype=torch.float64).reshape(1, 1, -1), state)
            held = float(y.detach().reshape(-1)[0]) * model.output_norm.std[0] + model.output_norm.mean[0]
        out[n] = a - held
    return out


@pytest.fixture(scope="module")
def small_settings() -> FusionSettings:
    return FusionSettings(population=3, iterations=25, cycles=5, seed=4)


@pytest.mark.parametrize("cls", [RecursiveDLSTM, TemperatureDLSTM])
def test_vectorised_run_equals_a_literal_stream(cls: type, small_settings: FusionSettings) -> None:
    train, valid = _recording(seed=1), _recording(seed=2)
    model = cls(
        settings=small_settings, frontend_seconds={"step_s": 1.0, "run_smoothing_s": 0.5}, progress=False
    )
    model.fit(train.without_truth())
    np.testing.assert_allclose(model.compensate(valid.without_truth()), _stream(model, valid), atol=1e-9)


def test_hold_applies_each_estimate_to_its_block() -> None:
    held = hold(np.array([1.0, 2.0, 3.0]), 7, 3)
    assert held.tolist() == [1, 1, 1, 2, 2, 2, 3]


def test_temperature_rate_is_in_degrees_per_minute() -> None:
    fe = FrontEnd.from_seconds(10.0, temp_smoothing_s=0.1, step_s=1.0)  # window of 1 sample
    t = np.arange(600) / 10.0
    temp_k, rate_k = temperature_steps(2.0 * t / 60.0, fe)  # 2 degC/min
    assert rate_k[0] == 0.0
    np.testing.assert_allclose(rate_k[1:], 2.0, rtol=1e-9)
    np.testing.assert_allclose(temp_k, 2.0 * t[::10] / 60.0)


def test_persistence_subtracts_the_last_smoothed_output() -> None:
    rec = _recording(60.0)
    model = Persistence({"run_smoothing_s": 0.2, "step_s": 1.0}).fit(rec)
    fe = model.frontend
    drift = model.predict_drift(rec)
    for n in (0, 49, 50, 51, 1234):
        k = (n // fe.decimation) * fe.decimation
        window = rec.accel_mg[max(0, k - fe.accel_window + 1) : k + 1]
        assert drift[n] == pytest.approx(window.mean())


def test_a_recording_at_another_rate_is_refused(small_settings: FusionSettings) -> None:
    model = RecursiveDLSTM(settings=small_settings, progress=False).fit(_recording().without_truth())
    with pytest.raises(UserError, match="trained at 50 Hz"):
        model.predict_drift(_recording(rate=100.0))


def test_too_short_a_recording_is_refused(small_settings: FusionSettings) -> None:
    with pytest.raises(UserError, match="network steps"):
        RecursiveDLSTM(settings=small_settings, progress=False).fit(_recording(seconds=5.0))
