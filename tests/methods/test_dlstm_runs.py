"""The DLSTM compensators' network runs are kept by content (trainer/dlstm/compensators.py):
a repeated run gives a fresh run's bits without running the network again, and any change of a
weight or an input runs it again."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from trainer.dlstm import compensators
from trainer.dlstm.network import PopulationDLSTM


@pytest.fixture
def runs(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Counts the networks built by run_network, with an empty store of kept runs."""
    monkeypatch.setattr(compensators, "network_runs", type(compensators.network_runs)())
    built: list[int] = []
    original = PopulationDLSTM.from_individuals

    def counting(*args: object, **kwargs: object) -> PopulationDLSTM:
        built.append(1)
        return original(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(compensators.PopulationDLSTM, "from_individuals", counting)
    return built


def _weights(seed: int) -> dict[str, torch.Tensor]:
    return PopulationDLSTM(1, 1, seed=seed).individual(0)


def test_a_repeated_run_is_the_fresh_run_without_running_again(runs: list[int]) -> None:
    weights, inputs = _weights(3), np.sin(np.linspace(0.0, 6.0, 200)).reshape(-1, 1)
    first = compensators.run_network(weights, inputs)
    first[:] = np.nan  # a caller's change of its copy does not reach the kept run
    again = compensators.run_network(weights, inputs)
    assert len(runs) == 1
    compensators.network_runs.clear()
    fresh = compensators.run_network(weights, inputs)
    assert len(runs) == 2
    assert np.array_equal(again, fresh) and np.isfinite(fresh).all()


def test_a_changed_weight_or_input_runs_the_network_again(runs: list[int]) -> None:
    weights, inputs = _weights(3), np.cos(np.linspace(0.0, 6.0, 200)).reshape(-1, 1)
    base = compensators.run_network(weights, inputs)
    nudged = {name: value.clone() for name, value in weights.items()}
    nudged["w_out"][0, 0] = torch.nextafter(nudged["w_out"][0, 0], torch.tensor(np.inf))
    other_weights = compensators.run_network(nudged, inputs)
    other_inputs = compensators.run_network(weights, inputs[::-1].copy())
    assert len(runs) == 3
    assert not np.array_equal(base, other_weights) and not np.array_equal(base, other_inputs)


def test_only_the_last_runs_are_kept(runs: list[int]) -> None:
    inputs = np.linspace(-1.0, 1.0, 50).reshape(-1, 1)
    for seed in range(compensators.NETWORK_RUNS_KEPT + 1):
        compensators.run_network(_weights(seed), inputs)
    assert len(compensators.network_runs) == compensators.NETWORK_RUNS_KEPT
    compensators.run_network(_weights(0), inputs)  # the oldest was let go: run again
    assert len(runs) == compensators.NETWORK_RUNS_KEPT + 2
