"""Shared checks of the hand-written C kernel headers (codegen/kernels/) and the Cortex-M4 driver."""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import numpy as np

from codegen.hostbuild import FIRMWARE_WARNINGS, SANITIZER_FLAGS, STRICT_FLAGS, compile_c

ROOT = Path(__file__).resolve().parents[1]
KERNELS = ROOT / "codegen" / "kernels"


def harness_codes(harness: Path) -> dict[str, int]:
    """The kernel-test harness's op codes (its ``enum kernel``) and its record widths (``KERNEL_IN``,
    ``KERNEL_OUT``), read from the C: declared there only, so Python and C cannot disagree."""
    text = harness.read_text(encoding="utf-8")
    codes = {
        m[1]: int(m[2]) for m in re.finditer(r"^#define (KERNEL_IN|KERNEL_OUT) (\d+)$", text, re.MULTILINE)
    }
    enum = re.search(r"enum kernel \{([^}]*)\}", text)
    if enum is None or set(codes) != {"KERNEL_IN", "KERNEL_OUT"}:
        raise ValueError(f"{harness}: no 'enum kernel {{ ... }}' or no KERNEL_IN / KERNEL_OUT")
    for entry in enum[1].split(","):
        name, _, value = entry.partition("=")
        codes[name.strip()] = int(value)
    return codes


def assert_header_warning_free(compiler: str, header: str, harness: Path, work: Path) -> None:
    """``header`` alone in a unit, and its test harness, compile silently at -O0 and -O2."""
    unit = work / "unit.c"
    unit.write_text(f'#include "{header}"\nint unit_marker(void);\nint unit_marker(void) {{ return 0; }}\n')
    for opt in ("-O0", "-O2"):
        for source in (unit, harness):
            cmd = [compiler, *STRICT_FLAGS, *FIRMWARE_WARNINGS, opt, f"-I{KERNELS}", "-c", str(source)]
            cmd += ["-o", str(work / "x.o")]
            result = subprocess.run(cmd, capture_output=True, text=True, check=False)
            assert result.returncode == 0 and not result.stderr, f"{source.name} {opt}: {result.stderr}"


def write_records(path: Path, records: list[list[int]], width: int) -> None:
    """A harness's input: one row of ``width`` little-endian int64 per record, zero-padded."""
    rows = np.zeros((len(records), width), dtype="<i8")
    for row, record in zip(rows, records, strict=True):
        row[: len(record)] = record
    path.write_bytes(rows.tobytes())


def build_sanitized(harness: Path, binary: Path) -> Path:
    """The harness built for the host with ASan/UBSan (gcc, -O1)."""
    compile_c([harness], binary, include_dirs=[KERNELS], cc="gcc", flags=("-O1", *SANITIZER_FLAGS))
    return binary


def run_sanitized(binary: Path, records: list[list[int]], width: int, work: Path) -> bytes:
    """Run a sanitized harness on ``records``; any sanitizer report fails the test."""
    work.mkdir(parents=True, exist_ok=True)
    write_records(work / "in.bin", records, width)
    env = dict(os.environ, UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1", ASAN_OPTIONS="detect_leaks=1")
    result = subprocess.run(
        [str(binary), str(work / "in.bin"), str(work / "out.bin")], capture_output=True, env=env, check=False
    )
    assert result.returncode == 0 and b"runtime error" not in result.stderr, result.stderr.decode()[-3000:]
    return (work / "out.bin").read_bytes()
