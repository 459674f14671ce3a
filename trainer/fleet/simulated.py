"""A simulated production batch: units drawn around one sensor, a few with a planted defect.

The tests, ``bench/bench_fleet.py`` and ``scripts/fleet_dask_cluster.sh`` use it. The sensor is the
default tactical-grade accelerometer of ``trainer/physics/default.toml`` with a proof-mass lag,
run through a short chamber cycle (soak, heat, hold, cool, hold; a reversal and two ramp rates,
so that a lag is identifiable) at a low sample rate to keep each unit cheap. Each unit draws its
bias curve, lag and white noise with a unit-to-unit spread; a defect unit adds a bias step (a
shock during the run) or a tripled thermal lag (a bad die attach). Each unit gets two runs (fit,
evaluate) with different noise.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import tomli_w

from trainer.data.recording_io import write_recording
from trainer.physics.catalogue import EFFECTS, WHITE_NOISE, bias_step, thermal_lag
from trainer.physics.config import NoiseConfig, PhysicsConfig, parse_config_text
from trainer.physics.effects import EffectConfig
from trainer.physics.simulate import simulate

SENSOR_TOML = """
[recording]
sample_rate_hz = 1.0
sensor = "fleet-sim-accel-x"

[protocol]
name = "custom"
start_c = -20.0
segments = [
  { label = "soak", duration_s = 1200.0, end_c = -20.0 },
  { label = "ramp_up", rate_c_per_min = 2.0, end_c = 70.0 },
  { label = "hold", duration_s = 1800.0, end_c = 70.0 },
  { label = "ramp_down", rate_c_per_min = 1.0, end_c = 20.0 },
  { label = "hold", duration_s = 1200.0, end_c = 20.0 },
]

[temperature]
case_tau_s = 180.0
temp_noise_c = 0.03

[effects.bias_poly]
c0_mg = 0.5
c1_mg_per_c = 0.12
c2_mg_per_c2 = 0.0008
c3_mg_per_c3 = 4e-6

[effects.thermal_lag]
tau_s = 60.0

[noise.white_noise]
n_mg_rt_s = 0.025

[noise.bias_instability]
b_mg = 0.02

[noise.rate_random_walk]
k_mg_per_rt_s = 0.0005
"""

# Unit-to-unit spread: c0 additive (mg), the rest relative (1 sigma).
C0_SPREAD_MG = 0.3
RELATIVE_SPREAD = {"c1_mg_per_c": 0.10, "c2_mg_per_c2": 0.10, "c3_mg_per_c3": 0.10, "tau_s": 0.10}
WHITE_SPREAD = 0.05
BIAS_STEP_MG = 0.3
BIAS_STEP_AT = 0.55  # share of the run
STEP = bias_step.DEFINITION.identifier
LAG = thermal_lag.DEFINITION.identifier
LAG_X3 = "lag_x3"  # a defect name (the lag tripled), not a catalogue identifier
DEFECTS = (STEP, LAG_X3)
DEFAULT_DEFECTS = {"U07": STEP, "U18": LAG_X3}


def sensor() -> PhysicsConfig:
    return parse_config_text(SENSOR_TOML, "trainer.fleet.simulated.SENSOR_TOML")


def _spread(params: dict[str, float], rng: np.random.Generator) -> dict[str, float]:
    out = dict(params)
    for name, value in params.items():
        if name == "c0_mg":
            out[name] = value + float(rng.normal(0.0, C0_SPREAD_MG))
        elif name in RELATIVE_SPREAD:
            out[name] = value * (1.0 + float(rng.normal(0.0, RELATIVE_SPREAD[name])))
    return out


def unit_config(base: PhysicsConfig, rng: np.random.Generator, defect: str | None) -> PhysicsConfig:
    """One unit of the batch: ``base`` with the spread drawn from ``rng`` and ``defect`` planted."""
    if defect is not None and defect not in DEFECTS:
        raise ValueError(f"defect {defect!r} is not one of {DEFECTS}")
    effects = [EffectConfig(e.identifier, _spread(e.params, rng)) for e in base.effects]
    noise = [
        NoiseConfig(
            n.identifier, {k: v * (1.0 + float(rng.normal(0.0, WHITE_SPREAD))) for k, v in n.params.items()}
        )
        if n.identifier == WHITE_NOISE
        else n
        for n in base.noise
    ]
    if defect == LAG_X3:
        effects = [
            EffectConfig(e.identifier, {"tau_s": 3.0 * e.params["tau_s"]}) if e.identifier == LAG else e
            for e in effects
        ]
    if defect == STEP:
        _start, segments = base.protocol.resolved()
        duration = sum(s.duration_s for s in segments)
        effects.append(
            EffectConfig(STEP, {"t_s": round(BIAS_STEP_AT * duration, 1), "step_mg": BIAS_STEP_MG})
        )
    order = list(EFFECTS)
    effects.sort(key=lambda e: order.index(e.identifier))
    return replace(base, effects=tuple(effects), noise=tuple(noise))


def write_fleet(
    directory: Path,
    n_units: int = 24,
    *,
    defects: dict[str, str] | None = None,
    seed: int = 0,
    methods: tuple[str, ...] | None = None,
    diagnose_blocks: int | None = 120,
) -> Path:
    """Simulate the batch into ``directory/runs/`` and write ``directory/fleet.toml``; returns its path.

    Unit ids are ``U01``, ``U02``, ...; ``defects`` maps unit id -> one of :data:`DEFECTS`;
    ``methods`` None leaves the manifest's default (the cheap memoryless methods).
    """
    defects = DEFAULT_DEFECTS if defects is None else defects
    base = sensor()
    runs = directory / "runs"
    runs.mkdir(parents=True, exist_ok=True)
    units = []
    for index in range(n_units):
        unit_id = f"U{index + 1:02d}"
        rng = np.random.default_rng(np.random.SeedSequence([seed, index]))
        cfg = unit_config(base, rng, defects.get(unit_id))
        names = []
        for run in (1, 2):
            rec = simulate(cfg, int(np.random.SeedSequence([seed, index, run]).generate_state(1)[0]))
            name = f"runs/{unit_id}_run{run}.npz"
            write_recording(rec, directory / name)
            names.append(name)
        units.append({"id": unit_id, "recordings": names})
    fleet: dict[str, object] = {} if methods is None else {"methods": list(methods)}
    if diagnose_blocks is not None:
        fleet["diagnose_blocks"] = diagnose_blocks
    manifest = directory / "fleet.toml"
    manifest.write_text(tomli_w.dumps({"fleet": fleet, "unit": units}), encoding="utf-8")
    return manifest
