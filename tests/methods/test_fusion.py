"""The fusion algorithm end to end on a short drift, and the DLSTM checkpoints."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
import torch

from trainer.checkpoint import load_model, save_model
from trainer.data.recording import Recording
from trainer.dlstm.compensators import RecursiveDLSTMWithISSA, TemperatureDLSTM
from trainer.dlstm.fusion import FusionSettings, as_batch, refine_stage, train_stage
from trainer.dlstm.network import PopulationDLSTM
from trainer.dlstm.train import population_loss
from trainer.train_stats import TrainStats


def _drift_pairs(steps: int = 300) -> tuple[np.ndarray, np.ndarray]:
    t = np.linspace(0.0, 1.0, steps + 1)
    u = 1.0 - np.exp(-t / 0.3) + 0.5 * t**2
    u = (u - u.mean()) / u.std()
    return u[:-1].reshape(-1, 1), u[1:]


@pytest.mark.parametrize("optimiser", ["ssa", "issa"])
def test_fusion_improves_on_its_starting_population(optimiser: str) -> None:
    x, y = _drift_pairs()
    settings = FusionSettings(population=4, iterations=40, cycles=15, seed=3)
    start = PopulationDLSTM(4, 1, seed=3)
    xb, yb = as_batch(x, y)
    with torch.no_grad():
        initial = population_loss(start, xb, yb).numpy()
    trained = train_stage(x, y, settings, progress=False)
    result = refine_stage(trained, x, y, settings, optimiser, progress=False)
    assert result.best_loss < 0.2 * initial.min()
    # The optimiser keeps the best so far: never worse than the best gradient-trained network.
    assert result.best_loss <= min(result.population_loss_before) * (1 + 1e-6)
    assert len(result.optimiser_history) == settings.cycles + 1
    assert all(b <= a * (1 + 1e-6) for a, b in itertools.pairwise(result.optimiser_history))


def test_fusion_is_deterministic_per_seed() -> None:
    x, y = _drift_pairs(120)
    settings = FusionSettings(population=3, iterations=10, cycles=5, seed=9)
    runs = [
        refine_stage(train_stage(x, y, settings, progress=False), x, y, settings, "issa", progress=False)
        for _ in range(2)
    ]
    for key in runs[0].weights:
        assert torch.equal(runs[0].weights[key], runs[1].weights[key])


def _short_recording(seed: int) -> Recording:
    rng = np.random.default_rng(seed)
    t = np.arange(12_000) / 50.0
    temp = 20.0 + 10.0 * t / t[-1]
    accel = 0.3 * temp + rng.normal(0, 0.2, t.size)
    return Recording({"time_s": t, "temp_c": temp, "accel_mg": accel}, {"sample_rate_hz": "50"}, "short")


@pytest.mark.parametrize("cls", [RecursiveDLSTMWithISSA, TemperatureDLSTM])
def test_dlstm_checkpoint_round_trip(cls: type, tmp_path: Path) -> None:
    rec = _short_recording(0)
    model = cls(settings=FusionSettings(population=2, iterations=5, cycles=3), progress=False).fit(rec)
    path = tmp_path / "model.pt"
    save_model(model, path, train_stats=TrainStats(), valid_temp_range_c=(20.0, 30.0))
    raw = torch.load(path, weights_only=True)
    assert raw["payload"]["frontend"]["kind"] == cls.kind
    assert raw["payload"]["architecture"] == {
        "input_size": 1 if cls.kind == "recursive" else 2,
        "hidden_size": 10,
        "num_layers": 2,
        "output_size": 1,
        "gate_order": "ifgo",
    }
    loaded, _ = load_model(path)
    other = _short_recording(1)
    np.testing.assert_allclose(loaded.predict_drift(other), model.predict_drift(other), rtol=0, atol=1e-12)
