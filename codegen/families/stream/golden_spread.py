"""The golden model of the spread schedule (``codegen export --schedule spread``).

The C computes the window mean at phase 0 and splits the network step into ``T`` tasks: one per
input (its normalisation), then per unit of each layer the tasks of ``UNIT_TASKS`` (the first
``first_pairs`` pairs of its dot product with the biases, the other pairs added to the saved sums,
the four activations in place of the sums, the cell), the head last. The sample of phase p runs
``floor((p + 1) T / D) - floor(p T / D)`` of them, so the estimate of the step started at phase 0
takes effect on the sample of phase D - 1. This replays the same tasks on the same state (the final
state of a stream that ends mid-period is the C's, field for field): each task uses
:class:`GoldenStream`'s arithmetic, so the numbers are the "step" schedule's, only later.
"""

from __future__ import annotations

import numpy as np

from codegen.families.stream.golden import GoldenStream
from codegen.families.stream.quantise import UNIT_TASKS, X_SLOTS, QStream
from codegen.golden import UINT32_MAX
from codegen.qformats import TANH_FRAC

WORD = 1 << 32  # state->acc holds uint32 words
EXCESS = 1 << 31  # the dot products' sums are in excess-2^31 form


class GoldenStreamSpread(GoldenStream):
    model: QStream

    def reset(self) -> None:
        super().reset()
        self.mean = 0  # the step's window mean, Q(mean_frac) (C: state->mean)
        self.task = 0  # tasks of the current step done
        self.acc = np.zeros(4, dtype=np.int64)  # the C's words: sums + 2^31 mod 2^32, or activations
        self.h_new = np.zeros(self.model.hidden_slots, dtype=np.int64)
        self.step_number = 0  # C: state->steps as the current step's tasks see it

    def state(self) -> dict[str, np.ndarray | int]:
        m = self.model
        return {
            **super().state(),
            "mean": self.mean,
            "task": self.task,
            "credit": self.phase * m.tasks % m.frontend.decimation,
            "acc": self.acc.copy(),
            "h_new": self.h_new.copy(),
        }

    def _input_task(self, k: int) -> None:
        """Input k's normalisation; the temperature model's rate input is the mean's change."""
        value = self.mean
        if k == 1:
            value = 0 if self.step_number == 1 else self.mean - self.prev_mean
            self.prev_mean = self.mean
        self.vec[k] = int(self._normalise(np.array([value], dtype=np.int64), self.model.inputs[k])[0])

    def _unit_task(self, index: int, j: int, kind: str) -> None:
        """Task ``kind`` of unit j of layer ``index`` on state->acc."""
        m = self.model
        H = m.hidden_size
        layer = m.layers[index]
        rows = np.arange(4) * H + j
        split = 2 * layer.first_pairs
        v = self.vec[layer.offset : layer.offset + 2 * layer.pairs]
        if kind == "dot":
            self.acc = (layer.b[rows] + layer.w_padded[rows, :split] @ v[:split] + EXCESS) % WORD
        elif kind == "dot_rest":
            rest = np.asarray(layer.w_padded[rows, split:] @ v[split:], dtype=np.int64)  # int64 @ int64
            self.acc = (self.acc + rest) % WORD
        elif kind == "gates":  # the whole sum is in int32 (proved), so it is the word - 2^31
            i, f, g, o = self._gates(index, (self.acc - EXCESS).reshape(4, 1))
            self.acc = np.array([i[0], f[0], g[0] + (1 << TANH_FRAC), o[0]], dtype=np.int64)
        else:
            a = self.acc.reshape(4, 1)
            c_new, h_new = self._cell((a[0], a[1], a[2] - (1 << TANH_FRAC), a[3]), self.c[index][j : j + 1])
            self.c[index][j], self.h_new[j] = int(c_new[0]), int(h_new[0])
            if j == H - 1:
                start = X_SLOTS + index * m.hidden_slots
                self.vec[start : start + H] = self.h_new[:H]

    def _task(self, t: int) -> int | None:
        """Run task t; the estimate (Q16 accel LSB) if it was the head."""
        m = self.model
        n_in = len(m.inputs)
        if t == m.tasks - 1:
            return self._head()
        if t < n_in:
            self._input_task(t)
            return None
        index, r = divmod(t - n_in, len(UNIT_TASKS) * m.hidden_size)
        j, kind = divmod(r, len(UNIT_TASKS))
        self._unit_task(index, j, UNIT_TASKS[kind])
        return None

    def _tasks(self, until_phase: int) -> int | None:
        """The tasks due by the end of phase ``until_phase - 1``; the estimate if the head ran."""
        m = self.model
        due = m.tasks_before(until_phase)
        estimate = None
        for t in range(self.task, due):
            out = self._task(t)
            estimate = out if out is not None else estimate
        self.task = max(self.task, due)
        return estimate

    def _held(self, window_sums: np.ndarray, count: np.ndarray, step_at: np.ndarray, n: int) -> np.ndarray:
        D = self.model.frontend.decimation
        changes: list[tuple[int, int]] = []  # (sample of the chunk, estimate from it on)
        if self.phase != 0:  # the step started before this chunk goes on until the next phase 0
            span = int(step_at[0]) if step_at.size else n
            self.step_number = self.steps
            estimate = self._tasks(self.phase + span)
            if estimate is not None:
                changes.append((D - 1 - self.phase, estimate))
        for k, (mean, start) in enumerate(zip(self._means(window_sums, count), step_at, strict=True)):
            self.mean = int(mean)
            self.step_number = min(self.steps + k + 1, UINT32_MAX)
            self.task = 0
            estimate = self._tasks(min(D, n - int(start)))
            if estimate is not None:
                changes.append((int(start) + D - 1, estimate))
        held = np.full(n, self.estimate_q16, dtype=np.int64)
        for position, estimate in changes:
            held[position:] = estimate
            self.estimate_q16 = estimate
        return held
