"""The physics kernels (codegen/kernels/tdc_physics_kernels.h) on their own, independently of any
model: every kernel against a reference written here in Python integers (floors of exact fractions,
not the C's offset tricks or exact divisions), on random inputs with the extremes each kernel's
precondition allows (hypothesis draws the seeds). Run by firmware_c/harness/physics_kernel_app.c on
the host under AddressSanitizer + UndefinedBehaviorSanitizer, and on the Cortex-M4 under QEMU with
the SMMLAR path and with the portable path. Also: the header is warning-free with gcc and clang."""

from __future__ import annotations

import math
import shutil
import subprocess
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from codegen import cortex_m as cm
from tests.kernel_checks import (
    assert_header_warning_free,
    build_sanitized,
    harness_codes,
    run_sanitized,
    write_records,
)
from tests.repo import REPO_ROOT

ROOT = REPO_ROOT
HARNESS = ROOT / "firmware_c" / "harness" / "physics_kernel_app.c"
KERNELS = ROOT / "codegen" / "kernels"
CODES = harness_codes(HARNESS)  # the op codes and record widths, declared in the C harness only
N_IN, N_OUT = CODES["KERNEL_IN"], CODES["KERNEL_OUT"]
K_HI, K_HI_FLOOR, K_HI_ROUND, K_MLA, K_LOWPASS, K_PLAY, K_OUTPUT = (
    CODES[k] for k in ("K_HI", "K_HI_FLOOR", "K_HI_ROUND", "K_MLA", "K_LOWPASS", "K_PLAY", "K_OUTPUT")
)
I32 = (-(2**31), 2**31 - 1)
I64 = (-(2**63), 2**63 - 1)
SAT_BIT = 4


def _floor(q: Fraction) -> int:
    return math.floor(q)


def expected(record: list[int]) -> list[int]:
    kid, a = record[0], record[1:]
    if kid == K_HI:
        return [_floor(Fraction(a[0], 2**32))]
    if kid == K_HI_FLOOR:
        return [_floor(Fraction(a[0], 2 ** (32 + a[1])))]
    if kid == K_HI_ROUND:
        return [_floor(Fraction(a[0], 2 ** (32 + a[1])) + Fraction(1, 2))]
    if kid == K_MLA:
        return [a[0] + _floor(Fraction(a[1] * a[2], 2**32) + Fraction(1, 2))]
    if kid == K_LOWPASS:
        y, prev, step, c, b0, s = a[0:6]
        d = _floor(Fraction(prev * 2**32 - y, 2 ** (32 + s)))
        return [y + d * c + step * b0]
    if kid == K_PLAY:
        p, x, h = a[0:3]
        return [min(max(p, x - h), x + h)]
    assert kid == K_OUTPUT
    samples, accel, drift, flags = a[0:4]
    out = accel - drift
    clamped = min(max(out, I32[0]), I32[1])
    return [clamped, min(samples + 1, 2**32 - 1), flags | (SAT_BIT if clamped != out else 0)]


