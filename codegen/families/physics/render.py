"""The physics family's template variables (``_physics.c.j2``), state struct members, table sizes
and kernel header (``tdc_physics_kernels.h`` of the kernel library, shipped with its modules)."""

from __future__ import annotations

from string import Template

from codegen.families.physics.quantise import QPhysics, QTerm, rename_words
from codegen.qformats import HEADER as KERNEL_HEADER
from codegen.render import Field, bound_text, c_rows
from codegen.step_units import LSB_PER_UNIT, STEP_UNITS
from trainer.physics.catalogue.streaming import HI_BITS, FixedPoint, StateWord

KERNEL_FILE = "tdc_physics_kernels.h"
KERNEL_PATH = KERNEL_HEADER.parent / KERNEL_FILE


def physics_state_fields(model: QPhysics, common: list[Field]) -> list[Field]:
    """The state members: its terms' filter states (int64) and temperatures (int32), then the sample
    bookkeeping and the model tag, the common ones (flags, samples) last."""
    wide = f"Q{model.temp_frac + HI_BITS} mdegC about {model.centre_mdegc} mdegC"
    narrow = f"Q{model.temp_frac} mdegC"
    words = physics_state_words(model)
    return [
        *(Field("int64_t", w.name, (), f"{w.doc}, {wide}") for w in words if w.wide),
        *(Field("int32_t", w.name, (), f"{w.doc}, {narrow}") for w in words if not w.wide),
        Field("int32_t", "temp_prev", (), "previous clipped temperature, mdegC"),
        Field("uint32_t", "started", (), "0 until the first sample after init/reset"),
        Field("uint32_t", "model_tag", (), "NAME_MODEL_TAG: a restore checks it"),
        *common,
    ]


def physics_state_words(model: QPhysics) -> list[StateWord]:
    """The state words a physics model keeps (its terms' filters and play operators, each instance
    its own), in step order."""
    return list(model.words)


def physics_snippets(fixed: FixedPoint, values: dict[str, object], suffix: str = "") -> dict[str, str]:
    """A streamed effect's C step before and after the polynomial, its constants filled in, on the
    state words of its instance with ``suffix`` (``state->play_2``)."""
    return {
        "before": rename_words(fixed, Template(fixed.before_poly).substitute(values), suffix),
        "after": rename_words(fixed, Template(fixed.after_poly).substitute(values), suffix),
    }


def physics_tables(model: QPhysics) -> dict[str, int]:
    return {"physics_coefficients": 16}


def play_start_text(model: QPhysics) -> str:
    """Where the play operator starts at power-on, as the header and the manifest say it (every play
    operator of a model with several instances); every figure in the channel's unit, every bound a
    magnitude (an amplitude may be negative)."""
    branches = [t for t in model.terms if t.margin_q is not None and t.gain is not None]
    several = len(branches) > 1
    plays = ", ".join(f"P{t.suffix}" for t in branches) if several else "P"
    unit = STEP_UNITS[model.limits.unit].label

    def amplitude(term: QTerm) -> float:
        """The branch term's amplitude in the channel's unit (signed, as fitted)."""
        assert term.gain is not None and term.margin_q is not None
        return term.gain.q * term.margin_q / 2 ** (model.frac + 32) / LSB_PER_UNIT

    def half_width_c(term: QTerm) -> float:
        assert term.margin_q is not None
        return term.margin_q / 2**model.temp_frac / 1000

    if model.play_start_q is None:

        def size(term: QTerm) -> str:
            return (
                f"{f'{term.gain_name}: ' if several else ''}|its amplitude|, "
                f"{abs(amplitude(term)):.3g} {unit}, until T has moved by w/2 = {half_width_c(term):.3g} degC"
            )

        sizes = "; ".join(size(term) for term in branches)
        if not sizes:
            return "no play operator (no branch term)"
        if several:
            return (
                f"{plays} each at T_pm, mid-way between its branches (each branch term is then off by at "
                f"most {sizes})"
            )
        return f"P at T_pm, mid-way between the branches (the branch term is then off by at most {sizes})"
    start_c = (model.centre_mdegc + model.play_start_q / 2**model.temp_frac) / 1000.0
    each = "; ".join(
        f"P{t.suffix}: amplitude {amplitude(t):.3g} {unit}, width {2 * half_width_c(t):.3g} degC"
        for t in branches
    )
    worst = sum(2 * abs(amplitude(t)) for t in branches)
    widest = max(2 * half_width_c(t) for t in branches)
    return (
        f"{plays} at {start_c:g} degC (x = {model.play_start_q}), {'each ' if several else ''}clamped into "
        f"T_pm +- w/2 by the first step: the branch of a sensor brought to its first temperature from "
        f"{start_c:g} degC ({each}). A sensor that came another way (a reboot after a warmer or colder "
        f"excursion, or a reset mid-run) can be on another branch: each branch term is then off by up to "
        f"twice |its amplitude| until T has moved by its width, in all at most {worst:.3g} {unit} until T has "
        f"moved by {widest:.3g} degC; restore a saved state to keep the branch"
    )


