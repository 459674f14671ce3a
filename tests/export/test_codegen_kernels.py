"""The C kernel library (codegen/kernels/tdc_kernels.h) on its own, independently of any model:
every kernel against a reference written here in Python integers (floor divisions and fractions,
not the C's offset tricks), on random inputs with the extremes each kernel's precondition allows
(hypothesis draws the seeds and the edge cases). Run by firmware_c/harness/kernel_app.c on the
host under AddressSanitizer + UndefinedBehaviorSanitizer, and on the Cortex-M4 under QEMU with the
SMLAD path and with the portable path. Also: the header is warning-free with gcc and clang under
the strict flags, and its Q-format block is the one codegen/qformats.py writes."""

from __future__ import annotations

import shutil
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from codegen import cortex_m as cm
from codegen import qformats
from codegen.activations import ACT_KNOT
from codegen.hostbuild import STRICT_FLAGS
from codegen.qformats import ACT_KNOTS, ACT_POS_BITS, ACT_SEGMENTS, ACT_STEP_BITS, C_FRAC
from tests.kernel_checks import (
    assert_header_warning_free,
    build_sanitized,
    harness_codes,
    run_sanitized,
    write_records,
)
from tests.repo import REPO_ROOT

ROOT = REPO_ROOT
HARNESS = ROOT / "firmware_c" / "harness" / "kernel_app.c"
KERNELS = ROOT / "codegen" / "kernels"
CODES = harness_codes(HARNESS)  # the op codes and record widths, declared in the C harness only
N_IN, N_OUT = CODES["KERNEL_IN"], CODES["KERNEL_OUT"]
K_TABLE, K_ACT, K_RS64, K_RS32, K_RR64, K_RDIV = (
    CODES[k]
    for k in ("K_TABLE", "K_ACT", "K_ROUND_SHIFT64", "K_ROUND_SHIFT32", "K_RSHIFT_ROUND64", "K_RDIV_ROUND64")
)
K_DOT4, K_CELL, K_INPUT, K_HOLD, K_SAT, K_CLAMP, K_SHAPE, K_WINDOW, K_DOT_WIDE, K_GATES = (
    CODES[k]
    for k in (
        "K_DOT4",
        "K_CELL",
        "K_INPUT",
        "K_HOLD",
        "K_SAT",
        "K_CLAMP",
        "K_SHAPE",
        "K_WINDOW",
        "K_DOT_WIDE",
        "K_GATES",
    )
)
I32 = (-(2**31), 2**31 - 1)


# ------------------------------------------------------------------------------ references


