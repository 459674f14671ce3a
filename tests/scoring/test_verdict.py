"""The sign-off guard and verdict (trainer.scoring.verdict) on plain figures."""

from __future__ import annotations

import math

import numpy as np

from trainer.scoring.verdict import FAIL, NO_VERDICT, PASS, Figures, verdict, worse_than_uncompensated


def _rms_about_mean(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean((x - x.mean()) ** 2)))


def test_a_constant_shift_ties_with_uncompensated_and_is_not_worse() -> None:
    """A cubic held at its end value beyond the trained range adds a constant: the same drift left,
    whatever the last bit of the floating-point RMS says."""
    rng = np.random.default_rng(7)
    raw = 0.003 * np.linspace(0.0, 1.0, 5000) + 0.01 * rng.standard_normal(5000)
    raws, models = [], []
    for shift in np.linspace(-100.0, 100.0, 41):
        raws.append(_rms_about_mean(raw))
        models.append(_rms_about_mean(raw - shift))
    assert any(m > r for m, r in zip(models, raws, strict=True))  # rounding does make some "worse"
    for model, uncompensated in zip(models, raws, strict=True):
        guard = worse_than_uncompensated(
            "G1 / poly3", Figures("held-out", model, uncompensated, unit="deg/s")
        )
        assert guard.ok, guard.detail


def test_a_model_worse_than_uncompensated_fails_in_the_channels_unit() -> None:
    figures = Figures("held-out", 0.30, 0.20, unit="deg/s")
    guard = worse_than_uncompensated("gyro0_x / poly3", figures)
    assert not guard.ok
    assert "0.3 deg/s RMS > 0.2 deg/s" in guard.detail and "mg" not in guard.detail
    result = verdict({"gyro0_x / poly3": figures})
    assert result.status == FAIL and result.failed == (guard.name,)


def test_worse_in_range_alone_fails_and_noise_is_not_worse() -> None:
    in_range_worse = Figures("held-out", 1.0, 2.0, model_in_range_rms=0.9, uncompensated_in_range_rms=0.5)
    assert not worse_than_uncompensated("m", in_range_worse).ok
    # both within 1.2x a 1.0 mg noise floor: the model's excess is noise
    at_noise = Figures("held-out", 1.15, 1.0, noise_floor=1.0)
    assert worse_than_uncompensated("m", at_noise).ok
    beyond_noise = Figures("held-out", 1.3, 1.0, noise_floor=1.0)
    assert not worse_than_uncompensated("m", beyond_noise).ok


def test_a_guard_alone_gives_no_verdict_and_nan_is_not_measured() -> None:
    unmeasured = Figures("held-out", math.nan, math.nan)  # no samples: neither is measured
    assert worse_than_uncompensated("m", unmeasured).ok
    # the output measured without the model but not with it: the model's output is NaN (a hand-edited
    # width of 0 gave NaN everywhere, and the guard used to pass it)
    broken = worse_than_uncompensated("m", Figures("held-out", math.nan, 1.0))
    assert not broken.ok and "not finite" in broken.detail
    assert verdict({"m": Figures("held-out", math.nan, 1.0)}).status == FAIL
    assert verdict({"m": Figures("held-out", 0.5, 1.0)}).status == NO_VERDICT

    class Threshold:
        ok, decisive, name = True, True, "holdout <= 1 mg"

    assert verdict({"m": Figures("held-out", 0.5, 1.0)}, [Threshold()]).status == PASS


def test_a_model_not_worse_only_by_the_noise_margin_is_not_called_better() -> None:
    """0.00854 against 0.008532 with a noise floor of 0.0118: not worse (noise), and not "better ... <"
    either, which the figures contradict."""
    guard = worse_than_uncompensated(
        "u", Figures("held-out", 0.00854, 0.008532, noise_floor=0.0118, unit="deg/s")
    )
    assert guard.ok and guard.detail.startswith("at the noise floor") and "better" not in guard.detail
    assert "0.00854" in guard.detail and "0.008532" in guard.detail
