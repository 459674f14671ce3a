"""Compile generated modules with the host C compiler and drive them from Python through cffi.

The sources are compiled into a shared library with the strict warning set the generated code
must pass (so every host build is also a warning check), then opened with cffi in ABI mode; the
cdef is the generated header itself minus its preprocessor lines, so Python sees exactly the
struct layout the C compiler used. A whole recording streams through ``NAME_run`` in one call.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cffi
import numpy as np

from trainer.errors import UserError

STRICT_FLAGS = ("-std=c99", "-pedantic", "-Wall", "-Wextra", "-Wconversion", "-Wshadow", "-Werror")
# what a firmware build that includes generated code or the kernel headers may add to STRICT_FLAGS
FIRMWARE_WARNINGS = (
    "-Wstrict-prototypes",
    "-Wmissing-prototypes",
    "-Wundef",
    "-Wcast-qual",
    "-Wvla",
    "-Wdouble-promotion",
    "-Wfloat-equal",
)
SANITIZER_FLAGS = (
    "-fsanitize=address,undefined",
    "-fno-sanitize-recover=all",
    "-fno-omit-frame-pointer",
    "-g",
)


def find_compiler(preferred: str | None = None) -> str:
    """``preferred`` (``--cc``: that one or a one-line refusal, never another), else $CC, else
    cc/gcc/clang on PATH."""
    if preferred and not shutil.which(preferred):
        raise UserError(f"--cc {preferred}: no such compiler on PATH")
    for candidate in (preferred, os.environ.get("CC"), "cc", "gcc", "clang"):
        if candidate and shutil.which(candidate):
            return candidate
    raise UserError("no C compiler found (set CC or install gcc)")


def compile_c(
    sources: list[Path],
    output: Path,
    *,
    include_dirs: list[Path],
    cc: str | None = None,
    flags: tuple[str, ...] = ("-O2",),
    shared: bool = False,
) -> None:
    """Compile (and link) ``sources`` with the strict flags; a compiler message is a UserError."""
    cmd = [find_compiler(cc), *STRICT_FLAGS, *flags]
    if shared:
        cmd += ["-shared", "-fPIC"]
    cmd += [f"-I{d}" for d in include_dirs] + [str(s) for s in sources] + ["-o", str(output)]
    result = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if result.returncode != 0:
        first = (result.stderr.strip().splitlines() or ["(no message)"])[0]
        raise UserError(f"compiling {', '.join(s.name for s in sources)} failed: {first}")


def cdef_from_header(text: str) -> str:
    """The declarations of a generated header, as cffi's cdef wants them (no preprocessor)."""
    out, skipping = [], False
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("#ifdef __cplusplus"):
            skipping = True
            continue
        if skipping:
            skipping = not stripped.startswith("#endif")
            continue
        if not stripped.startswith("#"):
            out.append(line)
    return "\n".join(out)


def _field_value(ffi: cffi.FFI, cdata: Any, ctype: Any) -> np.ndarray | int:
    if ctype.kind == "array":
        item = ctype.item
        dims = [ctype.length]
        while item.kind == "array":
            dims.append(item.length)
            item = item.item
        dtype = np.dtype(f"{'u' if item.cname.startswith('u') else 'i'}{ffi.sizeof(item)}")
        return np.frombuffer(ffi.buffer(cdata), dtype=dtype).reshape(dims).astype(np.int64)
    return int(cdata)


