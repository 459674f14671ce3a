"""The physics family's channels in the IMU module (codegen/imu.py): their record, their constants
and state (``NAME_physics_t`` / ``NAME_physics_state_t``, one slot per channel) in the streamed
effects' registry layout, and the template variables of its macros ``_physics_imu.j2``."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from codegen.families.physics.quantise import QLowpass, QPhysics, QTerm, instance_text, instance_words
from codegen.families.physics.render import physics_snippets
from codegen.family import ImuForm
from codegen.imu_record import KIND_PHYSICS, ChannelTables, ImuPart
from trainer.errors import UserError
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
MAX_BITS = 32  # NAME_physics_t.terms is a uint32_t

Slot = tuple[FixedPoint, str]  # a C term of the layout and its instance suffix ("", "_2", ...)


def instance_counts(models: Iterable[QPhysics]) -> dict[str, int]:
    """How many slots of each C term the module's layout has: the most instances of it any of its
    physics channels carries (an effect may have several, each its own constants and state), at
    least one (every registry term keeps its slot, as in a module of one-instance channels)."""
    counts = {f.name: 1 for f in c_terms()}
    for q in models:
        for name, n in Counter(t.fixed.name for t in q.terms).items():
            counts[name] = max(counts[name], n)
    return counts


def slots(counts: dict[str, int]) -> list[Slot]:
    """The layout's C term slots in step order: each registry term, its further instances after it."""
    return [(f, "" if k == 0 else f"_{k + 1}") for f in c_terms() for k in range(counts[f.name])]


def _option(f: FixedPoint, suffix: str) -> str | None:
    """The option bit of a slot whose word the polynomial reads (READS_PLAY, READS_PLAY_2)."""
    return None if f.poly_reads is None else f"READS_{(f.poly_reads + suffix).upper()}"


def phys_terms(counts: dict[str, int] | None = None) -> dict[str, int]:
    """A physics channel's terms, bits of NAME_physics_t.terms (the header defines them from these): one
    per C term of the streamed effects' registry, then its options, in step order, then PLAY_START,
    then the further instances' slots and options (``counts``: :func:`instance_counts`)."""
    names = [t.name.upper() for t in c_terms()] + c_options() + [PLAY_START]
    for f, suffix in slots(counts or instance_counts([])):
        option = _option(f, suffix)
        if suffix:
            names += [f"{f.name}{suffix}".upper(), *([option] if option is not None else [])]
    if len(names) > MAX_BITS:
        raise ValueError(f"{len(names)} physics term bits, more than {MAX_BITS}")
    return {name: 1 << k for k, name in enumerate(names)}


@dataclass(frozen=True)
class PhysicsTables:
    """A physics channel's constants exactly as ``NAME_physics_t`` holds them (its clip range, frac
    and cubic are in the channel's record: ``ChannelTables``), in the module's layout (:func:`slots`
    of :func:`trainer.physics.catalogue.streamed.c_terms`; zeros for a slot the channel lacks)."""

    terms: int  # phys_terms() bits
    centre: int  # mdegC
    scale: int  # 2^tf
    u_scale: int  # 2^u_shift
    filters: list[tuple[int, int, int, int]]  # per filter: c, b0, step_scale 2^(tf - s), s
    margins: list[int]  # per margin (the play's half width), Q(tf) mdegC
    play_start: int  # where the play operator starts at power-on (with the PLAY_START bit), Q(tf) mdegC
    gains: list[int]


def channel_slots(q: QPhysics) -> dict[str, tuple[QTerm, str]]:
    """A channel's terms by slot (``branch``, ``branch_2``: a C term's instances in step order), each
    with its slot's suffix."""
    seen: Counter[str] = Counter()
    out = {}
    for t in q.terms:
        seen[t.fixed.name] += 1
        suffix = "" if seen[t.fixed.name] == 1 else f"_{seen[t.fixed.name]}"
        out[t.fixed.name + suffix] = (t, suffix)
    return out


