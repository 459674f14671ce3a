"""The physics compensator fitted on a cross-validation fold (one thermal segment held out, its output
imputed by the cubic and given no weight): the cross-validated stage must judge a term on the rows
the fold trains on, and place a rate term seen through a filter longer than the finder names.

The realistic experiment's gyroscope (``trainer/physics/realistic.toml``: lag 60 s, a rate term
-0.117 deg/s per degC/min through 330 s, a branch offset) is the case: before, the rate term was
judged on how well it predicted the imputed cubic, never added on a fold, and ``auto`` kept to the
cubic (0.079 against 0.013 deg/s cross-validated).
"""

from __future__ import annotations

import numpy as np
import pytest

from trainer.data.channels import channel_view, select_channels
from trainer.data.recording import Recording
from trainer.diagnose.api import build_baseline, build_blocks, fit_model
from trainer.diagnose.blocks import HELD_OUT_COLUMN
from trainer.fitting import fit_compensator
from trainer.greybox.select import cv_rms
from trainer.physics.config import PhysicsConfig, parse_config_text
from trainer.physics.simulate import simulate
from trainer.scoring.crossval import folds_of, impute_held_out, training_rows

TOLERANCE = 0.25
RATE_K = -0.117  # deg/s per degC/min
RATE_TAU_S = 330.0  # beyond the finder's freed search (FREED_MAX_S), inside the catalogue's range
GYRO_TOML = f"""
[recording]
sample_rate_hz = 5.0
[protocol]
name = "realistic-train"
[effects.bias_poly]
c1_mg_per_c = 0.1
[noise.white_noise]
n_mg_rt_s = 0.24
[channels.gyro0_x.effects.bias_poly]
c1_dps_per_c = 0.0108
c2_dps_per_c2 = 0.00039
c3_dps_per_c3 = -2.4e-6
[channels.gyro0_x.effects.thermal_lag]
tau_s = 60.0
[channels.gyro0_x.effects.temp_rate]
k_dps_per_c_per_min = {RATE_K}
tau_s = {RATE_TAU_S}
[channels.gyro0_x.effects.hysteresis_offset]
amp_dps = -0.056
width_c = 20.0
[channels.gyro0_x.noise.white_noise]
n_dps_rt_s = 0.0099
[channels.gyro0_x.noise.rate_random_walk]
k_dps_per_rt_s = 2e-5
"""


@pytest.fixture(scope="module")
def gyro() -> Recording:
    config: PhysicsConfig = parse_config_text(GYRO_TOML, "gyro.toml")
    rec = simulate(config, 11)
    return channel_view(rec, select_channels(rec, ("gyro0_x",))[0]).without_truth()


def test_the_inner_held_out_test_ignores_the_imputed_rows(gyro: Recording) -> None:
    """Whatever the imputed output of the held-out segment, a term's cross-validated figure is the same
    (away from the segment's edges: a block across one is mostly training rows and counts)."""
    heating = next(s for s in folds_of(gyro) if s.label == "heating")
    train = training_rows(len(gyro), heating)
    imputed = impute_held_out(gyro, train)
    assert imputed.columns[HELD_OUT_COLUMN].sum() == len(gyro) - train.sum()
    margin_s = 2.0 * build_blocks(imputed).block_s
    t = imputed.time_s
    inside = ~train & (t > t[heating.start] + margin_s) & (t < t[heating.stop - 1] - margin_s)
    garbage = Recording(
        {**imputed.columns, "accel_mg": np.where(inside, 50.0 * np.sin(t), imputed.accel_mg)},
        dict(imputed.meta),
        "garbage",
    )
    figures = []
    for rec in (imputed, garbage):
        data = build_blocks(rec)
        assert data.held_out is not None and data.held_out.any()
        baseline = build_baseline(None, rec.time_s - rec.time_s[0], data.lattice_lsb_c)
        fit = fit_model(baseline.terms, baseline.noise_terms, data)
        figures.append(cv_rms(fit.terms, data))
    assert figures[0] == pytest.approx(figures[1], rel=1e-9)


@pytest.mark.parametrize("label", ["heating", "cooling"])
def test_a_fold_fit_places_the_rate_term_seen_through_330_s(gyro: Recording, label: str) -> None:
    segment = next(s for s in folds_of(gyro) if s.label == label)
    model = fit_compensator("physics", impute_held_out(gyro, training_rows(len(gyro), segment)))
    params = {e.identifier: e.params for e in model.effects}  # type: ignore[attr-defined]
    assert "temp_rate" in params, model.describe()
    k, tau = params["temp_rate"]["k_mg_per_c_per_min"], params["temp_rate"]["tau_s"]
    assert abs(k - RATE_K) <= TOLERANCE * abs(RATE_K), f"k {k:.4g}"
    assert abs(tau - RATE_TAU_S) <= TOLERANCE * RATE_TAU_S, f"tau {tau:.4g} s"
