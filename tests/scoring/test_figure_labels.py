"""Every figure and table names its channel and unit; sign-off and fleet plots say what each mark is.

A gyroscope channel (deg/s) goes through ``evaluate``, ``compare``, ``report`` and ``diagnose``;
each figure is captured as it is saved and its matplotlib texts (titles, axis labels, legend) are
read back, and each report's tables are read as text. The fleet's strip plot is drawn from known
values and read back the same way.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from tests.data_io.test_channels import RATE_HZ, imu_recording
from trainer.cli import main as trainer_main
from trainer.data.channels import channel_view, select_channels
from trainer.data.recording_io import write_recording
from trainer.fleet.report import strip_plot

CHANNEL = "gyro0_z"
UNIT = "deg/s"
MG_WORD = re.compile(r"\bmg\b")  # the unit word; column names such as true_drift_mg do not match
HELD_OUT_FRACTION = 0.3
THRESHOLDS = {"residual_max_mg": 0.01, "branch_max_mg": 0.008, "holdout_max_mg": 0.005}


@pytest.fixture
def saved(monkeypatch: pytest.MonkeyPatch) -> list[Figure]:
    """Every figure saved while the test runs (the PNGs are written as usual)."""
    figures: list[Figure] = []
    original = Figure.savefig

    def capture(self: Figure, *args: Any, **kwargs: Any) -> None:
        figures.append(self)
        original(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", capture)
    return figures


@pytest.fixture(scope="module")
def gyro(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A one-channel view of a gyroscope axis (deg/s) and a cubic fitted on it."""
    root = tmp_path_factory.mktemp("gyro")
    rec = imu_recording()
    (channel,) = select_channels(rec, (CHANNEL,))
    write_recording(channel_view(rec, channel), root / "gyro.npz")
    assert trainer_main(["fit", "--method", "poly3", str(root / "gyro.npz"), "-o", str(root / "m.pt")]) == 0
    config = root / "thresholds.toml"
    config.write_text("[thresholds]\n" + "".join(f"{k} = {v}\n" for k, v in THRESHOLDS.items()))
    return {"rec": root / "gyro.npz", "model": root / "m.pt", "config": config, "root": root}


def _titles(figure: Figure) -> list[str]:
    suptitle = figure._suptitle.get_text() if figure._suptitle is not None else ""
    return [ax.get_title() for ax in figure.axes] + [suptitle]


def _legend(ax: Axes) -> list[str]:
    legend = ax.get_legend()
    return [] if legend is None else [t.get_text() for t in legend.get_texts()]


def _command(name: str, gyro: dict[str, Path], out: Path) -> list[str]:
    rec, model = str(gyro["rec"]), str(gyro["model"])
    return {
        "evaluate": ["evaluate", model, rec, "--out-dir", str(out)],
        "compare": ["compare", rec, "--holdout", str(HELD_OUT_FRACTION), "--methods", "poly3", "--quiet",
                    "--out-dir", str(out)],
        "report": ["report", model, "--recording", rec, "--holdout", f"last:{HELD_OUT_FRACTION}", "--config",
                   str(gyro["config"]), "-o", str(out)],
        "diagnose": ["diagnose", rec, "--report", str(out)],
    }[name]  # fmt: skip


@pytest.mark.parametrize("command", ["evaluate", "compare", "report", "diagnose"])
def test_figures_and_tables_of_a_gyro_channel_name_it_and_its_unit(
    command: str, gyro: dict[str, Path], saved: list[Figure], tmp_path: Path
) -> None:
    out = tmp_path / command
    trainer_main(_command(command, gyro, out))  # report: FAIL (exit 1) against the tight thresholds
    assert saved, "no figure was written"
    for figure in saved:
        assert any(CHANNEL in title for title in _titles(figure)), _titles(figure)
        for ax in figure.axes:
            label = ax.get_ylabel()
            if label:  # every data axis is in the channel's unit, none in mg
                assert UNIT in label and not MG_WORD.search(label), label
    report = (out / "report.md").read_text()
    assert CHANNEL in report and f"({UNIT})" in report and not MG_WORD.search(report)


def test_sign_off_plots_label_limits_and_shade_the_held_out_part(
    gyro: dict[str, Path], saved: list[Figure], tmp_path: Path
) -> None:
    trainer_main(_command("report", gyro, tmp_path / "so"))
    (residual,) = [f for f in saved if any("drift left over time" in t for t in _titles(f))]
    over_time = next(ax for ax in residual.axes if "over time" in ax.get_title())
    n = len(imu_recording().time_s)
    first_held = n - round(HELD_OUT_FRACTION * n)  # the held-out part: the last 30 % of the rows
    t0, t1 = first_held / RATE_HZ, (n - 1) / RATE_HZ
    legend = _legend(over_time)
    for key, value in THRESHOLDS.items():
        assert f"limit {key}: +-{value:g} {UNIT}" in legend
    assert f"held-out part (t = {t0:g} .. {t1:g} s)" in legend
    (span,) = [p for p in over_time.patches if p.get_label().startswith("held-out part")]
    corners = span.get_patch_transform().transform(span.get_path().vertices)
    assert (corners[:, 0].min(), corners[:, 0].max()) == pytest.approx((t0 / 60.0, t1 / 60.0))
    by_temperature = next(ax for ax in residual.axes if "by branch" in ax.get_title())
    assert any(text.startswith("held-out part's temperatures") for text in _legend(by_temperature))
    assert "limit residual_max_mg: +-0.01 deg/s" in _legend(by_temperature)


def test_fleet_strip_plot_says_which_dot_is_which_unit(saved: list[Figure], tmp_path: Path) -> None:
    units = ["SN-3", "SN-1", "SN-2"]  # manifest order, not sorted
    values = {"SN-1": 0.5, "SN-2": 9.0, "SN-3": 0.4}
    strip_plot(tmp_path / "strip.png", [("drift left poly3 (mg)", values)], {"SN-2"}, "Drift left", units)
    (figure,) = saved
    ax = figure.axes[0]
    assert [t.get_text() for t in ax.get_xticklabels()] == units
    dots = ax.collections[0].get_offsets()
    for x, y in np.asarray(dots):
        assert values[units[int(x)]] == y  # the dot above a unit's label is that unit's value
    assert [t.get_text() for t in ax.texts] == ["SN-2"]  # the out-of-family unit is named beside its dot
