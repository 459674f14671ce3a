"""The DLSTM channels of the IMU module (codegen/imu.py): each keeps the one-channel module of its
checkpoint, named ``NAME_<channel>`` and embedded verbatim (its macros: ``_stream_imu.j2``); the
channel's record names only its kind and sensor, it has no calibration-blob record."""

from __future__ import annotations

from pathlib import Path

from codegen.families.stream.quantise import QStream
from codegen.family import ImuForm
from codegen.imu_record import KIND_STREAM, ChannelTables, ImuPart
from codegen.render import render_sources, validate_name
from trainer.errors import UserError


def imu_tables(q: QStream, sensor: int) -> ChannelTables:
    """Its numbers are in its own module, embedded in the IMU module: the record names its kind and sensor."""
    return ChannelTables(KIND_STREAM, sensor, 0, 0, 0, 0, 0, (0, 0, 0, 0), (), (), ())


def stream_module_name(module: str, channel: str) -> str:
    """The C name of a DLSTM channel's own module inside the IMU module ``module``."""
    sub = f"{module}_{channel}"
    try:
        return validate_name(sub)
    except UserError as exc:
        raise UserError(
            f"--name {module}: the DLSTM channel {channel} is the embedded module {sub}, which is not a "
            f"valid module name ({exc}); choose a shorter --name"
        ) from None


def embedded_modules(part: ImuPart) -> list[dict[str, object]]:
    """Each DLSTM channel's one-channel header and source (codegen/render.py, unchanged), to embed."""
    name = part.module
    modules: list[dict[str, object]] = []
    for channel, index in zip(part.channels, part.indices, strict=True):
        sub = stream_module_name(name, channel.name)
        files = render_sources(
            channel.model.quantised,
            sub,
            channel.model.sha256,
            notes=channel.model.notes,
            sensor=channel.model.sensor,
            shown=channel.model.name,
        )
        own_include = f'#include "{sub}.h"\n'
        assert files[f"{sub}.c"].count(own_include) == 1
        modules.append(
            {
                "name": channel.name,
                "sub": sub,
                "index": index,
                "header": files[f"{sub}.h"].rstrip("\n"),
                "source": files[f"{sub}.c"]
                .replace(own_include, f"/* {sub}.h: embedded in {name}.h */\n")
                .rstrip("\n"),
            }
        )
    return modules


FORM = ImuForm(
    KIND_STREAM,
    imu_tables,
    code="STREAM",
    label="DLSTM",
    snippets=Path(__file__).with_name("_stream_imu.j2"),
    context=lambda part: {"stream_channels": embedded_modules(part)},
    manifest=lambda part: {
        "embedded_modules": {c.name: stream_module_name(part.module, c.name) for c in part.channels}
    },
    layout_tag="D",
    timed="DLSTM channels' windows and network steps",
    timed_brief="DLSTM windows",
)
