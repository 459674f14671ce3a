"""model.pt: round trip, and every kind of bad file is a one-line UserError without running code."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import torch

from trainer.baselines.pla import PiecewiseLinear
from trainer.baselines.poly3 import CubicPolynomial
from trainer.checkpoint import load_model, save_model
from trainer.errors import UserError


def _fitted_pla() -> PiecewiseLinear:
    temp = np.linspace(-40, 80, 5_000)
    return PiecewiseLinear().fit_arrays(temp, 0.02 * temp**2 - temp)


def test_round_trip_with_weights_only(tmp_path: Path) -> None:
    model = _fitted_pla()
    path = tmp_path / "model.pt"
    save_model(model, path, train_stats={"n_samples": 5000}, valid_temp_range_c=(-40.0, 80.0))
    raw = torch.load(path, weights_only=True)  # must not need unsafe unpickling
    assert raw["method"] == "pla" and raw["valid_temp_range_c"] == [-40.0, 80.0]
    loaded, checkpoint = load_model(path)
    temp = np.linspace(-50, 90, 777)
    np.testing.assert_array_equal(loaded.drift_at(temp), model.drift_at(temp))
    assert checkpoint["train_stats"]["n_samples"] == 5000


def test_poly3_round_trip(tmp_path: Path) -> None:
    temp = np.linspace(-40, 80, 5_000)
    model = CubicPolynomial().fit_arrays(temp, 1e-4 * temp**3)
    save_model(model, tmp_path / "m.pt", train_stats={}, valid_temp_range_c=(-40.0, 80.0))
    loaded, _ = load_model(tmp_path / "m.pt")
    np.testing.assert_array_equal(loaded.drift_at(temp), model.drift_at(temp))


def _save_then(tmp_path: Path) -> Path:
    path = tmp_path / "model.pt"
    save_model(_fitted_pla(), path, train_stats={}, valid_temp_range_c=(0.0, 1.0))
    return path


def test_truncated_file_is_rejected(tmp_path: Path) -> None:
    path = _save_then(tmp_path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(UserError, match=r"model\.pt: not a readable model file"):
        load_model(path)


def test_random_bytes_are_rejected(tmp_path: Path) -> None:
    path = tmp_path / "model.pt"
    path.write_bytes(os.urandom(4096))
    with pytest.raises(UserError, match=r"model\.pt"):
        load_model(path)


class _Exploit:
    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (self.marker,))


def test_pickled_code_is_never_executed(tmp_path: Path) -> None:
    marker = tmp_path / "pwned"
    path = tmp_path / "model.pt"
    torch.save({"format": "mems-tdc-model", "payload": _Exploit(marker)}, path)
    with pytest.raises(UserError, match="refused to load"):
        load_model(path)
    assert not marker.exists()


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (torch.zeros(3), "not a mems-tdc model"),
        ({"format": "something-else"}, "not a mems-tdc model"),
        ({"format": "mems-tdc-model", "format_version": 99}, "format_version"),
        ({"format": "mems-tdc-model", "format_version": 1, "method": "pla"}, "field 'payload' is missing"),
    ],
)
def test_foreign_checkpoints_are_rejected(tmp_path: Path, content: object, message: str) -> None:
    path = tmp_path / "model.pt"
    torch.save(content, path)
    with pytest.raises(UserError, match=message):
        load_model(path)


def test_unknown_method_is_rejected(tmp_path: Path) -> None:
    path = tmp_path / "model.pt"
    torch.save(
        {
            "format": "mems-tdc-model",
            "format_version": 1,
            "method": "magic",
            "payload": {},
            "train_stats": {},
            "valid_temp_range_c": [0.0, 1.0],
        },
        path,
    )
    with pytest.raises(UserError, match="'magic', not one of"):
        load_model(path)


def test_malformed_payload_is_rejected(tmp_path: Path) -> None:
    path = tmp_path / "model.pt"
    torch.save(
        {
            "format": "mems-tdc-model",
            "format_version": 1,
            "method": "pla",
            "payload": {"n_intervals": 10},
            "train_stats": {},
            "valid_temp_range_c": [0.0, 1.0],
        },
        path,
    )
    with pytest.raises(UserError, match="payload' is malformed"):
        load_model(path)


def test_failed_save_leaves_no_file(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="does not exist"):
        save_model(_fitted_pla(), tmp_path / "missing" / "m.pt", train_stats={}, valid_temp_range_c=(0, 1))
    assert not (tmp_path / "missing").exists()


def test_the_same_model_gives_byte_identical_files_whatever_the_path(tmp_path: Path) -> None:
    model = _fitted_pla()
    (tmp_path / "a").mkdir()
    paths = [tmp_path / "a" / "model.pt", tmp_path / "other-name.pt"]
    for path in paths:
        save_model(model, path, train_stats={"n": 1}, valid_temp_range_c=(0.0, 1.0))
    assert paths[0].read_bytes() == paths[1].read_bytes()
