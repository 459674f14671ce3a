"""Frozen reference vectors (tests/refvectors.py): for every method, the generated C and the
golden model reproduce the checked-in outputs of a checked-in model on a checked-in stream. A
change that moves the templates and the golden model together fails here."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from codegen.export import export
from codegen.golden_select import golden_for
from codegen.hostbuild import load_module
from tests import refvectors as ref


@pytest.mark.parametrize("method", ref.methods())
def test_c_and_golden_reproduce_the_frozen_outputs(method: str, tmp_path: Path) -> None:
    model, _ = export(ref.REF_DIR / f"{method}.pt", tmp_path / "out", name="ref")
    accel, temp = ref.load_stream()
    frozen = ref.load_outputs(method)
    assert frozen.size == accel.size == ref.SAMPLES
    host = load_module(tmp_path / "out", "ref", flags=("-O1",))
    state, golden = host.new_state(), golden_for(model.quantised)
    cut = ref.RESET_AT
    c_out = host.run(state, accel[:cut], temp[:cut])
    g_out = golden.run(accel[:cut], temp[:cut])
    host.reset(state)
    golden.reset()
    c_out = np.concatenate((c_out, host.run(state, accel[cut:], temp[cut:])))
    g_out = np.concatenate((g_out, golden.run(accel[cut:], temp[cut:])))
    np.testing.assert_array_equal(c_out, frozen)
    np.testing.assert_array_equal(g_out, frozen)
    assert len(np.unique(frozen)) > 100  # the vectors exercise the model, not a constant
