"""The physics family's manifest section: its rate, formats, filters, gains and bounds."""

from __future__ import annotations

from codegen.families.physics.quantise import QPhysics
from codegen.families.physics.render import play_start_text
from codegen.fixedpoint import INT64_MAX, headroom_bits
from codegen.manifest import six_digits
from codegen.rate import ANY_RATE_MILLIHZ, declared_rate_millihz


def physics_rates(model: QPhysics) -> dict[str, object]:
    """The rate contract, as the header states it: the filters' rate, or any rate without a filter
    (the hysteresis branch is a function of the temperature alone)."""
    millihz = declared_rate_millihz(model)  # the family's time base decides, as for the header
    if millihz == ANY_RATE_MILLIHZ:
        return {
            "sample_rate_hz": None,
            "sample_rate_millihz": millihz,
            "note": "no filter: NAME_step runs at any rate (the hysteresis branch depends on the temperature alone)",
        }
    return {
        "sample_rate_hz": model.rate_hz,
        "sample_rate_millihz": millihz,
        "note": "the filters are discretised for this rate: call NAME_step at exactly this rate",
    }


def physics_manifest(model: QPhysics) -> dict[str, object]:
    return {
        "rates": physics_rates(model),
        "quantisation": {
            "rounding": "floor (filter differences, high words) and half up (Horner products, the drift): "
            "tdc_physics_kernels.h",
            "temperatures": f"int32 Q{model.temp_frac} mdegC about {model.centre_mdegc} mdegC (x, P)",
            "filter_states": f"int64 Q{model.temp_frac + 32} mdegC (the high word is the int32 temperature)",
            "clip_mdegc": [model.clip_lo_mdegc, model.clip_hi_mdegc],
            "polynomial_u": f"T_b 2^{model.u_shift} in Q31 (|u| < 2^31), re-expanded about the centre",
            "coefficients_q": list(model.coefficients_q),
            "coefficient_frac_bits": [model.frac + k for k in range(4)],
            "horner_bounds": list(model.horner_bounds),
            "drift_frac_bits": model.frac,
            "accumulator_frac_bits": model.frac + 32,
            "drift_bound": model.bound,
            "drift_headroom_bits": six_digits(headroom_bits(model.bound, INT64_MAX)),
            "filters": [
                {
                    "name": f.name,
                    "tau_s": f.tau_s,
                    "c_q": f.c_q,
                    "b0_q": f.b_q,
                    "frac_bits": 32 + f.shift,
                    "difference_shift": f.shift,
                    "state_error_bound_mdegc": six_digits(f.error_mdegc),
                    "state_error_bound_drift": six_digits(f.error_mg),  # in the channel's unit (units.unit)
                }
                for f in model.filters
            ],
            "gains": [{"name": g.name, "q": g.q, "difference_bound": g.diff_bound} for g in model.gains],
        },
        "model_tag": model.tag,
        "power_on": f"filters start in equilibrium at the first sample; {play_start_text(model)}",
        "save_restore": "copy NAME_state_t; NAME_restore checks model_tag and every word against the bounds of the step's proofs, and keeps the hysteresis branch",
        "macs_per_sample": 3 + 2 * len(model.filters) + len(model.gains),
    }
