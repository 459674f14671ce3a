"""Every figure of a module's header, source and manifest is in the channel's own unit, and a bound is
a magnitude.

A gyroscope physics module said "amplitude -0.62 mg, width 60 degC ... in all at most 1.41 mg" and,
further down, that the model's own figures "where they say mg, are in deg/s"; one with a play
started half-way said "off by at most its amplitude, -0.0626 mg". The expected figures here come
from the model file's own parameters (amplitudes in the channel's unit), not from the generator.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from codegen.export import export
from tests import testmodels as tm
from trainer.data.channels import UNIT_LABELS
from trainer.data.recording import Recording
from trainer.greybox.compensator import PhysicsCompensator
from trainer.physics.effects import EffectConfig

BIAS = EffectConfig(
    "bias_poly", {"c0_mg": 0.1, "c1_mg_per_c": 0.02, "c2_mg_per_c2": 1e-4, "c3_mg_per_c3": -1e-6}
)
MG = re.compile(r"\bmg\b")
NUMBER = r"(-?[0-9][0-9.]*(?:e[-+]?[0-9]+)?)"


@pytest.fixture(scope="module")
def rec() -> Recording:
    temp = np.concatenate((np.linspace(60.0, -10.0, 2000), np.linspace(-10.0, 60.0, 2000)))
    return Recording(
        {"time_s": np.arange(temp.size) / 2.0, "temp_c": temp, "accel_mg": np.zeros(temp.size)},
        {"sample_rate_hz": "2"},
        "units-train",
    )


def _physics(
    rec: Recording,
    effects: tuple[EffectConfig, ...],
    play_start_c: float | None,
    channel: str,
    unit: str,
    path: Path,
) -> None:
    """A physics model file with the given effects (parameters in the channel's unit, as a fit on that
    channel writes them) of ``channel``."""
    model = PhysicsCompensator(play_start_c=play_start_c)
    model.effects = effects
    model.temp_range_c = (float(rec.temp_c.min()), float(rec.temp_c.max()))
    model.report = {}
    checkpoint = tm.checkpoint_dict("physics", model.to_payload(), model.temp_range_c)
    checkpoint["train_stats"] = {
        "sample_rate_hz": float(rec.sample_rate_hz),
        "channel": channel,
        "unit": unit,
    }
    tm.save_checkpoint(checkpoint, path)


def _texts(out: Path, name: str) -> dict[str, str]:
    return {suffix: (out / f"{name}{suffix}").read_text() for suffix in (".h", ".c", ".manifest.json")}


def _flat(text: str) -> str:
    return " ".join(text.replace(" * ", " ").split())


@pytest.mark.parametrize(("channel", "unit"), [("gyro0_y", "dps"), ("baro0", "pa")])
def test_a_half_way_play_gives_its_bound_as_a_magnitude_in_the_channel_s_unit(
    channel: str, unit: str, rec: Recording, tmp_path: Path
) -> None:
    amp = -0.0626  # a negative branch offset, in the channel's unit
    branch = EffectConfig("hysteresis_offset", {"amp_mg": amp, "width_c": 23.4})
    _physics(rec, (BIAS, branch), None, channel, unit, tmp_path / "m.pt")
    export(tmp_path / "m.pt", tmp_path / "out", name="half")
    texts = _texts(tmp_path / "out", "half")
    for suffix, text in texts.items():
        assert not MG.search(text), (suffix, MG.search(text))
    label = re.escape(UNIT_LABELS[unit])
    header = _flat(texts[".h"])
    bounds = re.findall(rf"at most \|its amplitude\|, {NUMBER} {label}", header)
    assert [float(b) for b in bounds] == [pytest.approx(abs(amp), rel=5e-3)]
    assert "where they say mg" not in header


def test_a_room_start_gives_every_figure_in_deg_s_and_the_worst_case_as_a_magnitude(
    rec: Recording, tmp_path: Path
) -> None:
    """Three branch offsets of several widths (the bundled gyro x's structure), started from 25 degC:
    each amplitude in deg/s, and the power-on bound, twice the sum of their sizes, positive."""
    amps = (-0.62, -0.0427, 0.0437)
    widths = (60.0, 30.0, 15.0)
    effects = (
        BIAS,
        *(
            EffectConfig("hysteresis_offset", {"amp_mg": a, "width_c": w})
            for a, w in zip(amps, widths, strict=True)
        ),
    )
    _physics(rec, effects, 25.0, "gyro0_x", "dps", tmp_path / "m.pt")
    export(tmp_path / "m.pt", tmp_path / "out", name="room")
    texts = _texts(tmp_path / "out", "room")
    for suffix, text in texts.items():
        assert not MG.search(text), (suffix, MG.search(text))
    header = _flat(texts[".h"])
    said = [float(v) for v in re.findall(rf"amplitude {NUMBER} deg/s, width", header)]
    assert said == [pytest.approx(a, rel=5e-3) for a in amps]
    worst = re.findall(rf"in all at most {NUMBER} deg/s until T has moved by {NUMBER} degC", header)
    assert len(worst) == 1
    assert float(worst[0][0]) == pytest.approx(2 * sum(abs(a) for a in amps), rel=5e-3)
    assert float(worst[0][1]) == pytest.approx(max(widths), rel=5e-3)
    # the manifest's power-on text is the header's
    assert "in all at most" in texts[".manifest.json"] and "deg/s" in texts[".manifest.json"]


@pytest.mark.parametrize("method", ["pla", "dlstm", "dlstm-temp", "poly3"])
def test_a_gyroscope_module_of_every_family_says_no_mg_and_no_micro_g(
    method: str, rec: Recording, tmp_path: Path
) -> None:
    """The PLA's tables, the DLSTM's head, estimate and window comments, the manifests' formats: in the
    output LSB of the channel (1/16000 deg/s), not 1/16 ug."""
    checkpoint = tm.checkpoint_for(method, rec, hidden=4, layers=2)
    checkpoint["train_stats"] = {**checkpoint["train_stats"], "channel": "gyro0_z", "unit": "dps"}
    tm.save_checkpoint(checkpoint, tmp_path / "m.pt")
    export(tmp_path / "m.pt", tmp_path / "out", name="gz")
    for suffix, text in _texts(tmp_path / "out", "gz").items():
        assert not MG.search(text), (suffix, MG.search(text))
        assert "1/16 ug" not in text and "micro-g" not in text, suffix
        assert "accel LSB" not in text, suffix
