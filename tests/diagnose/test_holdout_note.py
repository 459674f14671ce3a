"""The finder's held-out check says when the found terms, fitted on the leading part of the run, leave
more on the tail than the starting model (a single heating ramp: a rate term named on its first 75 %
took the tail from 3.16 to 8.33 mg), and how much of the tail lies outside the leading part's
temperature range; a check where they help says nothing."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any, cast

import numpy as np
import pytest

from trainer.diagnose.blocks import BlockData
from trainer.diagnose.holdout import WORSE_MARGIN, HoldoutScore, worse_note


def _blocks(temp_c: np.ndarray) -> BlockData:
    fake: Any = SimpleNamespace(temperature=lambda dequantized: temp_c)
    return cast(BlockData, fake)


@pytest.mark.parametrize(
    ("after_mg", "said"), [(8.33, True), (3.16 * WORSE_MARGIN * 0.99, False), (0.7, False)]
)
def test_a_tail_the_found_terms_make_worse_is_said_with_its_share_outside_the_range(
    after_mg: float, said: bool
) -> None:
    temp = np.linspace(-17.6, 74.0, 100)  # one heating ramp: the last quarter beyond the first 75 %
    before, after = HoldoutScore(0.0, 3.16, 0.5), HoldoutScore(0.0, after_mg, 0.4)
    note = worse_note(before, after, _blocks(temp), 75)
    assert bool(note) == said
    if said:
        assert "leave more on the tail than the starting model" in note
        lo, hi = temp[0], temp[74]
        assert f"100 % of the tail lies outside the leading part's {lo:.1f} .. {hi:.1f} degC" in note


def test_a_tail_inside_the_range_says_no_share() -> None:
    temp = np.concatenate([np.linspace(0.0, 60.0, 75), np.linspace(60.0, 30.0, 25)])
    note = worse_note(HoldoutScore(0.0, 1.0, 0.5), HoldoutScore(0.0, 2.0, 0.4), _blocks(temp), 75)
    assert "do not carry over" in note and "outside" not in note
