"""Frozen reference vectors (tests/refvectors.py): for every method, the generated C and the
golden model reproduce the checked-in outputs of a checked-in model on a checked-in stream. A
change that moves the templates and the golden model together fails here."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from codegen.export import export
from codegen.families.stream.quantise import QStream
from codegen.golden_select import golden_for
from codegen.hostbuild import load_module
from tests import refvectors as ref
from trainer import methods as registry

INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1


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


NETWORKS = [m for m in ref.methods() if registry.get(m).renderer == "lstm-stream"]  # the DLSTMs


@pytest.mark.parametrize("method", NETWORKS)
def test_spread_schedule_reproduces_the_frozen_outputs_delayed(method: str, tmp_path: Path) -> None:
    """The spread schedule against the frozen step-schedule outputs, not against its own golden
    model: in each segment after init or reset, nothing is removed on the first D - 1 samples and
    the drift removed on sample n is the frozen drift of sample n - (D - 1)."""
    model, _ = export(ref.REF_DIR / f"{method}.pt", tmp_path / "out", name="ref", schedule="spread")
    assert isinstance(model.quantised, QStream)
    lat = model.quantised.latency_samples
    accel, temp = ref.load_stream()
    frozen = ref.load_outputs(method)
    host = load_module(tmp_path / "out", "ref", flags=("-O1",))
    state, cut, n = host.new_state(), ref.RESET_AT, accel.size
    out = host.run(state, accel[:cut], temp[:cut])
    host.reset(state)
    out = np.concatenate((out, host.run(state, accel[cut:], temp[cut:])))

    removed = accel - frozen  # the frozen drift removed, exact where the output did not saturate
    exact = (frozen > INT32_MIN) & (frozen < INT32_MAX)
    expected, known = accel.copy(), np.ones(n, dtype=bool)
    for start, stop in ((0, cut), (cut, n)):
        later = slice(start + lat, stop)
        expected[later] = np.clip(accel[later] - removed[start : stop - lat], INT32_MIN, INT32_MAX)
        known[later] = exact[start : stop - lat]
    assert known.mean() > 0.9 and lat > 0
    np.testing.assert_array_equal(out[known], expected[known])
