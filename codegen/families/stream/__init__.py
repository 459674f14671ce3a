"""The streaming DLSTM family (``lstm-stream``: recursive and temperature input) and the
persistence front end without a network (``mean-stream``): window means, a decimated network, a
held estimate. Its stages are modules here: the parser :mod:`.spec`, the quantiser :mod:`.quantise`,
the golden models :mod:`.golden` and :mod:`.golden_spread` (the spread schedule's), the manifest
section :mod:`.manifest`, the template ``_stream.c.j2`` (and the header's paragraph ``_stream.h.j2``)
and its variables :mod:`.render`, its IMU-module channel :mod:`.imu` (the one-channel module
embedded) and its macros ``_stream_imu.j2``."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from codegen.families.stream.golden import GoldenStream
from codegen.families.stream.golden_spread import GoldenStreamSpread
from codegen.families.stream.imu import FORM
from codegen.families.stream.manifest import stream_manifest
from codegen.families.stream.quantise import SCHEDULES, QStream, quantise_stream
from codegen.families.stream.render import stream_context, stream_state_fields, stream_tables
from codegen.families.stream.spec import parse_dlstm, parse_persistence
from codegen.family import CFamily, InputClamps, TimeBase
from codegen.golden import GoldenBase
from trainer.dlstm.realtime import FrontEnd


def retime_frontend(raw: dict[str, Any], millihz: int) -> dict[str, Any]:
    """The front end's windows and decimation in samples at another rate."""
    payload = raw["payload"]
    frontend = payload["frontend"]
    retimed = FrontEnd.from_dict(frontend).at_rate(millihz).to_dict()
    return {**raw, "payload": {**payload, "frontend": {**frontend, **retimed}}}


TIME_BASE = TimeBase(
    rate_hz=lambda model: model.frontend.rate_hz,
    trained_hz=lambda raw: float(raw["payload"]["frontend"]["rate_hz"]),
    retime=retime_frontend,
    what="windows and decimation",
)


def input_clamps(model: QStream) -> InputClamps:
    """What the front end smooths is clamped: the temperature (a temperature-input network) to the
    front end's range, else the raw input (a recursive network, persistence) to the limit of the
    channel's unit (``--accel-limit-g``, ``--gyro-limit-dps``: codegen/input_limits.py); the other
    input is not read beyond the valid-range flag."""
    if model.kind == "temperature":
        return InputClamps((model.limits.temp_lo_mdegc, model.limits.temp_hi_mdegc))
    return InputClamps(None, model.limits.signal_lsb)


def golden_model(model: QStream) -> GoldenBase:
    """The spread schedule's golden model is its own (golden_spread.py)."""
    return GoldenStreamSpread(model) if model.layers and model.schedule == "spread" else GoldenStream(model)


LSTM = CFamily(
    name="lstm-stream",
    parse=parse_dlstm,
    quantise=quantise_stream,
    golden=golden_model,
    template=Path(__file__).with_name("_stream.c.j2"),
    usage=Path(__file__).with_name("_stream.h.j2"),
    context=stream_context,
    manifest=stream_manifest,
    tables=stream_tables,
    state=stream_state_fields,
    schedules=SCHEDULES,
    time_base=TIME_BASE,
    imu=FORM,
    input_clamps=input_clamps,
)
MEAN = dataclasses.replace(LSTM, name="mean-stream", parse=parse_persistence, schedules=("step",))
