"""Identifiability rules shared by several definitions (read from the temperature profile)."""

from __future__ import annotations

from trainer.physics.catalogue.base import FinderProfile, Identifiability


def rate_changes(p: FinderProfile) -> Identifiability:
    """``thermal_lag`` and ``temp_rate``: the heating rate must change (corners, two rates).

    On one constant-rate ramp both are a constant temperature offset the polynomial absorbs.
    """
    if p.corners >= 1 or len(p.ramp_rates) >= 2 or p.reversals >= 1:
        weak = not (p.corners >= 2 or len(p.ramp_rates) >= 2 or p.reversals >= 1)
        reason = (
            f"{p.corners} ramp corner(s), {len(p.ramp_rates)} ramp rate(s), {p.reversals} reversal(s)"
            + ("; only the start of the ramp separates a lag from a dT/dt term" if weak else "")
        )
        return Identifiability(
            True, reason, "a second ramp rate or a hold after the ramp (corners)" if weak else "", weak
        )
    reason = (
        "one constant-rate ramp: a lag or a dT/dt term is a constant temperature offset that the "
        "polynomial absorbs (an uneven heating rate in flight would then skew the compensation)"
    )
    return Identifiability(False, reason, "ramp at two different rates, or add a hold after the ramp")


def whole_run(p: FinderProfile) -> Identifiability:
    """Noise terms: any recording shows them."""
    return Identifiability(True, f"{p.duration_s:.0f} s of data")
