"""The cubic in temperature (``poly3``): Horner in u = (T - T_ref) / 2^u_shift, T clipped to the
fitted range. Its C is ``cubic.c.j2`` (one channel) and ``_cubic_imu.j2`` of the IMU module; what the
firmware engineer reads of it (the drift formula, its coefficients in the channel's unit, the fixed
point, where the cost is measured) is ``_cubic_doc.j2``, in both headers, rendered from :func:`doc`.

Its fixed-point format is chosen per model by :func:`quantise` and declared once, in :class:`QPoly3`
(``frac``, ``u_shift``, ``t_ref_mdegc``); every text that states it (the C's comments, both headers,
the manifest) is :func:`u_text` and :func:`coefficient_q` of it."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np

from codegen.family import CFamily, ImuForm, InputClamps
from codegen.fixedpoint import INT32_MAX, INT64_MAX, headroom_bits, round_half_away, rshift_round
from codegen.golden import GoldenBase
from codegen.imu_record import KIND_CUBIC, ChannelTables, ImuPart
from codegen.manifest import memoryless_rates, six_digits
from codegen.quantize import ACCEL_PER_MG, INT64_SAFE, Limits
from codegen.render import c_rows
from codegen.step_units import LSB_PER_UNIT, STEP_UNITS
from trainer.errors import UserError
from trainer.fields import DottedFields

MACS_PER_SAMPLE = 3  # the Horner steps: one int64 multiplication each (the manifest's macs_per_sample)
ROUNDING = "half away from zero"  # codegen.fixedpoint's one rule: every product, the drift
DIGITS = 9  # significant digits of a coefficient in the header (%.9g: ~1e-9 of each term)
# where a cubic module's cost is measured (the header names them, no figure: the exporter measures none)
COST_BENCHES = (
    'bench/bench_cortex_m.py (Cortex-M4: docs/firmware.md, "Timing on a Cortex-M4F" and "Memory")',
    'bench/bench_codegen_callgrind.py (host: docs/codegen.md, "Cost")',
)


@dataclass(frozen=True)
class Poly3Spec:
    method: str
    coefficients_mg: np.ndarray  # c0..c3 of (T - t_ref)^k, mg / degC^k
    t_ref_c: float
    temp_range_c: tuple[float, float]
    degree: int = 3  # the model's order (poly1, poly2: the higher coefficients are zero)


def parse(root: DottedFields, payload: DottedFields, method: str) -> Poly3Spec:
    """The cubic as the trainer reads it (:func:`trainer.checkpoint.model_of`: evaluate's refusals,
    in the same line, here too), read once."""
    from trainer.baselines.poly3 import CubicPolynomial
    from trainer.checkpoint import model_of

    del payload  # read by the model's own from_payload
    model = model_of(root.data, root.source)
    assert isinstance(model, CubicPolynomial), f"{method} is registered with the cubic's class"
    return Poly3Spec(
        method,
        np.asarray(model.coefficients, dtype=np.float64),
        model.t_ref_c,
        model.temp_range_c,
        model.degree,
    )


@dataclass(frozen=True)
class QPoly3:
    method: str
    limits: Limits
    clip_lo_mdegc: int
    clip_hi_mdegc: int
    t_ref_mdegc: int
    u_shift: int  # u = (T - T_ref) / 2**u_shift, |u| <= 1
    coefficients_q: tuple[int, ...]  # int32, d0..d3, Q(frac) accel LSB
    frac: int
    bound: int  # worst-case |Horner accumulator|
    degree: int = 3  # the float model's order (its higher d_k are 0)
    # the float model's c0..c3 re-expanded exactly about t_ref_mdegc: the same polynomial, of
    # (T - T_ref)^k in degC, in the channel's unit per degC^k (the header prints them)
    coefficients_unit: tuple[Fraction, ...] = ()


def u_text(model: QPoly3) -> str:
    """The Q format of u, as the C's comments, the headers and the manifest say it."""
    return f"(T - T_ref) / 2^{model.u_shift}"


