"""A cross-validation fold's held-out rows are run through but never learned (temperature-input DLSTM).

The fold gives a stateful method the whole temperature history, with the held-out output imputed
(:func:`trainer.scoring.crossval.impute_held_out`). Before, the network learned the imputed values as
targets, and its cross-validated figure could differ from ``--holdout``'s on the same rows.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from trainer.data.recording import HELD_OUT_COLUMN, Recording
from trainer.dlstm.compensators import TemperatureDLSTM
from trainer.dlstm.fusion import FusionSettings
from trainer.dlstm.train import per_individual_loss


@pytest.mark.parametrize("loss", ["mse", "half_mse", "mae"])
def test_a_nan_target_is_not_scored(loss: str) -> None:
    gen = torch.Generator().manual_seed(1)
    y = torch.randn(3, 1, 20, 1, generator=gen, dtype=torch.float64, requires_grad=True)
    targets = torch.randn(1, 20, 1, generator=gen, dtype=torch.float64)
    missing = torch.zeros(20, dtype=torch.bool)
    missing[[0, 5, 6, 19]] = True
    with_gaps = targets.clone()
    with_gaps[0, missing, 0] = float("nan")

    got = per_individual_loss(y, with_gaps, loss)  # type: ignore[arg-type]

    kept = ~missing
    expected = per_individual_loss(y[:, :, kept], targets[:, kept], loss)  # type: ignore[arg-type]
    torch.testing.assert_close(got, expected)
    got.sum().backward()
    assert y.grad is not None
    assert torch.isfinite(y.grad).all()
    assert torch.all(y.grad[:, 0, missing, 0] == 0)


def _fold(filler_mg: float, *, marked: bool) -> Recording:
    """A 1 Hz cycle whose samples 200..349 are held out and filled with ``filler_mg``."""
    t = np.arange(600, dtype=np.float64)
    temp = 25.0 + 30.0 * np.sin(2 * np.pi * t / 600.0)
    drift = 0.02 * (temp - 25.0) ** 2
    held = (t >= 200) & (t < 350)
    columns = {"time_s": t, "temp_c": temp, "accel_mg": np.where(held, filler_mg, drift)}
    if marked:
        columns[HELD_OUT_COLUMN] = held.astype(np.float64)
    return Recording(columns, {"sample_rate_hz": "1.0"}, "fold")


def _fitted(rec: Recording) -> TemperatureDLSTM:
    settings = FusionSettings(population=2, hidden_size=4, num_layers=1, iterations=5, seed=3)
    return TemperatureDLSTM(settings=settings, progress=False).fit(rec)


def _same(a: TemperatureDLSTM, b: TemperatureDLSTM) -> bool:
    """Equal to rounding: the trailing mean of the targets is a running sum, whose rounding the filler's
    size reaches (1e-12 mg here)."""
    assert a.output_norm is not None and b.output_norm is not None
    norms = np.allclose(
        a.output_norm.mean + a.output_norm.std, b.output_norm.mean + b.output_norm.std, rtol=1e-9
    )
    return norms and all(torch.allclose(a.weights[k], b.weights[k], rtol=1e-6, atol=1e-7) for k in a.weights)


def test_the_held_out_rows_values_do_not_change_the_fit() -> None:
    assert _same(_fitted(_fold(0.0, marked=True)), _fitted(_fold(50.0, marked=True)))
    # the premise: the same rows, not marked as held out, are learned
    assert not _same(_fitted(_fold(0.0, marked=False)), _fitted(_fold(50.0, marked=False)))
