"""The one plausibility rule for fitted effect parameters.

``trainer diagnose`` (which effects it names) and ``trainer fit --method physics`` (which effects
its compensator keeps) both judge a fitted parameter here, against the catalogue's plausible range
(``Param.plausible``; on a gyroscope or barometer an amplitude against the channel's own drift,
:func:`~trainer.physics.catalogue.units.plausible_range`), so the two commands give one verdict.
"""

from __future__ import annotations

from collections.abc import Mapping

from trainer.data.channels import UNIT_LABELS
from trainer.physics.catalogue import PARAMETERS, flagged_range
from trainer.physics.catalogue.units import (
    CATALOGUE_UNIT,
    ChannelScale,
    channel_param_name,
    judged_by_drift_span,
)


def implausible(
    identifier: str, params: Mapping[str, float], scale: ChannelScale | None = None
) -> dict[str, str]:
    """``{catalogue parameter name: why}`` for each fitted parameter outside its plausible range
    (empty: plausible), the reason named as the channel names the parameter."""
    out: dict[str, str] = {}
    unit = scale.unit if scale is not None else CATALOGUE_UNIT
    for name, value in params.items():
        bounds = flagged_range(identifier, name, scale)
        if bounds is None or bounds[0] <= abs(value) <= bounds[1]:
            continue
        shown = channel_param_name(name, unit)
        if value < 0:  # the plausible ranges are of the size: say so for a negative value
            shown, value = f"|{shown}|", abs(value)
        if not judged_by_drift_span(name, scale):
            catalogue = PARAMETERS[(identifier, name)].plausible
            assert catalogue is not None  # a flagged range comes from the catalogue's
            out[name] = (
                f"{shown} = {value:.4g} is outside the catalogue's plausible {catalogue[0]:g}..{catalogue[1]:g}"
            )
        else:
            assert scale is not None
            out[name] = (
                f"{shown} = {value:.4g} is outside the plausible 0..{bounds[1]:.4g} (its contribution would "
                f"exceed the channel's cubic drift span of {scale.drift_span:.4g} {UNIT_LABELS[scale.unit]} "
                "over the run)"
            )
    return out