def coefficient_q(model: QPoly3) -> str:
    """The Q format of d0..d3 (of the output LSB), as the C's comments, the headers and the manifest say it."""
    return f"Q{model.frac}"


def quantise(spec: Poly3Spec, limits: Limits, schedule: str = "step") -> QPoly3:
    lo = round_half_away(Fraction(spec.temp_range_c[0]) * 1000)
    hi = round_half_away(Fraction(spec.temp_range_c[1]) * 1000)
    if not (-INT32_MAX <= lo < hi <= INT32_MAX):
        raise UserError(f"poly3: temperature range {spec.temp_range_c} degC is outside int32 mdegC")
    t_ref = round_half_away(Fraction(spec.t_ref_c) * 1000)
    t_ref = min(max(t_ref, lo), hi)
    u_shift = max(1, math.ceil(math.log2(max(abs(lo - t_ref), abs(hi - t_ref), 1))))
    delta = t_ref - Fraction(spec.t_ref_c) * 1000  # exact: p(T - t_ref) = q(T - T_ref_int)
    e = [Fraction(c) * ACCEL_PER_MG / Fraction(1000) ** k for k, c in enumerate(spec.coefficients_mg)]
    shifted = [sum(e[k] * math.comb(k, j) * delta ** (k - j) for k in range(j, 4)) for j in range(4)]
    d = [v * Fraction(2) ** (u_shift * j) for j, v in enumerate(shifted)]  # coefficients of u^j, accel LSB
    for frac in range(40, -1, -1):
        coeffs = [round_half_away(v * Fraction(2) ** frac) for v in d]
        bound = sum(abs(c) for c in coeffs) + 3
        if max(abs(c) for c in coeffs) <= INT32_MAX and bound << u_shift < INT64_SAFE:
            unit = tuple(v * Fraction(1000) ** j / ACCEL_PER_MG for j, v in enumerate(shifted))
            return QPoly3(
                spec.method, limits, lo, hi, t_ref, u_shift, tuple(coeffs), frac, bound, spec.degree, unit
            )
    raise UserError("poly3: coefficients too large for the fixed-point format")


class GoldenPoly3(GoldenBase):
    model: QPoly3

    def _run(self, accel: np.ndarray, temp: np.ndarray) -> np.ndarray:
        m = self.model
        u = self._clamp(temp, m.clip_lo_mdegc, m.clip_hi_mdegc) - m.t_ref_mdegc
        d0, d1, d2, d3 = m.coefficients_q
        acc = np.full(u.shape, d3, dtype=np.int64)
        for coefficient in (d2, d1, d0):
            acc = rshift_round(acc * u, m.u_shift) + coefficient
        drift = self._sat(rshift_round(acc, m.frac))
        return self._output(accel, drift)


def input_clamps(model: QPoly3) -> InputClamps:
    """T clipped to the fitted range (the float cubic holds the edge too); the raw input as it comes."""
    return InputClamps((model.clip_lo_mdegc, model.clip_hi_mdegc))


def _degc(mdegc: int) -> str:
    """A whole-mdegC temperature in degC, exactly (28182 -> "28.182", 74000 -> "74")."""
    return f"{mdegc / 1000:.3f}".rstrip("0").rstrip(".")


