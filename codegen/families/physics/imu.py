"""The physics family's channels in the IMU module (codegen/imu.py): their record, their constants
and state (``NAME_physics_t`` / ``NAME_physics_state_t``, one slot per channel) in the streamed
effects' registry layout, and the template variables of its macros ``_physics_imu.j2``."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from codegen.families.physics.quantise import QLowpass, QPhysics
from codegen.families.physics.render import physics_snippets
from codegen.family import ImuForm
from codegen.imu_record import KIND_PHYSICS, ChannelTables, ImuPart
from trainer.methods import PHYSICS_RENDERER
from trainer.physics.catalogue.streamed import c_options, c_terms, play_words
from trainer.physics.catalogue.streaming import FixedPoint


def imu_tables(q: QPhysics, sensor: int) -> ChannelTables:
    """Its clip range, frac and cubic (its filters and gains: :func:`slot_tables`)."""
    return ChannelTables(
        KIND_PHYSICS, sensor, q.frac, q.u_shift, q.clip_lo_mdegc, q.clip_hi_mdegc, 0,
        tuple(q.coefficients_q), (), (), (),
    )  # fmt: skip


PLAY_START = "PLAY_START"  # the bit: the play operator starts at NAME_physics_t.play_start, not at x


def phys_terms() -> dict[str, int]:
    """A physics channel's terms, bits of NAME_physics_t.terms (the header defines them from these): one
    per C term of the streamed effects' registry, then its options, in step order, then PLAY_START."""
    names = [t.name.upper() for t in c_terms()] + c_options() + [PLAY_START]
    return {name: 1 << k for k, name in enumerate(names)}


@dataclass(frozen=True)
class PhysicsTables:
    """A physics channel's constants exactly as ``NAME_physics_t`` holds them (its clip range, frac
    and cubic are in the channel's record: ``ChannelTables``), in the registry's layout
    (:func:`trainer.physics.catalogue.streamed.c_terms`; zeros for a term the channel lacks)."""

    terms: int  # phys_terms() bits
    centre: int  # mdegC
    scale: int  # 2^tf
    u_scale: int  # 2^u_shift
    filters: list[tuple[int, int, int, int]]  # per filter: c, b0, step_scale 2^(tf - s), s
    margins: list[int]  # per margin (the play's half width), Q(tf) mdegC
    play_start: int  # where the play operator starts at power-on (with the PLAY_START bit), Q(tf) mdegC
    gains: list[int]


def slot_tables(q: QPhysics) -> PhysicsTables:
    """A physics channel's ``NAME_physics_t`` (its slot of ``cal->physics``)."""

    def lowpass(f: QLowpass | None) -> tuple[int, int, int, int]:
        return (0, 0, 0, 0) if f is None else (f.c_q, f.b_q, 1 << (q.temp_frac - f.shift), f.shift)

    present = {t.fixed.name: t for t in q.terms}
    bits = phys_terms()
    layout = c_terms()
    return PhysicsTables(
        sum(bits[name.upper()] for name in present)
        + sum(bits[o] for o in q.options)
        + (0 if q.play_start_q is None else bits[PLAY_START]),
        q.centre_mdegc,
        1 << q.temp_frac,
        1 << q.u_shift,
        [lowpass(present[f.name].filter if f.name in present else None) for f in layout if f.tau_s],
        [(present[f.name].margin_q or 0) if f.name in present else 0 for f in layout if f.margin],
        0 if q.play_start_q is None else q.play_start_q,
        [
            present[f.name].gain.q if f.name in present and present[f.name].gain else 0  # type: ignore[union-attr]
            for f in layout
            if f.gain_mg_per_c
        ],
    )


def physics_layout(name: str) -> dict[str, object]:
    """What the IMU templates render of the registry's C terms: the tables' and the state's fields
    and each term's step, reading its constants from ``ph`` and testing its bit at run time."""
    layout = c_terms()
    on = {t: f"(ph->terms & {name.upper()}_PHYS_{t}) != 0u" for t in phys_terms()}

    def values(f: FixedPoint) -> dict[str, object]:
        filt = {k: f"ph->{f.name}.{k}" for k in ("c", "b0", "shift", "step_scale")}
        margin = f"ph->{f.margin_field}"
        return {**filt, "q": f"ph->{f.name}_q", "margin": margin, "margin_text": f"{margin} (Q(tf) mdegC)"}

    u_source = "t_pm"
    for f in reversed(layout):
        if f.poly_reads is not None and f.option is not None:
            u_source = f"({on[f.option]} ? state->{f.poly_reads} : {u_source})"
    words = list({w.name: w for f in layout for w in f.state}.values())
    start = f"({on[PLAY_START]} ? ph->play_start : x)"
    return {
        "filters": [{"field": f.name, "doc": f.filter_doc} for f in layout if f.tau_s],
        "margins": [{"field": f.margin_field, "doc": f.margin_doc} for f in layout if f.margin],
        "gains": [{"field": f"{f.name}_q", "text": f.difference_text} for f in layout if f.gain_mg_per_c],
        "state": [w for w in words if w.wide] + [w for w in words if not w.wide],
        "words": words,
        "starts": {w.name: start for w in words if w.name in play_words()},
        "terms": [{"on": on[f.name.upper()], **physics_snippets(f, values(f))} for f in layout],
        "u_source": u_source,
    }


def imu_context(part: ImuPart) -> dict[str, object]:
    """``_physics_imu.j2``'s variables: the registry's layout and each channel's slot tables."""
    return {
        "phys_terms": phys_terms(),
        "phys": physics_layout(part.module),
        "physics_channels": [{"name": c.name, "t": slot_tables(c.model.quantised)} for c in part.channels],
    }


FORM = ImuForm(
    KIND_PHYSICS,
    imu_tables,
    code="PHYSICS",
    label=PHYSICS_RENDERER,
    snippets=Path(__file__).with_name("_physics_imu.j2"),
    context=imu_context,
    slots=True,
    layout_tag="P",
    timed="physics channels' filters",
    timed_brief="physics filters",
)
