"""The piecewise-linear model (``pla``): slope and intercept of the interval holding T, T clamped
to the front end's range. Its C is ``pla.c.j2`` (one channel) and ``_pla_imu.j2`` of the IMU module."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np

from codegen.family import CFamily, ImuForm
from codegen.fixedpoint import INT32_MAX, INT64_MAX, headroom_bits, round_half_away, rshift_round
from codegen.golden import GoldenBase
from codegen.imu_record import KIND_PLA, ChannelTables
from codegen.manifest import memoryless_rates, six_digits
from codegen.quantize import ACCEL_PER_MG, INT64_SAFE, Limits
from codegen.render import c_rows
from trainer.errors import UserError
from trainer.fields import DottedFields
from trainer.methods import PLA


@dataclass(frozen=True)
class PlaSpec:
    method: str
    split_points_c: np.ndarray
    slopes_mg_per_c: np.ndarray
    intercepts_mg: np.ndarray


def parse(root: DottedFields, payload: DottedFields, method: str) -> PlaSpec:
    """The PLA as the trainer reads it (:func:`trainer.checkpoint.model_of`: evaluate's refusals,
    in the same line, here too), read once."""
    from trainer.baselines.pla import PiecewiseLinear
    from trainer.checkpoint import model_of

    del payload  # read by the model's own from_payload
    model = model_of(root.data, root.source)
    assert isinstance(model, PiecewiseLinear), f"{method} is registered with the PLA's class"
    return PlaSpec(method, model.split_points_c, model.slopes_mg_per_c, model.intercepts_mg)


@dataclass(frozen=True)
class QPla:
    method: str
    limits: Limits
    splits_mdegc: tuple[int, ...]
    slopes_q: tuple[int, ...]  # int32, Q(frac) accel LSB per mdegC
    intercepts_q: tuple[int, ...]  # int64, Q(frac) accel LSB
    frac: int
    bound: int  # worst-case |slope_q * T + intercept_q|


def quantise(spec: PlaSpec, limits: Limits, schedule: str = "step") -> QPla:
    splits = tuple(
        math.ceil(Fraction(s) * 1000) for s in spec.split_points_c
    )  # T_q >= s*1000 <=> T_q >= ceil
    splits = tuple(min(max(s, -INT32_MAX), INT32_MAX) for s in splits)
    t_max = max(-limits.temp_lo_mdegc, limits.temp_hi_mdegc)
    slopes_lsb = [Fraction(v) * ACCEL_PER_MG / 1000 for v in spec.slopes_mg_per_c]  # accel LSB per mdegC
    intercepts_lsb = [Fraction(v) * ACCEL_PER_MG for v in spec.intercepts_mg]
    for frac in range(40, -1, -1):
        slopes = [round_half_away(v * (1 << frac)) for v in slopes_lsb]
        intercepts = [round_half_away(v * (1 << frac)) for v in intercepts_lsb]
        bound = max(abs(s) * t_max + abs(c) for s, c in zip(slopes, intercepts, strict=True))
        if max(abs(s) for s in slopes) <= INT32_MAX and bound < INT64_SAFE:
            return QPla(spec.method, limits, splits, tuple(slopes), tuple(intercepts), frac, bound)
    raise UserError("pla: slopes or intercepts too large for the fixed-point format")


class GoldenPla(GoldenBase):
    model: QPla

    def _run(self, accel: np.ndarray, temp: np.ndarray) -> np.ndarray:
        m = self.model
        t = self._clamp(temp, m.limits.temp_lo_mdegc, m.limits.temp_hi_mdegc)
        k = np.searchsorted(np.asarray(m.splits_mdegc, dtype=np.int64), t, side="right")
        slopes = np.asarray(m.slopes_q, dtype=np.int64)
        intercepts = np.asarray(m.intercepts_q, dtype=np.int64)
        drift = self._sat(rshift_round(slopes[k] * t + intercepts[k], m.frac))
        return self._output(accel, drift)


def context(model: QPla) -> dict[str, object]:
    return {
        "splits": c_rows(model.splits_mdegc) if model.splits_mdegc else "",
        "n_splits": len(model.splits_mdegc),
        "n_intervals": len(model.slopes_q),
        "slopes": c_rows(model.slopes_q),
        "intercepts": c_rows(model.intercepts_q, width=64, per_line=4),
        "frac": model.frac,
    }


def manifest(model: QPla) -> dict[str, object]:
    return {
        "rates": memoryless_rates(),
        "quantisation": {
            "rounding": "half away from zero",
            "split_points_mdegc": list(model.splits_mdegc),
            "slopes": f"int32 Q{model.frac} output LSB (1/16000 of the channel's unit) per mdegC",
            "intercepts": f"int64 Q{model.frac} output LSB",
            "frac_bits": model.frac,
            "bound": model.bound,
            "headroom_bits": six_digits(headroom_bits(model.bound, INT64_MAX)),
        },
        "macs_per_sample": 1,
    }


def tables(model: QPla) -> dict[str, int]:
    return {"pla_tables": 4 * len(model.splits_mdegc) + 4 * len(model.slopes_q) + 8 * len(model.intercepts_q)}


def imu_tables(q: QPla, sensor: int) -> ChannelTables:
    return ChannelTables(
        KIND_PLA, sensor, q.frac, 0, q.limits.temp_lo_mdegc, q.limits.temp_hi_mdegc, 0,
        (0, 0, 0, 0), tuple(q.splits_mdegc), tuple(q.slopes_q), tuple(q.intercepts_q),
    )  # fmt: skip


def imu_blob(t: ChannelTables) -> bytes:
    """Its blob record: the split points, slopes and intercepts (their count in the channel header)."""
    n = len(t.slopes)
    return struct.pack(f"<{n - 1}i{n}i{n}q", *t.splits, *t.slopes, *t.intercepts)


FAMILY = CFamily(
    name=PLA,
    parse=parse,
    quantise=quantise,
    golden=GoldenPla,
    template=Path(__file__).with_name("pla.c.j2"),
    context=context,
    manifest=manifest,
    tables=tables,
    imu=ImuForm(
        KIND_PLA,
        imu_tables,
        code="PLA",
        label="piecewise-linear",
        snippets=Path(__file__).with_name("_pla_imu.j2"),
        blob=imu_blob,
    ),
)
