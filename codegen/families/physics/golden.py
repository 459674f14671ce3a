"""The physics family's golden model: the C's integer arithmetic sample by sample."""

from __future__ import annotations

import numpy as np

from codegen.families.physics.quantise import QPhysics
from codegen.fixedpoint import INT32_MAX
from codegen.golden import GoldenBase
from codegen.quantize import FLAG_INPUT_CLAMPED
from trainer.physics.catalogue.streamed import STREAMED, play_words
from trainer.physics.catalogue.streaming import BRANCH, CHAIN, HI_BITS, IntSample


class GoldenPhysics(GoldenBase):
    """The grey-box model sample by sample on Python integers, with the C struct's fields.

    Each streamed effect's step is its own (``FixedPoint.golden``, trainer/physics/catalogue);
    Python integers never wrap, so an int64 overflow the generator failed to rule out would show
    here as a value beyond int64 (checked at every update) instead of agreeing with the C."""

    model: QPhysics

    def reset(self) -> None:
        self.started = 0
        self.temp_prev = 0
        self.values = dict.fromkeys(self.present(), 0)

    def init(self) -> None:
        super().init()
        self.tag = self.model.tag

    def present(self) -> tuple[str, ...]:
        """The state words of the model's terms, in step order (the C state's fields)."""
        return tuple(w.name for t in self.model.terms for w in t.fixed.state)

    def state(self) -> dict[str, np.ndarray | int]:
        out: dict[str, np.ndarray | int] = {name: self.values[name] for name in self.present()}
        return {
            **out,
            "temp_prev": self.temp_prev,
            "started": self.started,
            "model_tag": self.tag,
            **super().state(),
        }

    def restore(self, saved: dict[str, int]) -> bool:
        """The C ``NAME_restore``: continue from a saved state of this model whose words lie within
        the bounds the step's proofs assume (a damaged copy would overflow it), else start afresh."""
        m = self.model
        inside = m.clip_lo_mdegc <= int(saved["temp_prev"]) <= m.clip_hi_mdegc and all(
            abs(int(saved[name])) <= bound for name, bound in m.word_bounds.items()
        )
        if saved["model_tag"] != m.tag or not inside:
            self.init()
            return False
        self.values.update({name: int(saved[name]) for name in self.present()})
        self.temp_prev, self.started = int(saved["temp_prev"]), int(saved["started"])
        self.flags, self.samples, self.tag = (
            int(saved["flags"]),
            int(saved["samples"]),
            int(saved["model_tag"]),
        )
        return True

    def _run(self, accel: np.ndarray, temp: np.ndarray) -> np.ndarray:
        m = self.model
        tf = m.temp_frac
        v = self.values
        wide = {w.name: w.wide for t in m.terms for w in t.fixed.state}
        start, play = (
            m.play_start_q,
            play_words(),
        )  # the play operator's power-on value, when the model has one
        before = [t for t in m.terms if STREAMED[t.identifier].phase in (CHAIN, BRANCH)]
        after = [t for t in m.terms if t not in before]
        drift = np.empty(temp.size, dtype=np.int64)
        d0, d1, d2, d3 = m.coefficients_q
        for n, raw in enumerate(temp.tolist()):
            t = min(max(raw, m.clip_lo_mdegc), m.clip_hi_mdegc)
            if t != raw:
                self.flags |= FLAG_INPUT_CLAMPED
            x = (t - m.centre_mdegc) << tf
            if not self.started:
                self.started, self.temp_prev = 1, t
                for name in self.present():
                    v[name] = (
                        x << HI_BITS if wide[name] else (start if start is not None and name in play else x)
                    )
            prev = (self.temp_prev - m.centre_mdegc) << tf
            s = IntSample(x, prev, t - self.temp_prev, tf, x, x)
            acc = sum(term.fixed.golden(term, v, s) for term in before)
            u = s.t_b << m.u_shift
            poly = d3
            for coefficient in (d2, d1, d0):  # each partial sum within m.horner_bounds (< 2**31)
                poly = coefficient + ((poly * u + (1 << 31)) >> HI_BITS)
                assert abs(poly) <= INT32_MAX
            acc += poly << HI_BITS
            acc += sum(term.fixed.golden(term, v, s) for term in after)
            assert abs(u) <= INT32_MAX and abs(acc) <= m.bound
            assert all(abs(y) < 1 << 62 if wide[k] else abs(y) <= INT32_MAX for k, y in v.items())
            self.temp_prev = t
            drift[n] = (acc + (1 << (HI_BITS - 1 + m.frac))) >> (HI_BITS + m.frac)
        return self._output(accel, drift)  # |drift| < 2**30: only the output saturates
