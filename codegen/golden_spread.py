"""The golden model of the spread schedule (``codegen export --schedule spread``).

The C splits a network step into ``T = 2 L H + 1`` tasks (unit j of layer l: its dot product into
``acc``, then its cell; the head last) and runs ``floor((p + 1) T / D) - floor(p T / D)`` of them on
the sample of phase p, so the estimate of the step started at phase 0 takes effect on the sample
of phase D - 1. This replays the same task split on the same state (so the final state of a stream
that ends mid-period is the C's, field for field): each task uses :class:`GoldenStream`'s unit
arithmetic, so the numbers are the ones of the "step" schedule, only later.
"""

from __future__ import annotations

import numpy as np

from codegen.golden import GoldenStream
from codegen.quantize import X_SLOTS, QStream


class GoldenStreamSpread(GoldenStream):
    model: QStream

    def reset(self) -> None:
        super().reset()
        self.task = 0  # tasks of the current step done
        self.acc = np.zeros(4, dtype=np.int64)  # the last dot product's gate sums (true values)
        self.h_new = np.zeros(self.model.hidden_slots, dtype=np.int64)

    def state(self) -> dict[str, np.ndarray | int]:
        m = self.model
        return {
            **super().state(),
            "task": self.task,
            "credit": self.phase * m.tasks % m.frontend.decimation,
            "acc": (self.acc + 2**31) & 0xFFFFFFFF,
            "h_new": self.h_new.copy(),
        }

    def _task(self, t: int) -> int | None:
        """Run task t; the estimate (Q16 accel LSB) if it was the head."""
        m = self.model
        H = m.hidden_size
        if t == m.tasks - 1:
            return self._head()
        index, r = divmod(t, 2 * H)
        j = r // 2
        layer = m.layers[index]
        if r % 2 == 0:
            rows = np.arange(4) * H + j
            v = self.vec[layer.offset : layer.offset + 2 * layer.pairs]
            self.acc = layer.b[rows] + layer.w_padded[rows] @ v
        else:
            c_new, h_new = self._cells(index, self.acc.reshape(4, 1), self.c[index][j : j + 1])
            self.c[index][j], self.h_new[j] = int(c_new[0]), int(h_new[0])
            if j == H - 1:
                start = X_SLOTS + index * m.hidden_slots
                self.vec[start : start + H] = self.h_new[:H]
        return None

    def _tasks(self, until_phase: int) -> int | None:
        """The tasks due by the end of phase ``until_phase - 1``; the estimate if the head ran."""
        m = self.model
        due = until_phase * m.tasks // m.frontend.decimation
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
            estimate = self._tasks(self.phase + span)
            if estimate is not None:
                changes.append((D - 1 - self.phase, estimate))
        for row, start in zip(self._inputs(window_sums, count), step_at, strict=True):
            self.vec[: row.size] = row
            self.task = 0
            estimate = self._tasks(min(D, n - int(start)))
            if estimate is not None:
                changes.append((int(start) + D - 1, estimate))
        held = np.full(n, self.estimate_q16, dtype=np.int64)
        for position, estimate in changes:
            held[position:] = estimate
            self.estimate_q16 = estimate
        return held
