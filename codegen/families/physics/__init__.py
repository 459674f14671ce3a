"""The grey-box physics family: a cubic of the clipped temperature plus the streamed effects'
terms (lag, hysteresis branch, rate, creep). Its stages are modules here: the parser :mod:`.spec`,
the quantiser :mod:`.quantise`, the golden model :mod:`.golden`, the manifest section
:mod:`.manifest`, the templates ``_physics.c.j2`` / ``_physics_step.c.j2`` (and the header's
paragraph ``_physics.h.j2``) and their variables, state and kernel header ``tdc_physics_kernels.h``
:mod:`.render`, its IMU-module channel :mod:`.imu` and its macros ``_physics_imu.j2``. What each streamed effect needs of them is its ``FixedPoint``
(trainer/physics/catalogue/)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

from codegen.families.physics.golden import GoldenPhysics
from codegen.families.physics.imu import FORM
from codegen.families.physics.manifest import physics_manifest
from codegen.families.physics.quantise import QPhysics, quantise_physics
from codegen.families.physics.render import KERNEL_PATH, physics_context, physics_state_fields, physics_tables
from codegen.families.physics.spec import parse_physics
from codegen.family import CFamily, InputClamps, TimeBase
from trainer.methods import PHYSICS_RENDERER
from trainer.train_stats import TrainStats


def retime(raw: dict[str, Any], millihz: int) -> dict[str, Any]:
    """The filters are discretised from their time constants at ``train_stats.sample_rate_hz``."""
    stats = replace(TrainStats.of_checkpoint(raw), sample_rate_hz=millihz / 1000)
    return {**raw, "train_stats": stats.to_dict()}


def trained_hz(raw: dict[str, Any]) -> float:
    rate_hz = TrainStats.of_checkpoint(raw).sample_rate_hz
    if rate_hz is None:
        raise KeyError("train_stats.sample_rate_hz")
    return rate_hz


def input_clamps(model: QPhysics) -> InputClamps:
    """T clipped to the training range (the float stream holds the edge too); the raw input as it comes."""
    return InputClamps((model.clip_lo_mdegc, model.clip_hi_mdegc))


TIME_BASE = TimeBase(
    rate_hz=lambda model: model.rate_hz if model.filters else 0.0,  # no filter: any rate
    trained_hz=trained_hz,
    retime=retime,
    what="filter coefficients",
)


FAMILY = CFamily(
    name=PHYSICS_RENDERER,
    parse=parse_physics,
    quantise=quantise_physics,
    golden=GoldenPhysics,
    template=Path(__file__).with_name("_physics.c.j2"),
    usage=Path(__file__).with_name("_physics.h.j2"),
    context=physics_context,
    manifest=physics_manifest,
    tables=physics_tables,
    state=physics_state_fields,
    kernels={"physics_kernels": KERNEL_PATH},
    restore=True,
    time_base=TIME_BASE,
    input_clamps=input_clamps,
    imu=FORM,
)
