"""The golden model: numpy, exactly the integer arithmetic of the generated C, state included.

It is written from the same rules as the C kernel library (``codegen/kernels/tdc_kernels.h``) but
independently of it, and it is what the C is compared with bit for bit (``codegen verify``, the
tests). Each C family's golden model (its unit's, codegen/families/) derives from
:class:`GoldenBase`: streams fed in chunks of any length, resets in between, and the state
(``state()``) with the C struct's fields.
"""

from __future__ import annotations

import numpy as np

from codegen.family import QuantModel
from codegen.fixedpoint import INT32_MAX, INT32_MIN, sat32
from codegen.quantize import FLAG_INPUT_CLAMPED, FLAG_SATURATED, FLAG_TEMP_OUT_OF_RANGE

UINT32_MAX = (1 << 32) - 1


def _as_int64(values: np.ndarray) -> np.ndarray:
    arr = np.asarray(values)
    if arr.ndim != 1:
        raise ValueError("streams are 1-D arrays")
    if arr.size and (arr.min() < INT32_MIN or arr.max() > INT32_MAX):
        raise ValueError("inputs must be int32 values")
    return arr.astype(np.int64)


class GoldenBase:
    """Common state (flags, sample counter) and the input flags every method shares; each C family
    (codegen/families/) derives its golden model from it."""

    def __init__(self, model: QuantModel) -> None:
        self.model = model
        self.flags = 0
        self.samples = 0
        # per sample of the last run: an input of that sample was clamped (FLAG_INPUT_CLAMPED, sample by sample)
        self.input_clamped = np.zeros(0, dtype=bool)

    def init(self) -> None:
        self.flags = 0
        self.samples = 0
        self.reset()

    def reset(self) -> None:
        """Restart the stream; flags and the sample counter survive (like the C ``_reset``)."""

    def _range_flag(self, temp: np.ndarray) -> None:
        lim = self.model.limits
        if np.any((temp < lim.valid_lo_mdegc) | (temp > lim.valid_hi_mdegc)):
            self.flags |= FLAG_TEMP_OUT_OF_RANGE

    def _clamp(self, x: np.ndarray, lo: int, hi: int) -> np.ndarray:
        """``x`` (a chunk's input) clamped into [lo, hi]: the flag, and the samples it clamped."""
        clamped = np.clip(x, lo, hi)
        beyond = clamped != x
        assert beyond.shape == self.input_clamped.shape, "_clamp takes the whole chunk of run()"
        if np.any(beyond):
            self.flags |= FLAG_INPUT_CLAMPED
            self.input_clamped = self.input_clamped | beyond
        return clamped

    def _sat(self, x: np.ndarray) -> np.ndarray:
        out = sat32(x)
        if np.any(out != x):
            self.flags |= FLAG_SATURATED
        return out

    def _output(self, accel: np.ndarray, estimate: np.ndarray) -> np.ndarray:
        self.samples = min(self.samples + accel.size, UINT32_MAX)
        return self._sat(accel - estimate)

    def run(self, accel: np.ndarray, temp: np.ndarray) -> np.ndarray:
        """Compensated int32 samples (as int64) of one chunk of raw int32 samples."""
        accel, temp = _as_int64(accel), _as_int64(temp)
        if accel.shape != temp.shape:
            raise ValueError("accel and temp must have the same length")
        self.input_clamped = np.zeros(accel.shape, dtype=bool)
        self._range_flag(temp)
        return self._run(accel, temp)

    def _run(self, accel: np.ndarray, temp: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def state(self) -> dict[str, np.ndarray | int]:
        return {"flags": self.flags, "samples": self.samples}
