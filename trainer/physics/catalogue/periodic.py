"""``periodic``: a periodic disturbance, ``amp * sin(2 pi t / period_s + phase)`` (repeatable)."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from trainer.physics.catalogue.base import (
    BlockDesign,
    Effect,
    Finder,
    FinderData,
    FinderTerm,
    Identifiability,
    Param,
    Region,
    Scenario,
    WhereContext,
)

REGION_KIND = "periodic"  # how a periodic component of a residual is reported


def sinusoid(t: np.ndarray, amp_mg: float, period_s: float, phase_rad: float) -> np.ndarray:
    return amp_mg * np.sin(2.0 * np.pi * t / period_s + phase_rad)


def _sinc(x: np.ndarray | float) -> np.ndarray | float:
    return np.sinc(np.asarray(x) / np.pi)


def periodic_columns(t: np.ndarray, period_s: float, block_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact block means of ``sin`` and ``cos`` of ``2 pi t / P`` (centres ``t``, width ``block_s``)."""
    w = 2.0 * math.pi / period_s
    gain = float(_sinc(w * block_s / 2.0))
    return gain * np.sin(w * t), gain * np.cos(w * t)


def _columns(term: FinderTerm, d: BlockDesign) -> list[tuple[str, np.ndarray]]:
    s, c = periodic_columns(d.data.t, term.nl[0], d.data.block_s)
    if term.offset is not None:  # a fast component fitted on the fine grid: a known contribution
        amp, phase = term.offset
        d.offset += amp * (math.cos(phase) * s + math.sin(phase) * c)
        return []
    return [("sin", s), ("cos", c)]


def _fine_offset(term: FinderTerm, t: np.ndarray) -> np.ndarray:
    if term.offset is None:
        raise ValueError("periodic: the fine-grid part is that of a held component (term.offset)")
    amp, phase = term.offset
    return amp * np.sin(2 * math.pi * t / term.nl[0] + phase)


def _same_instance(a: FinderTerm, b: FinderTerm, data: FinderData) -> bool:
    """Two frequencies within ``1 / duration`` (the Fourier resolution of the run) are one component."""
    return bool(abs(1.0 / a.nl[0] - 1.0 / b.nl[0]) <= 1.0 / data.duration_s)


def _where(p: Mapping[str, float], ctx: WhereContext) -> list[Region]:
    """The whole run, with the selection's evidence."""
    note = f"period {p['period_s']:.4g} s, whole run"
    return [ctx.region(0, ctx.data.n, {"evidence": ctx.evidence}, REGION_KIND, note)]


def _to_params(term: FinderTerm, lin: Mapping[str, float]) -> dict[str, float]:
    if term.offset is not None:
        amp, phase = term.offset
    else:
        amp, phase = math.hypot(lin["sin"], lin["cos"]), math.atan2(lin["cos"], lin["sin"])
    return {"amp_mg": amp, "period_s": term.nl[0], "phase_rad": phase}


def _sampling_check(p: Mapping[str, float], fs: float) -> str | None:
    if p["period_s"] <= 2.0 / fs:
        return f"[effects.periodic] period_s {p['period_s']:g} is not above two sample periods ({2 / fs:g} s)"
    return None


def _draw(rng: np.random.Generator, duration: float, sign: float) -> dict[str, float]:
    period = float(np.exp(rng.uniform(math.log(20.0), math.log(1500.0))))
    return {
        "amp_mg": float(rng.uniform(0.015, 0.06)),
        "period_s": period,
        "phase_rad": float(rng.uniform(-3.1, 3.1)),
    }


DEFINITION = Effect(
    identifier="periodic",
    params=(
        Param("amp_mg", unit="mg", plausible=(0.005, 1.0)),
        Param("period_s", "positive", unit="s", plausible=(5.0, 2000.0)),
        Param("phase_rad", default=0.0, unit="rad"),
    ),
    summary="amp * sin(2 pi t / period_s + phase) (chamber compressor, mains beat)",
    contribution=lambda p, s: sinusoid(s.t, p["amp_mg"], p["period_s"], p["phase_rad"]),
    multi_instance=True,
    sampling_check=_sampling_check,
    finder=Finder(
        search="sinusoid",
        nonlinear=(("period_s", True),),
        bounds=lambda data: ((max(2.0 * data.fine_step_s * 1.25, 4.0), 0.5 * data.duration_s),),
        max_terms=3,
        same_instance=_same_instance,
        # a period found by scanning hundreds of positions counts twice (modified BIC, look-elsewhere)
        bic_nonlinear=2,
        columns=_columns,
        fine_offset=_fine_offset,
        to_params=_to_params,
        where=_where,
        identifiability=lambda p: Identifiability(
            True, f"{p.duration_s:.0f} s of data: periods up to half of it"
        ),
        advice="a periodic disturbance (chamber compressor, mains beat, fan): it is not temperature drift",
    ),
    scenario=Scenario(draw=_draw, checked=("amp_mg", "period_s")),
)
