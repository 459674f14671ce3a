"""A warm-up the temperature polynomial absorbs is reported as confounded, not passed over (issue 21).

On a run that starts on a ramp it never returns to (fridge to room), a warm-up ``exp(-t / tau)`` is a
function of the temperature there, and the bias cubic absorbs it; on a run that comes back to its
starting temperatures it is not.
"""

from __future__ import annotations

import numpy as np

from trainer.data.recording import Recording
from trainer.diagnose import diagnose
from trainer.diagnose.blocks import build_blocks
from trainer.diagnose.profile import analyse_profile
from trainer.physics.catalogue import warmup
from trainer.physics.catalogue.bias_poly import absorbed_fraction
from trainer.physics.effects import effect_contribution

WARMUP = warmup.DEFINITION.identifier
FS_HZ = 1.0


def _recording(temp_of_t, duration_s: float, seed: int, added_mg: float = 0.0) -> Recording:
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 1.0 / FS_HZ)
    temp = temp_of_t(t)
    drift = 0.05 * (temp - 25.0) + effect_contribution(
        WARMUP, {"amp_mg": added_mg, "tau_s": 900.0}, t, temp, temp
    )
    columns = {"time_s": t, "temp_c": temp, "accel_mg": drift + 0.2 * rng.standard_normal(t.size)}
    return Recording(columns, {"sample_rate_hz": str(FS_HZ)}, f"synthetic#{seed}")


def _fridge_to_room(t: np.ndarray) -> np.ndarray:
    return 25.0 - 20.0 * np.exp(-t / 600.0)


def _cycle(t: np.ndarray) -> np.ndarray:
    return np.interp(t, [0.0, 1500.0, 3000.0, 4500.0, 7200.0], [5.0, 40.0, 0.0, 40.0, 20.0])


def test_absorbed_fraction_is_the_share_a_cubic_takes() -> None:
    """A cubic of T is absorbed whole; a signal orthogonal to every power of T not at all."""
    temp = np.linspace(-10.0, 60.0, 200)
    assert absorbed_fraction(temp, 0.3 + 0.01 * temp**3) > 0.999999
    signal = np.sin(np.arange(200) * 2.9)  # alternates between neighbouring temperatures
    assert absorbed_fraction(temp, signal) < 0.05


def test_warmup_on_a_monotone_start_is_not_identifiable() -> None:
    data = build_blocks(_recording(_fridge_to_room, 7200.0, seed=1))
    info = analyse_profile(data, {}).identifiability[WARMUP]
    assert not info.identifiable
    assert "bias polynomial" in info.reason and info.test


def test_warmup_on_a_revisited_start_is_searched() -> None:
    data = build_blocks(_recording(_cycle, 7200.0, seed=2))
    assert analyse_profile(data, {}).identifiability[WARMUP].identifiable


def test_the_report_says_why_a_hidden_warmup_is_not_named() -> None:
    """3.9 mg, 900 s on a fridge-to-room run: not named, listed as not identifiable with its reason."""
    d = diagnose(
        _recording(_fridge_to_room, 7200.0, seed=3, added_mg=3.9), holdout_fraction=0.0, max_blocks=300
    )
    assert WARMUP not in {e.effect for e in d.left_out}
    listed = [n for n in d.not_identifiable if n.effect == WARMUP]
    assert len(listed) == 1 and "bias polynomial" in listed[0].reason
