"""The catalogue's finder hooks are typed (trainer/physics/catalogue/base.py): what a hook reads of
the finder's objects is a Protocol the real objects satisfy, so the type checker sees through every
hook; no field of the hook records nor any definition's hook says ``Any``."""

from __future__ import annotations

import dataclasses
import inspect

import pytest

from trainer.diagnose.blocks import BlockData
from trainer.diagnose.model import Term
from trainer.diagnose.profile import Profile
from trainer.physics import catalogue
from trainer.physics.catalogue.base import (
    BlockDesign,
    Finder,
    FinderData,
    FinderProfile,
    FinderTerm,
    WhereContext,
)

DEFINITIONS = {d.identifier: d for d in (*catalogue.EFFECTS.values(), *catalogue.NOISE.values())}


@pytest.mark.parametrize("record", [Finder, WhereContext, BlockDesign])
def test_no_hook_field_is_typed_any(record: type) -> None:
    loose = [f.name for f in dataclasses.fields(record) if "Any" in str(f.type)]
    assert loose == []


@pytest.mark.parametrize("identifier", sorted(DEFINITIONS))
def test_no_definition_s_hook_takes_or_returns_any(identifier: str) -> None:
    finder = DEFINITIONS[identifier].finder
    for f in dataclasses.fields(Finder):
        hook = getattr(finder, f.name)
        if inspect.isfunction(hook):
            loose = {k: v for k, v in inspect.get_annotations(hook).items() if "Any" in str(v)}
            assert loose == {}, (f.name, hook.__qualname__)


def test_the_protocols_name_only_what_the_finder_s_objects_have() -> None:
    """Each Protocol member is an attribute or property of the object it stands for (a renamed
    field of BlockData, Term or Profile breaks this test, not a hook at run time)."""
    for protocol, real in ((FinderData, BlockData), (FinderTerm, Term), (FinderProfile, Profile)):
        members = {name for name in vars(protocol) if not name.startswith("_")}
        fields = {f.name for f in dataclasses.fields(real)} | {n for n in vars(real) if not n.startswith("_")}
        assert members and members <= fields, (protocol.__name__, sorted(members - fields))
