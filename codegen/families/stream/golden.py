"""The stream family's golden model: numpy, exactly the integer arithmetic of its C, state included.

It is written from the same rules as the C kernel library (``codegen/kernels/tdc_kernels.h``) but
independently of it, and it is what the C is compared with bit for bit (``codegen verify``, the
tests). Streams can be fed in chunks of any length, with resets in between, and the state
(``state()``) has the C struct's fields.

Speed: the window sums are vectorised over a whole chunk (exact int64 cumulative sums of the
clamped samples over a private history give every window sum by its definition, the last
min(n + 1, W) samples); the C's running sums (``window_current``, ``window_ring``) are tracked
separately for the state comparison, so the two descriptions check each other. Only the network,
which runs once every ``D`` samples, is a Python loop over steps (numpy over the units).

The C accumulates each gate row in int32 starting from the bias (SMLAD on a Cortex-M4);
:mod:`codegen.families.stream.quantise` proves every partial sum stays below 2**31, so the exact int64 dot products
here are the same numbers. The golden rounding is written as floor divisions on int64 (numpy's
``>>``), the C's as unsigned shifts of offset values: the same function, two derivations.

For the error budget the model also keeps, per network step, the estimate before its final
rounding to the output LSB (``fine_estimates``): that rounding is part of the API's unit, not of
the network's arithmetic, and ``codegen verify`` reports both.
"""

from __future__ import annotations

import numpy as np

from codegen.activations import sigmoid_q16, tanh_q15
from codegen.families.stream.quantise import EST_LIMIT, X_SLOTS, QInput, QStream
from codegen.fixedpoint import rdiv_round, rshift_round, sat32
from codegen.golden import UINT32_MAX, GoldenBase
from codegen.qformats import ACT_STEP_BITS, C_FRAC, EST_FRAC, GATE_FRAC, TANH_FRAC, X_MAX
from codegen.quantize import FLAG_SATURATED

EST_ONE = 1 << EST_FRAC


def _half_up_shift(x: np.ndarray | int, shift: int) -> np.ndarray:
    """floor(x / 2**shift + 1/2) on int64 (the C ``tdck_round_shift32/64``)."""
    return (np.asarray(x, dtype=np.int64) + (1 << (shift - 1))) >> shift