def doc(model: QPoly3) -> dict[str, object]:
    """What the headers say of a cubic (``_cubic_doc.j2``): the formula the step computes, in the
    channel's unit, its coefficients (the float model's, :data:`DIGITS` significant digits), the clamp,
    the fixed point (from the one declaration: :func:`u_text`, :func:`coefficient_q`) and where the
    cost is measured. Every figure is the model's."""
    unit = STEP_UNITS[model.limits.unit].label
    terms: list[dict[str, object]] = []
    powers = []
    for k in range(model.degree + 1):
        per = "" if k == 0 else ("/degC" if k == 1 else f"/degC^{k}")
        value = f"{float(model.coefficients_unit[k]):.{DIGITS}g}"
        powers.append(f"c{k}" + ("" if k == 0 else (" dT" if k == 1 else f" dT^{k}")))
        terms.append({"name": f"c{k}", "value": value, "unit": unit + per})
    return {
        "unit": unit,
        "lsb_per_unit": LSB_PER_UNIT,
        "lsb": STEP_UNITS[model.limits.unit].short,
        "terms": terms,
        "formula": " + ".join(powers),
        "degree": model.degree,
        "t_ref_c": _degc(model.t_ref_mdegc),
        "t_ref_mdegc": model.t_ref_mdegc,
        "t_min_c": _degc(model.clip_lo_mdegc),
        "t_max_c": _degc(model.clip_hi_mdegc),
        "u": u_text(model),
        "u_shift": model.u_shift,
        "q": coefficient_q(model),
        "frac": model.frac,
        **common(),
    }


def common() -> dict[str, object]:
    """What every cubic's words share: the rounding, the multiplications per sample, the digits of
    its coefficients and where its cost is measured."""
    return {"rounding": ROUNDING, "macs": MACS_PER_SAMPLE, "digits": DIGITS, "benches": COST_BENCHES}


def context(model: QPoly3) -> dict[str, object]:
    return {
        "coefficients": c_rows(model.coefficients_q),
        "frac": model.frac,
        "u_shift": model.u_shift,
        "t_ref": model.t_ref_mdegc,
        "u_text": u_text(model),
        "coefficient_q": coefficient_q(model),
        "cubic": doc(model),
    }


def imu_context(part: ImuPart) -> dict[str, object]:
    """The IMU header's words on its cubic channels (``_cubic_imu.j2``): each one's :func:`doc`, by name."""
    return {
        "cubic_docs": {c.name: doc(c.model.quantised) for c in part.channels},
        "cubic_common": common(),
    }


def manifest(model: QPoly3) -> dict[str, object]:
    return {
        "rates": memoryless_rates(),
        "quantisation": {
            "rounding": ROUNDING,
            "clip_mdegc": [model.clip_lo_mdegc, model.clip_hi_mdegc],
            "t_ref_mdegc": model.t_ref_mdegc,
            "u": u_text(model),
            "coefficients": f"int32 {coefficient_q(model)} output LSB (1/16000 of the channel's unit), of u^0..u^3",
            "coefficients_q": list(model.coefficients_q),
            "frac_bits": model.frac,
            "horner_bound": model.bound,
            "horner_headroom_bits": six_digits(headroom_bits(model.bound * 2.0**model.u_shift, INT64_MAX)),
        },
        "macs_per_sample": MACS_PER_SAMPLE,
    }


def tables(model: QPoly3) -> dict[str, int]:
    return {"poly3_coefficients": 16}


def imu_tables(q: QPoly3, sensor: int) -> ChannelTables:
    return ChannelTables(
        KIND_CUBIC, sensor, q.frac, q.u_shift, q.clip_lo_mdegc, q.clip_hi_mdegc, q.t_ref_mdegc,
        tuple(q.coefficients_q), (), (), (),
    )  # fmt: skip


def imu_blob(t: ChannelTables) -> bytes:
    """Its blob record: d0..d3."""
    return struct.pack("<4i", *t.coefficients)


FAMILY = CFamily(
    name="cubic",
    parse=parse,
    quantise=quantise,
    golden=GoldenPoly3,
    template=Path(__file__).with_name("cubic.c.j2"),
    context=context,
    manifest=manifest,
    tables=tables,
    input_clamps=input_clamps,
    usage=Path(__file__).with_name("_cubic.h.j2"),
    imu=ImuForm(
        KIND_CUBIC,
        imu_tables,
        code="CUBIC",
        label="cubic",
        snippets=Path(__file__).with_name("_cubic_imu.j2"),
        context=imu_context,
        blob=imu_blob,
    ),
)