def _act(acc: int, shift: int) -> int:
    k = min(max(acc // 2**shift + ACT_SEGMENTS // 2, 0), ACT_SEGMENTS - 1)
    pos = (acc // 2 ** (shift - ACT_POS_BITS)) % 2**ACT_POS_BITS
    v0, v1 = int(ACT_KNOT[k]), int(ACT_KNOT[k + 1])
    return v0 + ((v1 - v0) * pos + 2 ** (ACT_POS_BITS - 1)) // 2**ACT_POS_BITS


def _half_up(x: int, s: int) -> int:
    return int(np.floor(Fraction(x, 2**s) + Fraction(1, 2)))


def _half_away(q: Fraction) -> int:
    n = int(np.floor(abs(q) + Fraction(1, 2)))
    return -n if q < 0 else n


def _unpack(word: int) -> tuple[int, int]:
    """word = hi 2**16 + (lo mod 2**16)"""
    lo = ((word & 0xFFFF) ^ 0x8000) - 0x8000
    return lo, (word - (word & 0xFFFF)) // 65536


def expected(record: list[int], window: dict[str, object]) -> list[int]:
    kid, a = record[0], record[1:]
    if kid == K_TABLE:
        return []
    if kid == K_ACT:
        return [_act(a[0], a[1]), _act(a[0], a[1] + 1), _act(a[0], a[1]) - 2**15, _act(a[0], a[1])]
    if kid in (K_RS64, K_RS32):
        return [_half_up(a[0], a[1])]
    if kid == K_RR64:
        return [_half_away(Fraction(a[0], 2 ** a[1]))]
    if kid == K_RDIV:
        return [_half_away(Fraction(a[0], a[1]))]
    if kid == K_DOT4:  # the block: 4 biases, then per pair 4 words (reversed for odd pairs)
        words, (v0, v1), (b0, b1), pairs = a[0:4], a[4:6], a[6:8], a[8]
        out = []
        for r, bias in enumerate((b0, b1, -b0, -b1)):
            acc = bias
            for p in range(pairs):
                lo, hi = _unpack(words[3 - r] if p % 2 else words[r])
                acc += lo * v1 + hi * v0 if p % 2 else lo * v0 + hi * v1
            out.append(acc)
        return [*out, 4 + 4 * pairs]  # a split product (a[9] > 0) must give the same, else -1
    if kid == K_GATES:  # sigmoid of i, f, o at shift + 1; g's table value (tanh + 1) at shift
        sums, shift = a[0:4], a[4]
        return [
            _act(sums[0], shift + 1),
            _act(sums[1], shift + 1),
            _act(sums[2], shift),
            _act(sums[3], shift + 1),
            0,
        ]
    if kid == K_CELL:
        gi, gf, gg, go, c = a[0:5]
        rounded = _half_up(gf * c + gi * gg * 2 ** (C_FRAC - 15), 16)
        cell = min(max(rounded, I32[0]), I32[1])
        th = _act(cell, C_FRAC - ACT_STEP_BITS) - 2**15
        return [_half_up(go * th, 16), cell, 4 if cell != rounded else 0]
    if kid == K_INPUT:
        centred, pre, d_max, inv, shift = a[0:5]
        d = min(max(_half_away(Fraction(centred, 2**pre)), -d_max), d_max)
        x = _half_away(Fraction(d * inv, 2**shift))
        return [min(max(x, -32767), 32767), 4 if abs(x) > 32767 else 0]
    if kid == K_HOLD:
        return [a[0] // 65536, a[0] % 65536]
    if kid == K_SAT:
        y = min(max(a[0], I32[0]), I32[1])
        return [y, 4 if y != a[0] else 0]
    if kid == K_CLAMP:
        y = min(max(a[0], a[1]), a[2])
        return [y, 2 if y != a[0] else 0]
    if kid == K_SHAPE:
        total = a[0] + a[1]
        return [total >> 16, total & 0xFFFF]
    if kid == K_DOT_WIDE:  # weights w0..w3 repeated, h0, h1 alternating; both paths agree (0)
        n = a[7]
        return [a[6] + sum(a[j % 4] * a[4 + j % 2] for j in range(n)), 0]
    assert kid == K_WINDOW  # the window sum by its definition: the samples since the last chunk start
    chunks, start, phase, v, reset = a[0:5]
    if reset:
        window.update(samples=[], completed=[])
    samples: list[int] = window["samples"]  # type: ignore[assignment]
    completed: list[int] = window["completed"]  # type: ignore[assignment]
    if phase == start:
        completed.append(sum(samples))
        samples.clear()
    samples.append(v)
    recent = completed[-chunks:] if chunks else []
    return [sum(samples), sum(samples) + sum(recent), len(completed) % chunks if chunks else 0]


# ------------------------------------------------------------------------------ inputs


def table_records() -> list[list[int]]:
    return [[K_TABLE, k, int(ACT_KNOT[k])] for k in range(ACT_KNOTS)]


def random_records(seed: int, n: int = 400) -> list[list[int]]:
    """n random records per kernel, each within its documented precondition, plus the edges."""
    rng = np.random.default_rng(seed)
    out: list[list[int]] = []

    def ints(lo: int, hi: int) -> int:
        return int(rng.integers(lo, hi, endpoint=True))

    edge32 = [I32[0], I32[0] + 1, -1, 0, 1, I32[1]]
    for k in range(n):
        shift = ints(ACT_POS_BITS, 29)
        acc = edge32[k % 6] if k < 12 else ints(*I32) >> ints(0, 30)
        out.append([K_ACT, acc, shift])
        s = ints(1, 62)
        out.append([K_RS64, ints(-(2**62) + 1, 2**62 - 1) >> ints(0, 60), s])
        s32 = ints(1, 31)
        out.append([K_RS32, ints(I32[0], I32[1] - 2 ** (s32 - 1)) >> ints(0, 30), s32])
        out.append([K_RR64, ints(-(2**62), 2**62) >> ints(0, 60), ints(0, 62)])
        den = [1, 2, 0xFFFF][k] if k < 3 else ints(1, 0xFFFF)  # a window's count: below 2**16
        out.append([K_RDIV, ints(-(2**62), 2**62) >> ints(0, 60), den])
        pairs = ints(1, 9)  # every entry of the DSP path's unrolled loop
        v_max = 32767 // pairs
        v0, v1 = ints(-v_max, v_max), ints(-v_max, v_max)
        words = [ints(-32767, 32767) * 65536 + ints(0, 65535) for _ in range(4)]
        room = 2**31 - 1 - pairs * 2 * 32768 * v_max  # |bias| + sum |w v| < 2**31
        split = ints(1, pairs - 1) if pairs > 1 else 0  # the spread schedule's two tasks
        out.append([K_DOT4, *words, v0, v1, ints(-room, room), ints(-room, room), pairs, split])
        gate_shift = ints(ACT_POS_BITS, 29)
        with_sig = int(gate_shift >= 22 and k % 2 == 0)  # the caller's table base, where it applies
        sums = [edge32[(k + r) % 6] if k < 12 else ints(*I32) >> ints(0, 30) for r in range(4)]
        out.append([K_GATES, *sums, gate_shift, with_sig])
        cell = edge32[k % 6] if k < 12 else ints(*I32) >> ints(0, 16)
        out.append([K_CELL, ints(1, 65535), ints(1, 65535), ints(-32767, 32767), ints(1, 65535), cell])
        pre, shift_in = ints(0, 20), ints(0, 30)
        inv = ints(1, 2**31 - 1)
        d_max = (2**62 - 1) // inv
        out.append([K_INPUT, ints(-(2**61), 2**61) >> ints(0, 60), pre, ints(0, d_max), inv, shift_in])
        out.append([K_HOLD, ints(-(2**47), 2**47)])
        out.append([K_SAT, ints(-(2**62), 2**62) >> ints(0, 32)])
        lo = ints(*I32)
        out.append([K_CLAMP, ints(*I32), lo, ints(lo, I32[1])])
        out.append([K_SHAPE, ints(0, 65535), ints(0, 65535)])
        wide = [ints(*I32) for _ in range(4)]  # every count of the unrolled head, 1 .. 10
        out.append(
            [K_DOT_WIDE, *wide, ints(-32767, 32767), ints(-32767, 32767), ints(-(2**62), 2**62), ints(1, 10)]
        )
    D = ints(1, 9)
    chunks, start = ints(0, 4), ints(0, D - 1)
    for k in range(3 * n):
        out.append([K_WINDOW, chunks, start, k % D, ints(-(2**28), 2**28), int(k == 0 or k == 2 * n)])
    return out


def check_outputs(records: list[list[int]], raw: bytes) -> None:
    got = np.frombuffer(raw, dtype="<i8").reshape(-1, N_OUT)
    assert got.shape[0] == len(records)
    window: dict[str, object] = {"samples": [], "completed": []}
    for index, (record, row) in enumerate(zip(records, got, strict=True)):
        want = expected(record, window)
        assert [int(v) for v in row[: len(want)]] == want, f"record {index}: {record}"


# ------------------------------------------------------------------------------ host


@pytest.fixture(scope="module")
def sanitized_app(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed (scripts/install_c_tools.sh)")
    return build_sanitized(HARNESS, tmp_path_factory.mktemp("kernels") / "kernel_app")


def run_host(binary: Path, records: list[list[int]], work: Path) -> bytes:
    return run_sanitized(binary, records, N_IN, work)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1))
def test_kernels_equal_the_references_under_sanitizers(
    sanitized_app: Path, seed: int, tmp_path: Path
) -> None:
    records = table_records() + random_records(seed)
    check_outputs(records, run_host(sanitized_app, records, tmp_path / str(seed)))


def test_activation_over_every_segment_and_position(sanitized_app: Path, tmp_path: Path) -> None:
    """tdck_act at each segment's first, last and middle positions and across its boundary, for
    the gate shifts of A = 17 .. 30 and the cell's: every table entry is reached."""
    records = table_records()
    for shift in (ACT_POS_BITS, 16, 22, C_FRAC - ACT_STEP_BITS, 25):
        for k in range(ACT_SEGMENTS):
            base = (k - ACT_SEGMENTS // 2) << shift
            for offset in (0, 1, 1 << (shift - 1), (1 << shift) - 1, -1):
                acc = base + offset
                if I32[0] <= acc <= I32[1]:
                    records.append([K_ACT, acc, shift])
    check_outputs(records, run_host(sanitized_app, records, tmp_path))


@pytest.mark.parametrize("compiler", ["gcc", "clang"])
def test_header_is_warning_free(compiler: str, tmp_path: Path) -> None:
    if shutil.which(compiler) is None:
        pytest.skip(f"{compiler} is not installed (run scripts/install_c_tools.sh)")
    assert_header_warning_free(compiler, "tdc_kernels.h", HARNESS, tmp_path)


def test_q_format_block_is_generated_from_qformats() -> None:
    text = qformats.HEADER.read_text()
    assert qformats.header_with_block(text) == text
    for f in qformats.FORMATS:
        assert f"#define TDCK_{f.name} " in text and f"/* {f.doc} */" in text
    assert subprocess.run([sys.executable, "-m", "codegen.qformats"], cwd=ROOT, check=False).returncode == 0


# ------------------------------------------------------------------------------ Cortex-M4


@pytest.mark.parametrize("flags", ["", "-DTDCK_PORTABLE"])
def test_kernels_on_the_cortex_m4(flags: str, tmp_path: Path) -> None:
    """The SMLAD path (the default on a Cortex-M4) and the portable path on the target."""
    reason = cm.ensure_toolchain()
    if reason is not None:
        pytest.skip(f"Cortex-M toolchain unavailable: {reason}")
    out = tmp_path / "build"
    subprocess.run(
        [
            "make",
            "--no-print-directory",
            "-C",
            str(cm.FIRMWARE_DIR),
            f"OUT={out}",
            f"EXTRA_CFLAGS={flags}",
            "kernel-app",
        ],
        capture_output=True,
        check=True,
    )
    records = table_records() + random_records(20240611, n=150)
    write_records(tmp_path / "in.bin", records, N_IN)
    stdout = cm.run_qemu(out / "kernel_app.elf", ["in.bin", "out.bin"], cwd=tmp_path)
    assert f"dsp {0 if flags else 1}" in stdout
    check_outputs(records, (tmp_path / "out.bin").read_bytes())


@pytest.mark.parametrize("opt", ["-O0", "-Os", "-O2 -fno-omit-frame-pointer"])
def test_dsp_path_builds_at_any_optimisation(opt: str, tmp_path: Path) -> None:
    """The DSP path's inline assembly (LDM into fixed registers, SMULL/SMLAL, SMMULR) leaves the
    Thumb frame pointer r7 alone: it builds warning-free with and without a frame pointer."""
    if shutil.which("arm-none-eabi-gcc") is None:
        pytest.skip("arm-none-eabi-gcc is not installed")
    cmd = [
        "arm-none-eabi-gcc",
        *STRICT_FLAGS,
        "-mcpu=cortex-m4",
        "-mthumb",
        "-mfloat-abi=hard",
        "-mfpu=fpv4-sp-d16",
        *opt.split(),
        f"-I{KERNELS}",
        "-c",
        str(HARNESS),
        "-o",
        str(tmp_path / "k.o"),
    ]
    result = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert result.returncode == 0 and not result.stderr, result.stderr