def slot_tables(q: QPhysics, counts: dict[str, int] | None = None) -> PhysicsTables:
    """A physics channel's ``NAME_physics_t`` (its slot of ``cal->physics``) in the layout of
    ``counts`` (:func:`instance_counts`; None: the channel's own)."""

    def lowpass(f: QLowpass | None) -> tuple[int, int, int, int]:
        return (0, 0, 0, 0) if f is None else (f.c_q, f.b_q, 1 << (q.temp_frac - f.shift), f.shift)

    counts = counts or instance_counts([q])
    present = {key: t for key, (t, _) in channel_slots(q).items()}
    bits = phys_terms(counts)
    layout = slots(counts)
    # the polynomial reads the last term's word that switches it (as the golden model's step leaves T_b)
    readers = [_option(t.fixed, x) for t, x in channel_slots(q).values() if t.poly_reads is not None]
    return PhysicsTables(
        sum(bits[key.upper()] for key in present)
        + sum(bits[o] for o in readers[-1:] if o is not None)
        + (0 if q.play_start_q is None else bits[PLAY_START]),
        q.centre_mdegc,
        1 << q.temp_frac,
        1 << q.u_shift,
        [
            lowpass(present[f.name + x].filter if f.name + x in present else None)
            for f, x in layout
            if f.tau_s
        ],
        [(present[f.name + x].margin_q or 0) if f.name + x in present else 0 for f, x in layout if f.margin],
        0 if q.play_start_q is None else q.play_start_q,
        [_gain(present.get(f.name + x)) for f, x in layout if f.gain_mg_per_c],
    )


def _gain(t: QTerm | None) -> int:
    return 0 if t is None or t.gain is None else t.gain.q


def physics_layout(name: str, counts: dict[str, int] | None = None) -> dict[str, object]:
    """What the IMU templates render of the registry's C terms (``counts`` slots of each: an effect's
    further instances in slots of their own): the tables' and the state's fields and each slot's
    step, reading its constants from ``ph`` and testing its bit at run time."""
    counts = counts or instance_counts([])
    layout = slots(counts)
    on = {t: f"(ph->terms & {name.upper()}_PHYS_{t}) != 0u" for t in phys_terms(counts)}

    def values(f: FixedPoint, x: str) -> dict[str, object]:
        filt = {k: f"ph->{f.name}{x}.{k}" for k in ("c", "b0", "shift", "step_scale")}
        margin = f"ph->{f.margin_field}{x}"
        return {**filt, "q": f"ph->{f.name}{x}_q", "margin": margin, "margin_text": f"{margin} (Q(tf) mdegC)"}

    def instance(doc: str, x: str) -> str:
        return f"{doc}, instance {x[1:]}" if x else doc

    u_source = "t_pm"
    for f, x in reversed(layout):
        option = _option(f, x)
        if f.poly_reads is not None and option is not None:
            u_source = f"({on[option]} ? state->{f.poly_reads}{x} : {u_source})"
    words = list({w.name: w for f, x in layout for w in instance_words(f, x)}.values())
    start = f"({on[PLAY_START]} ? ph->play_start : x)"
    play = play_words()
    return {
        "filters": [{"field": f.name + x, "doc": instance(f.filter_doc, x)} for f, x in layout if f.tau_s],
        "margins": [
            {"field": f.margin_field + x, "doc": instance(f.margin_doc, x)} for f, x in layout if f.margin
        ],
        "gains": [
            {"field": f"{f.name}{x}_q", "text": instance_text(f, f.difference_text, x)}
            for f, x in layout
            if f.gain_mg_per_c
        ],
        "state": [w for w in words if w.wide] + [w for w in words if not w.wide],
        "words": words,
        "starts": {w.name + x: start for f, x in layout for w in f.state if w.name in play},
        "terms": [
            {"on": on[(f.name + x).upper()], **physics_snippets(f, values(f, x), x)} for f, x in layout
        ],
        "u_source": u_source,
    }


def imu_context(part: ImuPart) -> dict[str, object]:
    """``_physics_imu.j2``'s variables: the module's layout (as many slots of a C term as the most
    instances any of its channels has) and each channel's slot tables."""
    counts = instance_counts(c.model.quantised for c in part.channels)
    try:
        phys_terms(counts)
    except ValueError:
        most = max(part.channels, key=lambda c: len(c.model.quantised.terms))
        raise UserError(
            f"channel {most.name}: its physics terms need more term bits than an IMU module's physics "
            "channel has (32); export that channel as a one-channel module"
        ) from None
    return {
        "phys_terms": phys_terms(counts),
        "phys": physics_layout(part.module, counts),
        "physics_channels": [
            {"name": c.name, "t": slot_tables(c.model.quantised, counts)} for c in part.channels
        ],
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
