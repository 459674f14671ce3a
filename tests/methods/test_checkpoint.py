"""model.pt: round trip, and every kind of bad file is a one-line UserError without running code."""

from __future__ import annotations

import copy
import dataclasses
import os
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from codegen.spec import parse_checkpoint
from tests.testmodels import checkpoint_dict, random_weights, save_checkpoint
from trainer.baselines.pla import PiecewiseLinear
from trainer.baselines.poly3 import CubicPolynomial
from trainer.checkpoint import load_model, save_model
from trainer.data.recording import Recording
from trainer.dlstm.compensators import RecursiveDLSTM, TemperatureDLSTM
from trainer.dlstm.realtime import TEMPERATURE_KIND, FrontEnd, Standardiser
from trainer.errors import UserError
from trainer.fitting import fit_with_stats
from trainer.methods import name_of
from trainer.reference import OffsetRecord
from trainer.train_stats import TrainStats


def _fitted_pla() -> PiecewiseLinear:
    temp = np.linspace(-40, 80, 5_000)
    return PiecewiseLinear().fit_arrays(temp, 0.02 * temp**2 - temp)


def test_round_trip_with_weights_only(tmp_path: Path) -> None:
    model = _fitted_pla()
    path = tmp_path / "model.pt"
    save_model(model, path, train_stats=TrainStats(n_samples=5000), valid_temp_range_c=(-40.0, 80.0))
    raw = torch.load(path, weights_only=True)  # must not need unsafe unpickling
    assert raw["method"] == "pla" and raw["valid_temp_range_c"] == [-40.0, 80.0]
    loaded, checkpoint = load_model(path)
    temp = np.linspace(-50, 90, 777)
    np.testing.assert_array_equal(loaded.drift_at(temp), model.drift_at(temp))
    assert checkpoint["train_stats"]["n_samples"] == 5000


def test_poly3_round_trip(tmp_path: Path) -> None:
    temp = np.linspace(-40, 80, 5_000)
    model = CubicPolynomial().fit_arrays(temp, 1e-4 * temp**3)
    save_model(model, tmp_path / "m.pt", train_stats=TrainStats(), valid_temp_range_c=(-40.0, 80.0))
    loaded, _ = load_model(tmp_path / "m.pt")
    np.testing.assert_array_equal(loaded.drift_at(temp), model.drift_at(temp))


def _save_then(tmp_path: Path) -> Path:
    path = tmp_path / "model.pt"
    save_model(_fitted_pla(), path, train_stats=TrainStats(), valid_temp_range_c=(0.0, 1.0))
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


@pytest.mark.parametrize("suffix", [".csv", ".NPZ"])
def test_a_recording_given_as_the_model_is_named_as_swapped_arguments(tmp_path: Path, suffix: str) -> None:
    """The recording passed where the model goes (``trainer evaluate rec.csv model.pt``): said as such,
    not as a file that "holds content beyond tensors"."""
    path = tmp_path / f"run{suffix}"
    path.write_text("time_s,temp_c,accel_mg\n0,25,1\n")
    with pytest.raises(UserError, match=r"run\.(csv|NPZ): a recording .*arguments swapped"):
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
        save_model(
            _fitted_pla(), tmp_path / "missing" / "m.pt", train_stats=TrainStats(), valid_temp_range_c=(0, 1)
        )
    assert not (tmp_path / "missing").exists()


def test_the_same_model_gives_byte_identical_files_whatever_the_path(tmp_path: Path) -> None:
    model = _fitted_pla()
    (tmp_path / "a").mkdir()
    paths = [tmp_path / "a" / "model.pt", tmp_path / "other-name.pt"]
    for path in paths:
        save_model(model, path, train_stats=TrainStats(n_samples=1), valid_temp_range_c=(0.0, 1.0))
    assert paths[0].read_bytes() == paths[1].read_bytes()


def _legacy_normalisation_fields(kind: str, norm: dict[str, Any]) -> dict[str, float]:
    """What payload.frontend carried besides payload.normalisation before it was written once."""
    if kind == TEMPERATURE_KIND:
        names = ("temp_mean", "temp_std", "rate_mean", "rate_std", "drift_mean", "drift_std")
        values = (*norm["inputs_mean"][:1], *norm["inputs_std"][:1], norm["inputs_mean"][1])
        values += (norm["inputs_std"][1], norm["output_mean"], norm["output_std"])
        return dict(zip(names, (float(v) for v in values), strict=True))
    return {
        "accel_mean": float(norm["inputs_mean"][0]),
        "accel_std": float(norm["inputs_std"][0]),
        "output_mean": float(norm["output_mean"]),
        "output_std": float(norm["output_std"]),
    }


