"""``trainer compare --jobs N`` (trainer/scoring/side_by_side.py) gives the results of ``--jobs 1``:
the same weights, the same predictions, the same offsets, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from trainer.cli import main as trainer_main
from trainer.compensator import Compensator
from trainer.data.recording import Recording
from trainer.data.recording_io import read_recording
from trainer.dlstm.fusion import FusionSettings, join_parts, population_parts, train_part, train_stage
from trainer.errors import run_cli
from trainer.scoring.compare import fit_all

SETTINGS = FusionSettings(population=5, iterations=6, cycles=3)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> tuple[Recording, Recording]:
    """Two 10-minute paper runs at 20 Hz (600 network steps each)."""
    work = tmp_path_factory.mktemp("side")
    out = []
    for name, seed in (("train", 1), ("valid", 2)):
        path = work / f"{name}.npz"
        args = ["simulate", "--protocol", "paper-oven", "--seed", str(seed), "--duration", "600"]
        assert trainer_main([*args, "--rate", "20", "-o", str(path)]) == 0
        out.append(read_recording(path))
    return out[0], out[1]


def test_a_population_trained_in_parts_is_the_population_trained_whole() -> None:
    t = np.linspace(0.0, 1.0, 301)
    series = np.sin(6.0 * t) + 0.5 * t
    x, y = series[:-1].reshape(-1, 1), series[1:]
    parts = population_parts(SETTINGS)
    assert [list(p) for p in parts] == [[0, 1], [2, 3, 4]]  # the packed groups
    whole = train_stage(x, y, SETTINGS, progress=False)
    joined = join_parts([train_part(x, y, SETTINGS, part) for part in parts])
    for k in range(SETTINGS.population):
        for name, value in whole.model.individual(k).items():
            assert torch.equal(value, joined.model.individual(k)[name]), (k, name)
    assert torch.equal(whole.history.losses, joined.history.losses)
    assert torch.equal(whole.history.final_loss, joined.history.final_loss)
    # a target loss looks at every individual at once: one part, the whole population
    assert population_parts(FusionSettings(population=5, target_loss=0.1)) == [range(5)]


def test_the_comparison_fitted_side_by_side_equals_one_after_another(
    recordings: tuple[Recording, Recording],
) -> None:
    train, valid = recordings
    names = ("dlstm", "dlstm-ssa", "dlstm-issa", "poly3", "dlstm-temp", "persistence")

    def fit(jobs: int) -> dict[str, Compensator]:
        models, _ = fit_all(train, SETTINGS, methods=names, progress=False, log=lambda _: None, jobs=jobs)
        return models

    alone, side = fit(1), fit(2)
    assert list(alone) == list(side) == list(names)
    for name in names:
        a, b = alone[name], side[name]
        assert np.array_equal(a.predict_drift(valid), b.predict_drift(valid)), name
        assert a.offset == b.offset, name
        weights_a = a.to_payload().get("weights", {})
        weights_b = b.to_payload().get("weights", {})
        assert weights_a.keys() == weights_b.keys()
        assert all(torch.equal(weights_a[k], weights_b[k]) for k in weights_a), name


def test_jobs_below_one_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    code = run_cli(trainer_main, ["compare", "a.npz", "b.npz", "--jobs", "0"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--jobs: '0' is not a positive whole number" in err
