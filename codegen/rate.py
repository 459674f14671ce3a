"""The rate contract of a generated module: the sample rate it is built for, and re-deriving it.

A memoryless model (cubic, PLA) is a function of the present temperature and runs at any rate
(declared as 0). A model with a time base is built for one rate: the DLSTM front end (windows and
decimation in samples, :meth:`trainer.dlstm.realtime.FrontEnd.at_rate`) and the physics filters
(coefficients from time constants, :mod:`trainer.greybox.stream`). ``codegen export --rate HZ``
re-derives them for the firmware's rate exactly, or refuses in one line; the header declares the
rate as an integer in millihertz next to a compile-time check macro (``module.h.j2``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from codegen import family
from codegen.family import QuantModel, family_of
from trainer import methods as registry
from trainer.compensator import Compensator
from trainer.data.importer import resample_columns
from trainer.data.plausibility import RATE_MAX_HZ, RATE_MIN_HZ
from trainer.data.recording import Recording
from trainer.dlstm.realtime import FrontEnd
from trainer.errors import UserError

ANY_RATE_MILLIHZ = 0  # NAME_SAMPLE_RATE_MILLIHZ of a memoryless module


def rate_millihz(rate_hz: float) -> int:
    return round(rate_hz * 1000)


def parse_rate_hz(rate_hz: float) -> int:
    """``--rate HZ`` as whole millihertz (what the header declares), or a one-line refusal."""
    if not (math.isfinite(rate_hz) and RATE_MIN_HZ <= rate_hz <= RATE_MAX_HZ):
        raise UserError(
            f"--rate {rate_hz:g}: must be a sample rate in Hz within {RATE_MIN_HZ:g} Hz .. {RATE_MAX_HZ / 1e3:g} kHz "
            "(the rates a recording may have: trainer import refuses others as a time unit read wrongly)"
        )
    millihz = rate_millihz(rate_hz)
    if millihz == 0 or abs(rate_hz * 1000 - millihz) > 1e-6 * max(1.0, rate_hz):
        raise UserError(f"--rate {rate_hz!r}: the header declares the rate in whole millihertz; round it")
    return millihz


def declared_rate_millihz(model: QuantModel) -> int:
    """The rate a quantised model is built for, in millihertz; 0 for a memoryless one."""
    time_base = family_of(model).time_base
    return ANY_RATE_MILLIHZ if time_base is None else rate_millihz(time_base.rate_hz(model))


def retime_checkpoint(
    raw: dict[str, Any], millihz: int | None, source: str
) -> tuple[dict[str, Any], str | None]:
    """``raw`` re-derived for ``millihz`` (None or the trained rate: unchanged) and a note saying so.

    A memoryless method is unchanged at any rate. A malformed rate field is left for the parser
    (``codegen.spec``) to report.
    """
    time_base = _time_base(raw)
    if millihz is None or time_base is None:
        return raw, None
    try:
        trained = rate_millihz(time_base.trained_hz(raw))
    except (KeyError, TypeError, ValueError):
        return raw, None
    if trained == millihz:
        return raw, None
    try:
        retimed = time_base.retime(raw, millihz)
    except UserError as exc:
        raise UserError(f"{source}: {exc}") from None
    except (KeyError, TypeError, ValueError):
        return raw, None
    return (
        retimed,
        f"rate: exported for {millihz / 1000:g} Hz (trained at {trained / 1000:g} Hz; "
        f"{time_base.what} re-derived)",
    )


def any_rate_note(raw: dict[str, Any], millihz: int) -> str:
    """The note of a model whose family has a time base but that holds nothing built for a rate (a
    physics model without a filter): it runs at any rate, so ``--rate`` leaves it as trained."""
    time_base = _time_base(raw)
    assert time_base is not None
    return (
        f"rate: --rate {millihz / 1000:g} Hz changes nothing: this model has no {time_base.what} to "
        "re-derive (it runs at any rate)"
    )


def _time_base(raw: dict[str, Any]) -> family.TimeBase | None:
    renderer = registry.REGISTRY[raw["method"]].renderer
    return family.get(renderer).time_base if renderer in family.names() else None


def retime_compensator(model: Compensator, millihz: int) -> None:
    """The float model at the module's rate (verify's reference): the DLSTM front end in samples.

    The physics compensator's float form is a function of time (any rate); memoryless ones too.
    """
    frontend = getattr(model, "frontend", None)
    if isinstance(frontend, FrontEnd) and millihz and rate_millihz(frontend.rate_hz) != millihz:
        model.frontend = frontend.at_rate(millihz)  # type: ignore[attr-defined]


def resample(rec: Recording, rate_hz: float) -> Recording:
    """``rec`` linearly interpolated onto a uniform grid at ``rate_hz`` (the importer's resampler)."""
    t0 = float(rec.time_s[0])
    columns = {k: np.asarray(v, dtype=np.float64) for k, v in rec.columns.items()}
    columns["time_s"] = columns["time_s"] - t0
    out = resample_columns(columns, rate_hz)
    out["time_s"] = out["time_s"] + t0
    return Recording(
        out, {**rec.meta, "sample_rate_hz": repr(float(rate_hz))}, f"{rec.source} at {rate_hz:g} Hz"
    )