@pytest.mark.parametrize("cls", [RecursiveDLSTM, TemperatureDLSTM])
def test_dlstm_normalisation_is_written_once_and_old_checkpoints_still_load(
    cls: type[RecursiveDLSTM] | type[TemperatureDLSTM], tmp_path: Path
) -> None:
    n_in = 2 if cls.kind == TEMPERATURE_KIND else 1
    model = cls(progress=False)
    model.frontend = FrontEnd.from_seconds(50.0)
    model.inputs_norm = Standardiser(tuple(0.5 + k for k in range(n_in)), tuple(2.0 + k for k in range(n_in)))
    model.output_norm = Standardiser((3.25,), (0.75,))
    model.weights = random_weights(n_in, 4, 2, seed=3)
    model.training = {}
    payload = model.to_payload()
    assert set(payload["frontend"]) == {"kind", *model.frontend.to_dict()}  # no normalisation there

    old = copy.deepcopy(payload)
    old["frontend"].update(_legacy_normalisation_fields(cls.kind, payload["normalisation"]))
    method = name_of(model)
    for layout, data in (("new", payload), ("old", old)):
        path = tmp_path / f"{layout}.pt"
        save_checkpoint(checkpoint_dict(method, data, (-40.0, 80.0)), path)
        loaded, checkpoint = load_model(path)
        assert loaded.frontend == model.frontend, layout
        assert loaded.inputs_norm == model.inputs_norm and loaded.output_norm == model.output_norm, layout
        for key, tensor in model.weights.items():
            assert torch.equal(loaded.weights[key], tensor.float()), (layout, key)
        spec = parse_checkpoint(checkpoint, str(path)).model
        assert spec.frontend.inputs_mean == model.inputs_norm.mean, layout
        assert spec.frontend.output_std == model.output_norm.std[0], layout


@pytest.mark.parametrize(
    ("change", "field"),
    [
        (lambda c: c["payload"].update(slopes_mg_per_c=c["payload"]["slopes_mg_per_c"] * float("nan")),
         "payload.slopes_mg_per_c"),
        (lambda c: c.update(train_stats=None), "train_stats"),
        (lambda c: c["train_stats"].update(time_range_s=[5.0]), "train_stats.time_range_s"),
        (lambda c: c["train_stats"].update(sample_rate_hz=-1.0), "train_stats.sample_rate_hz"),
        (lambda c: c.update(valid_temp_range_c=[1.0]), "valid_temp_range_c"),
        (lambda c: c.update(valid_temp_range_c=[9.0, 1.0]), "valid_temp_range_c"),
        (lambda c: c.update(method=["pla"]), "method"),
        (lambda c: c.update(offset={"mode": "relative"}), "offset"),
    ],
)  # fmt: skip
def test_every_field_is_checked_at_load_naming_it(tmp_path: Path, change: Any, field: str) -> None:
    """One validation (load_checkpoint) for every command that loads a model: the field is named."""
    path = _save_then(tmp_path)
    checkpoint = torch.load(path, weights_only=True)
    checkpoint["train_stats"] = {"time_range_s": [0.0, 9.0], "sample_rate_hz": 2.0}
    change(checkpoint)
    torch.save(checkpoint, path)
    with pytest.raises(UserError, match=rf"model\.pt: field '{field}'"):
        load_model(path)


def _cubic_checkpoint(tmp_path: Path, **stats: Any) -> tuple[Path, dict[str, Any]]:
    temp = np.linspace(-40, 80, 500)
    model = CubicPolynomial().fit_arrays(temp, 1e-4 * temp**3)
    model.offset = OffsetRecord("relative", model.t_ref_c, 1.0)
    path = tmp_path / "m.pt"
    save_model(model, path, train_stats=TrainStats(**stats), valid_temp_range_c=(-40.0, 80.0))
    return path, torch.load(path, weights_only=True)


@pytest.mark.parametrize(
    ("stats", "change", "message"),
    [
        # a gyroscope's cubic relabelled as an accelerometer axis: exported in mg, 1.78x too small
        ({"channel": "gyro0_x", "unit": "dps"}, lambda c: c["train_stats"].update(channel="accel0_x"),
         "field 'train_stats.channel' 'accel0_x' is a channel in mg, but 'train_stats.unit' says dps"),
        ({"channel": "gyro0_x", "unit": "dps"}, lambda c: c["train_stats"].update(unit="deg/s"),
         "field 'train_stats.unit' is 'deg/s', not one of mg, dps, pa"),
        ({"channel": "accel0_z"}, lambda c: c["train_stats"].update(unit="dps"),
         "'accel0_z' is a channel in mg, but 'train_stats.unit' says dps"),
        ({}, lambda c: c["payload"].update(t_ref_c=500.0),
         "field 'payload.t_ref_c' 500 degC differs from 'offset.t_ref_c'"),
        ({}, lambda c: c["payload"].update(degree=2),
         "payload.degree is 2, but coefficients_mg has a non-zero term of a higher order"),
    ],
)  # fmt: skip
def test_contradicting_fields_are_refused_naming_them(
    tmp_path: Path, stats: dict[str, Any], change: Any, message: str
) -> None:
    """Fields one fit sets together must agree: an edited file that breaks that is refused."""
    path, checkpoint = _cubic_checkpoint(tmp_path, **stats)
    load_model(path)  # as written, it loads
    change(checkpoint)
    torch.save(checkpoint, path)
    with pytest.raises(UserError, match=re.escape(message)):
        load_model(path)


