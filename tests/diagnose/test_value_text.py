"""A fitted value reads the same on the terminal, in the report and in the JSON (to what each keeps):
a creep tau of 16982 s was 1.698e+04 in the report and 16980 to a reader, 16982 in the JSON."""

from __future__ import annotations

import pytest

from trainer.diagnose.document import params
from trainer.diagnose.report import value_text


@pytest.mark.parametrize("value", [16982.3, 1200.0, -2541.6, 901.24, 0.30127, -0.0578])
def test_a_value_printed_agrees_with_the_json_to_the_digits_printed(value: float) -> None:
    kept = params({"v": value})["v"]  # the JSON's figure (6 significant digits)
    text = value_text(value)
    assert "e" not in text, text  # never scientific notation for a parameter a user compares by eye
    digits = max(len(text.lstrip("-").replace(".", "").lstrip("0")), 1)
    assert float(text) == pytest.approx(kept, rel=10.0 ** (1 - digits)), (text, kept)
    if abs(value) >= 1000:
        assert float(text) == round(kept)  # whole units, as the JSON holds them