class GoldenStream(GoldenBase):
    """DLSTM methods and persistence: window means, decimated network, zero-order hold."""

    model: QStream
    fine_estimates: list[float] | None = None  # set to [] to record (accel LSB, before rounding)

    def reset(self) -> None:
        m = self.model
        L, H = len(m.layers), m.hidden_size
        self.history = np.zeros(0, dtype=np.int64)  # the last <= W clamped samples (not C state)
        self.window_current = 0  # the C's running sum and ring of completed chunk sums
        self.window_ring = np.zeros(m.chunks, dtype=np.int64)
        self.ring_pos = 0
        self.phase = 0
        self.steps = 0
        self.estimate_q16 = 0  # the held estimate, Q16 accel LSB (C: estimate + estimate_frac / 2**16)
        self.shaper = 0
        self.prev_mean = 0
        self.vec = np.zeros(m.vector_slots, dtype=np.int64)  # x pair, then h of each layer (padded)
        self.c = np.zeros((L, H), dtype=np.int64)

    def state(self) -> dict[str, np.ndarray | int]:
        m = self.model
        out: dict[str, np.ndarray | int] = {
            **super().state(),
            "window_current": self.window_current,
            "phase": self.phase,
            "steps": self.steps,
            "estimate": self.estimate_q16 >> EST_FRAC,  # floor (Python's >> on ints)
            "estimate_frac": self.estimate_q16 & (EST_ONE - 1),
            "shaper": self.shaper,
        }
        if m.chunks:
            out["window_ring"] = self.window_ring.copy()
            out["ring_pos"] = self.ring_pos
        if m.kind == "temperature":
            out["prev_mean"] = self.prev_mean
        if m.layers:
            out["vec"], out["c"] = self.vec.copy(), self.c.copy()
        return out

    def _chunk_sums(self, signal: np.ndarray) -> None:
        """The C's running sum: restarts at phase chunk_start, the completed sums go to the ring."""
        m = self.model
        D = m.frontend.decimation
        starts = np.flatnonzero((self.phase + np.arange(signal.size)) % D == m.chunk_start)
        if not starts.size:
            self.window_current += int(signal.sum())
            return
        pieces = np.add.reduceat(signal, starts)
        completed = [self.window_current + int(signal[: starts[0]].sum()), *(int(v) for v in pieces[:-1])]
        if m.chunks:  # the C writes every completed sum in turn; only the last `chunks` remain
            self.ring_pos = (self.ring_pos + max(0, len(completed) - m.chunks)) % m.chunks
            for value in completed[-m.chunks :]:
                self.window_ring[self.ring_pos] = value
                self.ring_pos = (self.ring_pos + 1) % m.chunks
        self.window_current = int(pieces[-1])

    def _run(self, accel: np.ndarray, temp: np.ndarray) -> np.ndarray:
        m = self.model
        n, W, D = accel.size, m.window, m.frontend.decimation
        if m.kind == "temperature":
            signal = self._clamp(temp, m.limits.temp_lo_mdegc, m.limits.temp_hi_mdegc)
        else:
            signal = self._clamp(accel, -m.limits.signal_lsb, m.limits.signal_lsb)
        extended = np.concatenate((self.history, signal))
        sums = np.concatenate(([0], np.cumsum(extended)))  # exact: |sum| < 2**52
        step_at = np.arange((D - self.phase) % D, n, D)  # chunk indices where phase == 0
        position = self.history.size + step_at
        count = np.minimum(self.steps + np.arange(step_at.size), m.full_steps) * D + 1
        count = np.minimum(count, W)  # min(n + 1, W): n = steps * D at a step
        window_sums = sums[position + 1] - sums[position + 1 - np.minimum(count, position + 1)]
        self._chunk_sums(signal)
        held = self._held(window_sums, count, step_at, n)
        # Output rounding with error feedback: sample i adds the fraction to the shaper and carries
        # one LSB when it reaches 2**16; the carries are the steps of floor(cumulative sum / 2**16).
        whole, fraction = held >> EST_FRAC, held & (EST_ONE - 1)  # floor and remainder (numpy: exact)
        cumulative = self.shaper + np.cumsum(fraction)  # < 2**16 (n + 1): exact
        carries = np.diff(cumulative >> EST_FRAC, prepend=0)
        if n:
            self.shaper = int(cumulative[-1] & (EST_ONE - 1))
        self.history = extended[-W:] if W else extended[:0]
        self.phase = (self.phase + n) % D
        self.steps = min(self.steps + step_at.size, UINT32_MAX)
        return self._output(accel, whole + carries)

    def _held(self, window_sums: np.ndarray, count: np.ndarray, step_at: np.ndarray, n: int) -> np.ndarray:
        """The held estimate (Q16 accel LSB) of each sample of the chunk: from each network step on."""
        estimates = self._steps(window_sums, count)
        held = np.full(n, self.estimate_q16, dtype=np.int64)
        if step_at.size:
            index = np.cumsum(np.isin(np.arange(n), step_at)) - 1
            held = np.where(index >= 0, estimates[np.maximum(index, 0)], self.estimate_q16)
            self.estimate_q16 = int(estimates[-1])
        return held

    def _steps(self, window_sums: np.ndarray, count: np.ndarray) -> np.ndarray:
        """The held estimate (Q16 accel LSB) produced at each network step of the chunk."""
        m = self.model
        if not m.layers:  # persistence: the mean itself
            if self.fine_estimates is not None:
                self.fine_estimates.extend((window_sums / count).tolist())
            return rdiv_round(window_sums * (1 << m.mean_frac), count) * (1 << (EST_FRAC - m.mean_frac))
        return np.array([self._network(row) for row in self._inputs(window_sums, count)], dtype=np.int64)

    def _means(self, window_sums: np.ndarray, count: np.ndarray) -> np.ndarray:
        """The window means, Q(mean_frac) of the input unit, at each step of the chunk."""
        return rdiv_round(window_sums * (1 << self.model.mean_frac), count)

    def _normalise(self, values: np.ndarray, q: QInput) -> np.ndarray:
        """Input q's int16 values from its feature (mean LSB): clamped to +-X_MAX, flagged."""
        x = rshift_round(
            np.clip(rshift_round(values - q.mu_q, q.pre_shift), -q.d_max, q.d_max) * q.inv_q, q.shift
        )
        clamped = np.clip(x, -X_MAX, X_MAX)
        if np.any(clamped != x):
            self.flags |= FLAG_SATURATED
        return clamped

    def _inputs(self, window_sums: np.ndarray, count: np.ndarray) -> np.ndarray:
        """The network's int16 inputs at each step of the chunk (one row per step)."""
        m = self.model
        means = self._means(window_sums, count)
        if m.kind == "temperature":
            previous = np.concatenate(([self.prev_mean], means[:-1]))
            delta = means - previous
            if self.steps == 0 and delta.size:
                delta[0] = 0  # r = 0 at the first step after a reset
            features = [means, delta]
            if means.size:
                self.prev_mean = int(means[-1])
        else:
            features = [means]
        return np.stack([self._normalise(v, q) for v, q in zip(features, m.inputs, strict=True)], axis=1)

    def _gates(self, index: int, acc: np.ndarray) -> tuple[np.ndarray, ...]:
        """Activations i, f, o (sigmoid, Q16) and g (tanh, Q15) of layer ``index``'s units from their
        gate accumulators ``acc`` (rows i, f, g, o; one column per unit)."""
        s = self.model.layers[index].shift
        return sigmoid_q16(acc[0], s), sigmoid_q16(acc[1], s), tanh_q15(acc[2], s), sigmoid_q16(acc[3], s)

    def _cell(self, gates: tuple[np.ndarray, ...], c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """New cell states and h from the activations (i, f, g, o) and the cell states ``c``."""
        i, f, g, o = gates
        # c' = f c + i g: Q16 x Q24 and Q16 x Q15 lifted to Q40, rounded half up to Q24
        wide = f * c + (i * g) * (1 << (C_FRAC + GATE_FRAC - GATE_FRAC - TANH_FRAC))
        rounded = _half_up_shift(wide, GATE_FRAC)
        c_new = sat32(rounded)
        if np.any(c_new != rounded):
            self.flags |= FLAG_SATURATED
        return c_new, _half_up_shift(o * tanh_q15(c_new, C_FRAC - ACT_STEP_BITS), GATE_FRAC)

    def _cells(self, index: int, acc: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """New cell states and h of layer ``index``'s units from their gate accumulators."""
        return self._cell(self._gates(index, acc), c)

    def _network(self, x: np.ndarray) -> int:
        m = self.model
        H, slots = m.hidden_size, m.hidden_slots
        self.vec[: x.size] = x
        for index, layer in enumerate(m.layers):
            v = self.vec[layer.offset : layer.offset + 2 * layer.pairs]
            acc = layer.b + layer.w_padded @ v  # |partial sums| < 2**31 (proved): the C's int32 sums
            self.c[index], h_new = self._cells(index, acc.reshape(4, H), self.c[index])
            start = X_SLOTS + index * slots
            self.vec[start : start + H] = h_new
        return self._head()

    def _head(self) -> int:
        """The head on the last layer's h: the estimate in Q16 accel LSB (saturated, flagged)."""
        m = self.model
        H, slots = m.hidden_size, m.hidden_slots
        head = m.head
        assert head is not None
        last = X_SLOTS + (len(m.layers) - 1) * slots
        acc_head = head.bias_q + int(head.w.q[0] @ self.vec[last : last + H])
        if self.fine_estimates is not None:
            self.fine_estimates.append(acc_head / 2.0**head.shift)
        estimate = int(rshift_round(acc_head, head.shift - EST_FRAC))
        if abs(estimate) > EST_LIMIT:
            self.flags |= FLAG_SATURATED
            estimate = EST_LIMIT if estimate > 0 else -EST_LIMIT
        return estimate
