"""The fixed-point formats of the generated code: declared once, here.

Every Q format (fractional bits, storage, range) of the streaming network and of the kernel
library is a constant of this module. The golden model, the quantiser and the renderer import
them; the C kernel library ``codegen/kernels/tdc_kernels.h`` carries the same values as
``#define``s in a block written by :func:`c_block` (``python -m codegen.qformats --write``
regenerates it, and a test fails when the checked-in header and this module disagree). So a
format is changed in one place, and its C comment and value follow.

Why 16 bits: the sensor's white noise is 0.354 mg per sample; int16 weights, Q15 states and table
activations leave errors near 1e-3 mg of the float model (docs/codegen.md, "Error budget"), and
they let a Cortex-M4 do two multiply-accumulates per instruction (SMLAD) into an int32 accumulator
whose bound is proved at generation time.
"""

from __future__ import annotations

import argparse
import re
import sys
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class QFormat:
    """One named constant of the fixed-point design, with the comment both languages show."""

    name: str  # C: TDCK_<name>
    value: int
    doc: str


FORMATS: tuple[QFormat, ...] = (
    QFormat("X_FRAC", 12, "network inputs x: int16 Q3.12 (normalised, clamped to +-8, flagged) ..."),
    QFormat("X_MIN_FRAC", 10, "... or wider, down to Q5.10 (+-32), when layer 0 loses no accumulator bit"),
    QFormat("H_FRAC", 15, "hidden states h: int16 Q15, |h| <= 32767"),
    QFormat("GATE_FRAC", 16, "sigmoid gates i, f, o: Q16 in 1 .. 65535 (a forget gate stays below 1)"),
    QFormat("TANH_FRAC", 15, "tanh of the g gate and of the cell: Q15 in -32767 .. 32767"),
    QFormat("C_FRAC", 24, "cell states c: int32 Q7.24 (saturated at the int32 limits, flagged)"),
    QFormat("EST_FRAC", 16, "held estimate: Q16 of the output LSB (1/16 ug)"),
    QFormat(
        "MIN_ACC_FRAC", 17, "gate accumulators: int32 Q(A) with A >= 17 (the table's step and position bits)"
    ),
    QFormat("MAX_ACC_FRAC", 30, "largest A the quantiser tries"),
    QFormat("ACT_RANGE", 8, "the activation table covers tanh inputs -8 .. 8 (sigmoid: -16 .. 16)"),
    QFormat("ACT_STEP_BITS", 5, "table step 2^-5 of the tanh input: 512 segments"),
    QFormat("ACT_SEGMENTS", 512, "segments of the activation table (2 ACT_RANGE 2^ACT_STEP_BITS)"),
    QFormat("ACT_POS_BITS", 12, "position inside a segment: 12 bits"),
    QFormat(
        "ACT_KNOTS",
        513,
        "knots v (uint16) at the segment ends: out = v[k] + ((v[k+1] - v[k]) pos + 2^11) >> 12",
    ),
    QFormat("ACT_VALUE_FRAC", 15, "knot values: tanh(x) + 1 in Q15 (= sigmoid(2x) in Q16), 1 .. 65535"),
)

_BY_NAME = {f.name: f.value for f in FORMATS}
X_FRAC = _BY_NAME["X_FRAC"]
X_MIN_FRAC = _BY_NAME["X_MIN_FRAC"]
H_FRAC = _BY_NAME["H_FRAC"]
GATE_FRAC = _BY_NAME["GATE_FRAC"]
TANH_FRAC = _BY_NAME["TANH_FRAC"]
C_FRAC = _BY_NAME["C_FRAC"]
EST_FRAC = _BY_NAME["EST_FRAC"]
MIN_ACC_FRAC = _BY_NAME["MIN_ACC_FRAC"]
MAX_ACC_FRAC = _BY_NAME["MAX_ACC_FRAC"]
ACT_RANGE = _BY_NAME["ACT_RANGE"]
ACT_STEP_BITS = _BY_NAME["ACT_STEP_BITS"]
ACT_SEGMENTS = _BY_NAME["ACT_SEGMENTS"]
ACT_POS_BITS = _BY_NAME["ACT_POS_BITS"]
ACT_KNOTS = _BY_NAME["ACT_KNOTS"]
ACT_VALUE_FRAC = _BY_NAME["ACT_VALUE_FRAC"]

X_MAX = (1 << 15) - 1  # |x_q|: 16 standard deviations
H_MAX = (1 << 15) - 1
ACT_ONE = 1 << ACT_VALUE_FRAC  # tanh = table value - ACT_ONE
assert ACT_SEGMENTS == 2 * ACT_RANGE << ACT_STEP_BITS and ACT_KNOTS == ACT_SEGMENTS + 1
assert MIN_ACC_FRAC == ACT_STEP_BITS + ACT_POS_BITS  # the tanh rows' position shift A - 4 - 12 >= 0

HEADER = Path(__file__).resolve().parent / "kernels" / "tdc_kernels.h"
BEGIN = "/* BEGIN Q FORMATS: written by `python -m codegen.qformats --write` from codegen/qformats.py */"
END = "/* END Q FORMATS */"


def c_block() -> str:
    """The ``#define`` block of the C header (between BEGIN and END, markers included)."""
    width = max(len(f.name) for f in FORMATS) + len("TDCK_")
    lines = [BEGIN]
    for f in FORMATS:
        lines.append(f"#define {'TDCK_' + f.name:<{width}} {f.value} /* {f.doc} */")
    lines.append(END)
    return "\n".join(lines)


def header_with_block(text: str) -> str:
    pattern = re.compile(re.escape(BEGIN) + r".*?" + re.escape(END), re.S)
    if not pattern.search(text):
        raise ValueError(f"{HEADER}: no Q-format block")
    return pattern.sub(lambda _: c_block(), text)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="write or check the Q-format block of tdc_kernels.h")
    parser.add_argument("--write", action="store_true", help="rewrite the block in place")
    args = parser.parse_args(argv)
    text = HEADER.read_text()
    wanted = header_with_block(text)
    if args.write:
        HEADER.write_text(wanted)
        return 0
    if wanted != text:
        print(
            f"{HEADER}: Q-format block out of date (run python -m codegen.qformats --write)", file=sys.stderr
        )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