def random_records(seed: int, n: int = 300) -> list[list[int]]:
    """n random records per kernel, each within its documented precondition, plus the edges."""
    rng = np.random.default_rng(seed)

    def ints(lo: int, hi: int) -> int:
        if hi - lo < 2**63:
            return lo + int(rng.integers(0, hi - lo, endpoint=True))
        return lo + int.from_bytes(rng.bytes(9), "little") % (hi - lo + 1)

    def scaled(limit: int) -> int:  # |v| <= limit, magnitudes spread over every bit length
        return ints(-limit, limit) >> ints(0, max(limit.bit_length() - 1, 0))

    out: list[list[int]] = []
    edges64 = [I64[0], I64[0] + 1, -(2**62), -1, 0, 1, 2**62, I64[1]]
    for k in range(n):
        x = edges64[k] if k < len(edges64) else ints(*I64) >> ints(0, 62)
        out.append([K_HI, x])
        out.append([K_HI_FLOOR, x, ints(0, 30)])
        s = ints(0, 30)
        hi_edges = [-(2**62) + 1, -1, 0, 1, 2**62 - 1]
        out.append([K_HI_ROUND, hi_edges[k] if k < 5 else scaled(2**62 - 1), s])
        a, b = scaled(I32[1]), scaled(I32[1])
        if k < 4:  # the largest products, both signs
            a, b = (I32[0], I32[0]) if k % 2 else (I32[0], I32[1])
        room = 2**31 - 1 - (abs(a * b) >> 32) - 1  # the sum fits int32
        out.append([K_MLA, ints(-room, room), a, b])
        y, prev = scaled(2**61 - 1), scaled(2**30 - 1)
        c, b0 = ints(0, 2**30), ints(0, 2**30)
        step = scaled(min(2**31 - 1, (2**61) // max(b0, 1)))
        out.append([K_LOWPASS, y, prev, step, c, b0, ints(0, 30)])
        h = ints(0, 2**29)
        out.append([K_PLAY, scaled(2**30), scaled(2**30), h])
        accel = (
            [I32[0], I32[1], -(2**30) - 1, -(2**30), 2**30 - 1, 2**30][k % 6] if k < 12 else scaled(I32[1])
        )
        drift = [-(2**30), 2**30, 0][k % 3] if k < 12 else scaled(2**30)
        samples = [2**32 - 1, 2**32 - 2, 0][k % 3] if k < 6 else ints(0, 2**32 - 1)
        out.append([K_OUTPUT, samples, accel, drift, ints(0, 7)])
    return out


def check_outputs(records: list[list[int]], raw: bytes) -> None:
    got = np.frombuffer(raw, dtype="<i8").reshape(-1, N_OUT)
    assert got.shape[0] == len(records)
    for index, (record, row) in enumerate(zip(records, got, strict=True)):
        want = expected(record)
        assert [int(v) for v in row[: len(want)]] == want, f"record {index}: {record}"


def test_references_hold_the_preconditions() -> None:
    """The records stay inside each kernel's documented precondition (else the C may wrap)."""
    for record in random_records(1, n=200):
        kid, a = record[0], record[1:]
        if kid == K_LOWPASS:
            y, prev, step, c, b0, s = a[0:6]
            d = (prev * 2**32 - y) >> (32 + s)
            assert abs(prev * 2**32) + abs(y) < 2**63 and abs(y) + abs(d * c) + abs(step * b0) < 2**63
        if kid in (K_HI_ROUND, K_MLA):
            assert I32[0] <= expected(record)[0] <= I32[1]


# ------------------------------------------------------------------------------ host


@pytest.fixture(scope="module")
def sanitized_app(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed (scripts/install_c_tools.sh)")
    return build_sanitized(HARNESS, tmp_path_factory.mktemp("physics-kernels") / "physics_kernel_app")


def run_host(binary: Path, records: list[list[int]], work: Path) -> bytes:
    return run_sanitized(binary, records, N_IN, work)


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1))
def test_kernels_equal_the_references_under_sanitizers(
    sanitized_app: Path, seed: int, tmp_path: Path
) -> None:
    records = random_records(seed)
    check_outputs(records, run_host(sanitized_app, records, tmp_path / str(seed)))


@pytest.mark.parametrize("compiler", ["gcc", "clang"])
def test_header_is_warning_free(compiler: str, tmp_path: Path) -> None:
    if shutil.which(compiler) is None:
        pytest.skip(f"{compiler} is not installed (run scripts/install_c_tools.sh)")
    assert_header_warning_free(compiler, "tdc_physics_kernels.h", HARNESS, tmp_path)


# ------------------------------------------------------------------------------ Cortex-M4


@pytest.mark.parametrize("flags", ["", "-DTDCK_PORTABLE"])
def test_kernels_on_the_cortex_m4(flags: str, tmp_path: Path) -> None:
    """The SMMLAR path (the default on a Cortex-M4) and the portable path on the target."""
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
            "physics-kernel-app",
        ],
        capture_output=True,
        check=True,
    )
    records = random_records(20240611, n=150)
    write_records(tmp_path / "in.bin", records, N_IN)
    stdout = cm.run_qemu(out / "physics_kernel_app.elf", ["in.bin", "out.bin"], cwd=tmp_path)
    assert f"dsp {0 if flags else 1}" in stdout
    check_outputs(records, (tmp_path / "out.bin").read_bytes())
