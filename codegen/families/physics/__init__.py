"""The grey-box physics family: a cubic of the clipped temperature plus the streamed effects'
terms (lag, hysteresis branch, rate, creep). Its per-effect stages stay in
:func:`codegen.spec.parse_physics`, :func:`codegen.quantize.quantise_physics`,
:class:`codegen.golden.GoldenPhysics`, the templates ``_physics.c.j2`` / ``_physics_step.c.j2`` (here),
the kernel header ``tdc_physics_kernels.h`` and :func:`codegen.manifest.physics_manifest`
(trainer/physics/catalogue/ is to hold what each effect needs of them)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

from codegen.family import CFamily, ImuForm, TimeBase
from codegen.golden import GoldenPhysics
from codegen.imu import KIND_PHYSICS, ChannelTables
from codegen.manifest import physics_manifest
from codegen.quantize import Limits, QPhysics, quantise_physics
from codegen.render import PHYSICS_KERNEL_HEADER, physics_context, physics_tables
from codegen.spec import PhysicsSpec, parse_physics
from trainer.methods import PHYSICS_RENDERER
from trainer.train_stats import TrainStats


def quantise(spec: PhysicsSpec, limits: Limits, schedule: str) -> QPhysics:
    return quantise_physics(spec, limits)


def context(model: QPhysics) -> dict[str, object]:
    return {**physics_context(model), "macros": [("MODEL_TAG", f"{model.tag}u")]}


def retime(raw: dict[str, Any], millihz: int) -> dict[str, Any]:
    """The filters are discretised from their time constants at ``train_stats.sample_rate_hz``."""
    stats = replace(TrainStats.of_checkpoint(raw), sample_rate_hz=millihz / 1000)
    return {**raw, "train_stats": stats.to_dict()}


def trained_hz(raw: dict[str, Any]) -> float:
    rate_hz = TrainStats.of_checkpoint(raw).sample_rate_hz
    if rate_hz is None:
        raise KeyError("train_stats.sample_rate_hz")
    return rate_hz


TIME_BASE = TimeBase(
    rate_hz=lambda model: model.rate_hz,
    trained_hz=trained_hz,
    retime=retime,
    what="filter coefficients",
)


def imu_tables(q: QPhysics, sensor: int) -> ChannelTables:
    """Its clip range, frac and cubic (its filters and gains: codegen.imu.physics_tables)."""
    return ChannelTables(
        KIND_PHYSICS, sensor, q.frac, q.u_shift, q.clip_lo_mdegc, q.clip_hi_mdegc, 0,
        tuple(q.coefficients_q), (), (), (),
    )  # fmt: skip


FAMILY = CFamily(
    name=PHYSICS_RENDERER,
    parse=parse_physics,
    quantise=quantise,
    golden=GoldenPhysics,
    template=Path(__file__).with_name("_physics.c.j2"),
    context=context,
    manifest=physics_manifest,
    tables=physics_tables,
    kernels={"physics_kernels": PHYSICS_KERNEL_HEADER},
    restore=True,
    time_base=TIME_BASE,
    imu=ImuForm(KIND_PHYSICS, imu_tables),
)
