"""Comparing a C module with its golden model: state structs, and the golden replay of a harness stream."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from codegen.hostbuild import CMD_INIT, CMD_RESET


def assert_states_equal(c_state: dict[str, Any], golden_state: dict[str, Any]) -> None:
    assert c_state.keys() == golden_state.keys()
    for key in c_state:
        np.testing.assert_array_equal(np.asarray(c_state[key]), np.asarray(golden_state[key]), err_msg=key)


def replay(golden: Any, accel: np.ndarray, temp: np.ndarray, commands: np.ndarray) -> np.ndarray:
    """``golden``'s outputs for a harness stream: ``commands[k]`` (CMD_RESET or CMD_INIT) is applied
    before sample ``k``, as the vector and Cortex-M4 harnesses do."""
    cuts = sorted({0, *np.flatnonzero(commands != 0).tolist(), accel.size})
    out = []
    for a, b in itertools.pairwise(cuts):
        if commands[a] == CMD_RESET:
            golden.reset()
        elif commands[a] == CMD_INIT:
            golden.init()
        out.append(golden.run(accel[a:b], temp[a:b]))
    return np.concatenate(out) if out else np.empty(0, dtype=np.int64)  # an instance with no samples