def usage_paragraphs(model: QPhysics, name: str) -> list[str]:
    """The header's paragraphs on this model: the rate, its drift formula (the cubic and the terms it
    carries, each symbol said once), power-on and save/restore, only what the model has."""
    words = physics_state_words(model)
    has_lag = any(t.fixed.name == "lag" for t in model.terms)
    has_branch = bool(model.play_words)
    reader = next((t for t in reversed(model.terms) if t.poly_reads is not None), None)  # the last
    reads = f"P{reader.suffix}" if reader is not None else ("T_pm" if has_lag else "T")
    terms = [f"{t.gain_name} gain {t.difference_text}" for t in model.terms if t.gain is not None]
    symbols = ["T clipped to the training range", *(w.doc for w in words)]
    if not has_lag and any("T_pm" in text for text in terms):
        symbols.append("T_pm = T (no lag)")
    out = [
        f"Call {name}_step once per raw sample at exactly {model.rate_hz:g} Hz: the filters' coefficients "
        "are computed for it."
        if model.filters
        else f"Call {name}_step once per raw sample, at any rate: this model has no filter.",
        f"Drift = {' + '.join([f'cubic({reads})', *terms])}, with {'; '.join(symbols)} (docs/codegen.md, "
        '"physics").',
    ]
    if model.filters:
        out.append("Power-on: every filter starts in equilibrium at the first sample.")
    if has_branch:
        out.append(f"Power-on, the play operator: {play_start_text(model)}.")
    if words:
        kept = [
            *(["the hysteresis branch is kept"] if has_branch else []),
            *(
                [
                    "the filters are right if the board was off for much less than their time constants "
                    f"(else call {name}_init)"
                ]
                if model.filters
                else []
            ),
        ]
        out.append(
            "Save/restore: the state is plain data; copy it to non-volatile memory at power-down and give "
            f"it to {name}_restore at power-up: {'; '.join(kept)}."
        )
    return out


def physics_context(model: QPhysics) -> dict[str, object]:
    tf = model.temp_frac
    words = physics_state_words(model)
    starts = (
        {}
        if model.play_start_q is None
        else {w.name: str(model.play_start_q) for w in words if w.name in model.play_words}
    )

    def values(t: QTerm) -> dict[str, object]:
        out: dict[str, object] = {}
        if t.filter is not None:
            f = t.filter
            out |= {"c": f.c_q, "b0": f.b_q, "shift": f"{f.shift}u", "step_scale": 2 ** (tf - f.shift)}
        if t.gain is not None:
            out["q"] = t.gain.q
        if t.margin_q is not None:
            out |= {"margin": t.margin_q, "margin_text": f"{t.margin_q} (Q{tf} mdegC)"}
        return out

    return {
        "rate_hz": f"{model.rate_hz:g}",
        "tf": tf,
        "centre": model.centre_mdegc,
        "frac": model.frac,
        "bound_text": bound_text(model.bound),
        "filters": [
            {
                "name": f.name,
                "tau": f"{f.tau_s:g}",
                "shift": f.shift,
                "c_real": f"{f.c_real:.9g}",
                "b0_real": f"{f.b0_real:.9g}",
            }
            for f in model.filters
        ],
        "words": words,
        "word_bounds": {
            w.name: f"INT64_C({model.word_bounds[w.name]})" if w.wide else str(model.word_bounds[w.name])
            for w in words
        },
        "starts": starts,
        "play_start_text": play_start_text(model),
        "usage": usage_paragraphs(
            model, "{name}"
        ),  # the header's paragraphs, the module's name filled in there
        "terms": [{"on": True, **physics_snippets(t.fixed, values(t), t.suffix)} for t in model.terms],
        "u_source": "t_pm" if model.poly_reads is None else f"state->{model.poly_reads}",
        "u_shift": model.u_shift,
        "coefficients": c_rows(model.coefficients_q, per_line=4),
        "macros": [("MODEL_TAG", f"{model.tag}u")],
    }