# The order of the train_stats keys in every model.pt written so far (the file format): the record
# must write them in this order for the same model to give the same bytes.
STORED_ORDER = (
    "source", "n_samples", "sample_rate_hz", "duration_s", "temp_min_c", "temp_max_c", "accel_mean_mg",
    "accel_std_mg", "time_range_s", "data_sha256", "channel", "unit", "device_id", "fit_residual_rms_mg",
)  # fmt: skip


def _imu_recording() -> Recording:
    time_s = np.arange(200) * 0.5
    columns = {"time_s": time_s, "temp_c": 20.0 + 0.1 * time_s, "accel_mg": np.sin(time_s)}
    meta = {"sample_rate_hz": "2", "channel": "gyro0_y", "unit": "dps", "device_id_gyro0": "2490378"}
    return Recording(columns, meta, "imu.csv")


def test_train_stats_are_stored_as_plain_values_in_the_format_order(tmp_path: Path) -> None:
    rec = _imu_recording()
    model, stats = fit_with_stats("poly3", rec)
    save_model(model, tmp_path / "m.pt", train_stats=stats, valid_temp_range_c=stats.temp_range_c)
    stored = torch.load(tmp_path / "m.pt", weights_only=True)["train_stats"]
    assert tuple(stored) == STORED_ORDER
    assert stored["time_range_s"] == [0.0, 99.5] and stored["n_samples"] == 200
    assert (stored["channel"], stored["unit"], stored["device_id"]) == ("gyro0_y", "dps", 2490378)
    assert (stored["temp_min_c"], stored["temp_max_c"]) == pytest.approx((20.0, 29.95))
    loaded = TrainStats.of_checkpoint(load_model(tmp_path / "m.pt")[1])
    assert loaded == stats and loaded.to_dict() == stored


def test_train_stats_keep_only_known_fields_and_an_absent_table_is_empty() -> None:
    assert TrainStats.from_dict({"n_samples": 3, "written_by_a_newer_version": 1}) == TrainStats(n_samples=3)
    assert TrainStats.of_checkpoint({"train_stats": None}) == TrainStats()
    assert TrainStats().to_dict() == {}
    with pytest.raises(ValueError, match="no temperature range"):
        _ = TrainStats(temp_min_c=1.0).temp_range_c


# a value of the wrong kind for each kind of field
WRONG = {str: 5, int: -1, float: "1.0", tuple: [3.0, 1.0], dict: [1]}


@pytest.mark.parametrize("name", [f.name for f in dataclasses.fields(TrainStats)])
def test_every_train_stats_field_is_checked_at_load(tmp_path: Path, name: str) -> None:
    kind = next(k for k in WRONG if k.__name__ in str(TrainStats.__annotations__[name]))
    path = _save_then(tmp_path)
    checkpoint = torch.load(path, weights_only=True)
    checkpoint["train_stats"] = {name: WRONG[kind]}
    torch.save(checkpoint, path)
    with pytest.raises(UserError, match=rf"field 'train_stats\.{name}' must be"):
        load_model(path)


def test_bytes_after_the_archive_and_a_text_file_are_refused_as_such(tmp_path: Path) -> None:
    """A model with bytes appended loaded as if intact (its id, a hash of the file, changed); a text
    file named .pt was refused as one that "holds content beyond tensors", which it does not."""
    path = _save_then(tmp_path)
    intact = path.read_bytes()
    path.write_bytes(intact + b"\n# appended by a transfer\n")
    with pytest.raises(UserError, match=r"model\.pt: not a readable model file: 26 bytes follow"):
        load_model(path)
    path.write_text("this is not a model\n")
    with pytest.raises(UserError, match=r"model\.pt: not a readable model file: .*not one") as caught:
        load_model(path)
    assert "beyond tensors" not in str(caught.value)
    path.write_bytes(intact)  # the file as written loads
    load_model(path)