@dataclass
class HostModule:
    """One generated module loaded in this process."""

    ffi: cffi.FFI
    lib: Any
    name: str

    def new_state(self) -> Any:
        state = self.ffi.new(f"{self.name}_state_t *")
        getattr(self.lib, f"{self.name}_init")(state)
        return state

    def reset(self, state: Any) -> None:
        getattr(self.lib, f"{self.name}_reset")(state)

    def step(self, state: Any, accel_q4ug: int, temp_mdegc: int) -> int:
        return int(getattr(self.lib, f"{self.name}_step")(state, accel_q4ug, temp_mdegc))

    def run(self, state: Any, accel_q4ug: np.ndarray, temp_mdegc: np.ndarray) -> np.ndarray:
        accel = np.ascontiguousarray(accel_q4ug, dtype=np.int32)
        temp = np.ascontiguousarray(temp_mdegc, dtype=np.int32)
        if accel.shape != temp.shape or accel.ndim != 1:
            raise ValueError("accel and temp must be 1-D arrays of the same length")
        out = np.empty_like(accel)
        getattr(self.lib, f"{self.name}_run")(
            state,
            self.ffi.from_buffer("int32_t[]", accel),
            self.ffi.from_buffer("int32_t[]", temp),
            self.ffi.from_buffer("int32_t[]", out),
            accel.size,
        )
        return out

    def model_id(self) -> str:
        return self.ffi.string(getattr(self.lib, f"{self.name}_model_id")()).decode()

    def read_state(self, state: Any) -> dict[str, np.ndarray | int]:
        """Every field of the state struct, arrays as int64 numpy arrays (for the golden comparison)."""
        fields = self.ffi.typeof(f"{self.name}_state_t").fields
        return {name: _field_value(self.ffi, getattr(state, name), f.type) for name, f in fields}

    def state_from_bytes(self, data: bytes) -> dict[str, np.ndarray | int]:
        """Decode a state struct dumped by the sanitizer harness."""
        state = self.ffi.from_buffer(f"{self.name}_state_t *", bytearray(data))
        return self.read_state(state)

    def sizeof_state(self) -> int:
        return int(self.ffi.sizeof(f"{self.name}_state_t"))


def load_modules(
    modules: list[tuple[Path, str]], *, cc: str | None = None, flags: tuple[str, ...] = ("-O2",)
) -> list[HostModule]:
    """Build the generated modules ``(directory, NAME)`` into one shared library and open it."""
    ffi = cffi.FFI()
    sources = []
    for directory, name in modules:
        header = directory / f"{name}.h"
        source = directory / f"{name}.c"
        for path in (header, source):
            if not path.is_file():
                raise UserError(f"{path}: missing (run 'codegen export' first)")
        ffi.cdef(cdef_from_header(header.read_text()))
        sources.append(source)
    with tempfile.TemporaryDirectory(prefix="codegen-host-") as tmp:
        library = Path(tmp) / "libgenerated.so"
        compile_c(
            sources, library, include_dirs=sorted({d for d, _ in modules}), cc=cc, flags=flags, shared=True
        )
        lib = ffi.dlopen(str(library))
    return [HostModule(ffi, lib, name) for _, name in modules]


def load_module(
    directory: Path, name: str, *, cc: str | None = None, flags: tuple[str, ...] = ("-O2",)
) -> HostModule:
    return load_modules([(directory, name)], cc=cc, flags=flags)[0]


# ------------------------------------------------------------------------------ sanitizer harness

CMD_SAMPLE, CMD_RESET, CMD_INIT = 0, 1, 2


def write_vectors(path: Path, accel: np.ndarray, temp: np.ndarray, commands: np.ndarray) -> None:
    """Test vectors for the harness: int32 triples (accel, temp, command before the sample)."""
    records = np.column_stack([accel, temp, commands]).astype("<i4")
    path.write_bytes(records.tobytes())


def build_harness(
    directory: Path,
    name: str,
    harness_source: str,
    output: Path,
    *,
    cc: str | None = None,
    flags: tuple[str, ...] = ("-O1", *SANITIZER_FLAGS),
) -> Path:
    """Compile the generated module with a rendered harness (``harness_vectors.c.j2``)."""
    harness = output.with_suffix(".harness.c")
    harness.write_text(harness_source)
    compile_c([directory / f"{name}.c", harness], output, include_dirs=[directory], cc=cc, flags=flags)
    return output


def run_harness(binary: Path, vectors: Path, outputs: Path) -> bytes:
    """Run the harness; returns the dumped state bytes. A sanitizer report fails loudly."""
    env = dict(os.environ, UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1", ASAN_OPTIONS="detect_leaks=1")
    result = subprocess.run(
        [str(binary), str(vectors), str(outputs)], capture_output=True, env=env, check=False
    )
    stderr = result.stderr.decode(errors="replace")
    if result.returncode != 0 or re.search(r"runtime error|AddressSanitizer|LeakSanitizer", stderr):
        raise AssertionError(f"harness failed (exit {result.returncode}):\n{stderr[-4000:]}")
    return result.stdout
