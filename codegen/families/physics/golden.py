"""The physics family's golden model: the C's integer arithmetic sample by sample."""

from __future__ import annotations

from array import array

import numpy as np

from codegen.families.physics.quantise import QPhysics, QTerm
from codegen.fixedpoint import INT32_MAX
from codegen.golden import GoldenBase
from trainer.physics.catalogue.streamed import STREAMED
from trainer.physics.catalogue.streaming import BRANCH, CHAIN, HI_BITS, GoldenStep, IntSample

BLOCK = 1 << 16  # samples the model steps between its bounds checks (and holds as arrays)
WIDE_MAX = (1 << 62) - 1  # |int64 filter state| < 2**62: tdcp_lowpass's preconditions


class GoldenPhysics(GoldenBase):
    """The grey-box model sample by sample on Python integers, with the C struct's fields.

    Each streamed effect's step is its own (``FixedPoint.golden``, trainer/physics/catalogue);
    Python integers never wrap, so an overflow the generator failed to rule out would show here as
    a value beyond its int32 / int64 bound instead of agreeing with the C: every sample's values
    are recorded and checked, block by block (:meth:`_block`), and what is not recursive (the clamp,
    x, the cubic, the rounding) runs on numpy int64 arrays where each value is proved within int64."""

    model: QPhysics

    def reset(self) -> None:
        self.started = 0
        self.temp_prev = 0
        self.values = dict.fromkeys(self.present(), 0)

    def init(self) -> None:
        super().init()
        self.tag = self.model.tag

    def present(self) -> tuple[str, ...]:
        """The state words of the model's terms (each instance its own), in step order (the C state's
        fields)."""
        return tuple(w.name for w in self.model.words)

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
        before, after = self._steps()
        m = self.model
        t = self._clamp(temp, m.clip_lo_mdegc, m.clip_hi_mdegc)  # outside: hold the range's edge
        drift = [self._block(t[lo : lo + BLOCK], before, after) for lo in range(0, t.size, BLOCK)]
        # |drift| < 2**30: only the output saturates
        return self._output(accel, np.concatenate(drift) if drift else np.empty(0, dtype=np.int64))

    def _block(self, t: np.ndarray, before: list[GoldenStep], after: list[GoldenStep]) -> np.ndarray:
        """The C step on each sample of ``t`` (the clamped temperatures, at most :data:`BLOCK`), in three
        parts: what no state feeds (x, the previous x, the step) on the whole block in numpy int64
        (within int64 as each line says); the terms' recursive steps sample by sample on Python
        integers, recording what the C holds in int32 / int64 (T_b, the terms' sum, every state
        word after the step); then the cubic of the recorded T_b and the accumulator on the whole
        block. The bounds the C's proofs assume are checked on every sample's values, as the C's
        types hold them (an AssertionError says what overflows)."""
        m = self.model
        tf, centre = m.temp_frac, m.centre_mdegc
        x = (t - centre) << tf  # |t - centre| < 2**32, tf <= 24: within int64
        assert _within(x, INT32_MAX), "x beyond int32"
        if not self.started:
            self._start(int(t[0]), int(x[0]))
        t_prev = np.concatenate(([self.temp_prev], t[:-1]))
        prev, step_mdegc = (t_prev - centre) << tf, t - t_prev
        self.temp_prev = int(t[-1])

        # the terms' steps (FixedPoint.golden) in the C's order; array("q") refuses a value beyond int64
        v, wide = self.values, self._wide
        s = IntSample(0, 0, 0, tf, 0, 0)
        t_b, terms, words = array("q"), array("q"), array("q")
        try:
            for s.x, s.prev, s.step_mdegc in zip(x.tolist(), prev.tolist(), step_mdegc.tolist(), strict=True):
                s.t_pm = s.t_b = s.x
                acc = 0
                for golden in before:  # CHAIN, BRANCH: T_pm, and T_b the polynomial reads
                    acc += golden(v, s)
                t_b.append(s.t_b)
                for golden in after:  # ADDITIVE
                    acc += golden(v, s)
                terms.append(acc)
                words.extend(v.values())
        except OverflowError:
            raise AssertionError("a value beyond int64 (T_b, the terms' sum or a state word)") from None
        assert tuple(v) == tuple(wide), "a term's step wrote a word not in the state"
        history = np.frombuffer(words, dtype=np.int64).reshape(len(terms), len(wide))
        for k, (name, is_wide) in enumerate(wide.items()):
            limit = WIDE_MAX if is_wide else INT32_MAX
            assert _within(history[:, k], limit), (
                f"state word {name} beyond its int{64 if is_wide else 32} bound"
            )

        # the cubic of T_b by Horner in int32 (rounded high words), then the int64 accumulator
        t_b_arr = np.frombuffer(t_b, dtype=np.int64)
        assert _within(t_b_arr, INT32_MAX >> m.u_shift), "u = T_b << u_shift beyond int32"
        u = t_b_arr << m.u_shift
        d0, d1, d2, d3 = m.coefficients_q
        assert max(map(abs, m.coefficients_q)) <= INT32_MAX
        poly = np.full(u.size, d3, dtype=np.int64)
        for coefficient in (d2, d1, d0):  # |poly|, |u| <= INT32_MAX: |poly u| < 2**62, no wrap
            poly = coefficient + ((poly * u + (1 << 31)) >> HI_BITS)
            assert _within(poly, INT32_MAX), "a Horner step beyond int32"
        acc_arr = _add_exact(np.frombuffer(terms, dtype=np.int64), poly << HI_BITS)  # |poly 2**32| < 2**63
        assert _within(acc_arr, m.bound), "the drift accumulator beyond its bound"
        return (acc_arr + (1 << (HI_BITS - 1 + m.frac))) >> (HI_BITS + m.frac)  # |acc| < 2**62: no wrap

    def _start(self, t: int, x: int) -> None:
        """The first sample after init/reset: every filter starts at x, the play operator at the
        model's play start (at x when it has none), every instance's."""
        start, play = self.model.play_start_q, self.model.play_words
        self.started, self.temp_prev = 1, t
        for name, wide in self._wide.items():
            self.values[name] = x << HI_BITS if wide else (start if start is not None and name in play else x)

    @property
    def _wide(self) -> dict[str, bool]:
        """Each state word (in step order) and whether it is an int64 filter state (else int32)."""
        return {w.name: w.wide for w in self.model.words}

    def _steps(self) -> tuple[list[GoldenStep], list[GoldenStep]]:
        """The terms' golden steps (their constants bound) before the polynomial (CHAIN, BRANCH)
        and after it, each in step order."""
        early = (CHAIN, BRANCH)
        terms = self.model.terms
        return (
            [_own_words(t) for t in terms if STREAMED[t.identifier].phase in early],
            [_own_words(t) for t in terms if STREAMED[t.identifier].phase not in early],
        )


def _own_words(term: QTerm) -> GoldenStep:
    """The term's golden step on its own state words: an effect's later instance keeps them suffixed
    (``play_2``), its step (the catalogue's) reads and writes the unsuffixed names."""
    step, suffix = term.fixed.golden(term), term.suffix
    if not suffix:
        return step
    words = [(w.name, w.name + suffix) for w in term.fixed.state]

    def own(v: dict[str, int], s: IntSample) -> int:
        mine = {word: v[name] for word, name in words}
        out = step(mine, s)
        assert len(mine) == len(words), "a term's step wrote a word not in its state"
        for word, name in words:
            v[name] = mine[word]
        return out

    return own


def _within(values: np.ndarray, bound: int) -> bool:
    """Every |value| <= bound (min and max: np.abs would wrap -2**63)."""
    return values.size == 0 or (int(values.min()) >= -bound and int(values.max()) <= bound)


def _add_exact(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a + b in int64, refused where it wraps (the sum's sign then differs from both addends')."""
    total = a + b
    assert not np.any(((a ^ total) & (b ^ total)) < 0), "an int64 sum wraps"
    return total
