"""Python driver of the Cortex-M4 build: make, run under QEMU (mps2-an386), read the results back.

Shared by ``codegen verify --cortex-m4``, the tests and bench/bench_cortex_m.py; the C it builds
(the Makefile, start-up code and harnesses) stays in firmware_c/. The apps exchange data with the host through semihosting files; QEMU runs with its
working directory set to a work folder and gets bare file names, so that paths with spaces or
commas never reach the semihosting command line.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from codegen.hostbuild import write_vectors

FIRMWARE_DIR = Path(__file__).resolve().parent.parent / "firmware_c"
INSTALLER = FIRMWARE_DIR.parent / "scripts" / "install_arm_tools.sh"
TOOLS = ("arm-none-eabi-gcc", "arm-none-eabi-size", "qemu-system-arm", "make")
QEMU = "qemu-system-arm"
QEMU_MACHINE = ("-M", "mps2-an386", "-nographic", "-monitor", "none", "-serial", "null")
CMD_INSTANCE_B = 16  # test_app: command bit selecting the second state (bits 0-1: hostbuild.CMD_*)
SYSCLK_HZ = 25_000_000  # mps2-an386 system clock: SysTick's processor clock source


class FirmwareError(RuntimeError):
    """A build or an emulated run failed; the message carries the tool's own output."""


def missing_tools() -> list[str]:
    return [tool for tool in TOOLS if shutil.which(tool) is None]


def ensure_toolchain() -> str | None:
    """None when the cross toolchain and QEMU are usable, else why not (after one install try)."""
    if missing_tools() and INSTALLER.is_file():
        subprocess.run(["bash", str(INSTALLER)], capture_output=True, check=False, timeout=1200)
    missing = missing_tools()
    if missing:
        return f"{', '.join(missing)} not available and scripts/install_arm_tools.sh could not install them"
    return None


@dataclass(frozen=True)
class Build:
    """One generated module (``directory/NAME.{h,c}``) and the folder its Cortex-M build goes to."""

    module_dir: Path
    name: str
    out: Path
    extra_cflags: str = ""
    ldlibs: str = ""  # e.g. "-lm" (the float32 anchors of the benchmark)

    def make(self, *targets: str, **variables: str) -> str:
        """Run firmware_c/Makefile; a failure (warnings are errors) raises with the compiler output."""
        cmd = [
            "make",
            "--no-print-directory",
            "-C",
            str(FIRMWARE_DIR),
            f"MODULE_DIR={self.module_dir.resolve()}",
            f"NAME={self.name}",
            f"OUT={self.out.resolve()}",
            f"EXTRA_CFLAGS={self.extra_cflags}",
            f"LDLIBS={self.ldlibs}",
            *(f"{k}={v}" for k, v in variables.items()),
            *targets,
        ]
        result = subprocess.run(cmd, capture_output=True, text=True, check=False)
        output = result.stdout + result.stderr
        if result.returncode != 0:
            raise FirmwareError(f"make {' '.join(targets)} failed:\n{output[-6000:]}")
        return output

    def elf(self, app: str) -> Path:
        return self.out.resolve() / f"{app}.elf"


def qemu_version() -> str:
    out = subprocess.run([QEMU, "--version"], capture_output=True, text=True, check=True).stdout
    return out.splitlines()[0].strip()


def gcc_version() -> str:
    out = subprocess.run(
        ["arm-none-eabi-gcc", "--version"], capture_output=True, text=True, check=True
    ).stdout
    return out.splitlines()[0].strip()


def run_qemu(
    elf: Path,
    args: list[str],
    *,
    cwd: Path,
    icount: bool = False,
    sleep_off: bool = False,
    timeout: float = 600,
) -> str:
    """Run an app; ``args`` become its semihosting command line. A non-zero exit raises.

    ``icount``: 1 ns of virtual time per instruction (SysTick then counts instructions);
    ``sleep_off``: idle time (WFI) jumps to the next timer deadline instead of passing in real time.
    """
    for arg in args:
        if re.search(r"[\s,]", arg):
            raise ValueError(
                f"semihosting argument {arg!r}: no spaces or commas (pass names relative to cwd)"
            )
    semihosting = ",".join(["enable=on", "target=native", f"arg={elf.stem}", *(f"arg={a}" for a in args)])
    cmd = [
        QEMU,
        *QEMU_MACHINE,
        *(("-icount", "shift=0,sleep=off" if sleep_off else "shift=0") if icount else ()),
        "-semihosting-config",
        semihosting,
        "-kernel",
        str(elf),
    ]
    try:
        result = subprocess.run(
            cmd,
            cwd=cwd,
            capture_output=True,
            text=True,
            check=False,
            timeout=timeout,
            stdin=subprocess.DEVNULL,
        )
    except subprocess.TimeoutExpired:
        raise FirmwareError(f"{elf.name} did not finish within {timeout:g} s under QEMU") from None
    if result.returncode != 0:
        raise FirmwareError(
            f"{elf.name} exited with status {result.returncode} under QEMU:\n{(result.stdout + result.stderr)[-4000:]}"
        )
    return result.stdout


def _key_values(text: str) -> dict[str, str]:
    out = {}
    for line in text.splitlines():
        key, _, value = line.partition(" ")
        out[key] = value.strip()
    return out


@dataclass(frozen=True)
class StreamResult:
    outputs: np.ndarray  # int32, one per record
    states: tuple[bytes, bytes]  # final state structs of instances A and B
    model_id: str
    state_bytes: int


def stream(
    build: Build, accel: np.ndarray, temp: np.ndarray, commands: np.ndarray, work: Path
) -> StreamResult:
    """Stream records (hostbuild.write_vectors format, plus CMD_INSTANCE_B) through test_app on the target."""
    build.make("test-app")
    work.mkdir(parents=True, exist_ok=True)
    write_vectors(work / "vectors.bin", accel, temp, commands)
    stdout = run_qemu(build.elf("test_app"), ["vectors.bin", "outputs.bin", "states.bin"], cwd=work)
    info = _key_values(stdout)
    if info.get("records") != str(accel.size):
        raise FirmwareError(f"test_app processed {info.get('records')} records, not {accel.size}:\n{stdout}")
    size = int(info["state_bytes"])
    raw = (work / "states.bin").read_bytes()
    return StreamResult(
        np.fromfile(work / "outputs.bin", dtype="<i4"), (raw[:size], raw[size:]), info["model_id"], size
    )


@dataclass(frozen=True)
class BenchCounts:
    """Instructions per call of NAME_step on the target (call and return included, loop excluded)."""

    model_id: str
    decimation: int  # 0: memoryless model
    samples: int
    instructions_per_tick: float  # 40 on mps2-an386 with -icount shift=0
    average: float  # per sample over whole periods (streaming) or the whole stream (memoryless)
    worst: float  # streaming: a sample on which the network steps; memoryless: the costliest batch
    plain: float  # streaming: a sample without network step; memoryless: = average
    worst_single: float  # streaming: the costliest single network-step sample (+-1 tick)
    worst_phase: float  # streaming: the costliest phase of the period, averaged over the periods
    phase_costs: tuple[float, ...] = ()  # streaming: every phase's cost, averaged over the periods


def bench(
    build: Build, work: Path, vectors: Path | None = None, rate_millihz: int | None = None
) -> BenchCounts:
    """Run bench_app under ``-icount shift=0`` and convert its SysTick ticks to instructions.

    ``rate_millihz``: the rate the stream stands for (default the Makefile's 200 Hz); a module
    exported for another rate fails to build (its rate check macro)."""
    build.make("bench-app", **({} if rate_millihz is None else {"RATE_MILLIHZ": str(rate_millihz)}))
    work.mkdir(parents=True, exist_ok=True)
    args = []
    if vectors is not None:
        shutil.copyfile(vectors, work / "bench_vectors.bin")
        args = ["bench_vectors.bin"]
    lines = run_qemu(build.elf("bench_app"), args, cwd=work, icount=True).splitlines()
    fields: dict[str, list[str]] = {}
    batches: list[tuple[int, int]] = []  # (samples, ticks net of the empty-call loop)
    phases: list[int] = []  # per phase of the period: ticks net of the empty call, summed over periods
    for line in lines:
        key, *values = line.split()
        fields[key] = values
        if key == "batch":
            batches.append((int(values[0]), int(values[1]) - int(values[2])))
        if key == "phase":
            phases.append(int(values[1]) - int(values[2]))
    instr, ticks = (int(v) for v in fields["calibration"])
    ipt = float(round(instr / ticks))  # 1e9 / SYSCLK_HZ = 40: 1 ns per instruction, 25 MHz SysTick
    if abs(instr / ticks - ipt) > 0.01 or ipt != 1e9 / SYSCLK_HZ:
        raise FirmwareError(
            f"SysTick calibration: {instr} instructions in {ticks} ticks (is -icount shift=0 on?)"
        )
    model_id, decimation, samples = (
        fields["model_id"][0],
        int(fields["decimation"][0]),
        int(fields["samples"][0]),
    )
    if decimation:
        n_net, net, net_null, net_max = (int(v) for v in fields["network"])
        n_plain, plain, plain_null = (int(v) for v in fields["plain"])
        average = ((net - net_null) + (plain - plain_null)) * ipt / (n_net + n_plain)
        network, plain_cost = (net - net_null) * ipt / n_net, (plain - plain_null) * ipt / n_plain
        costs = tuple(t * ipt / n_net for t in phases)
        return BenchCounts(
            model_id, decimation, samples, ipt, average, network, plain_cost, net_max * ipt, max(costs), costs
        )
    per_batch = [t * ipt / count for count, t in batches]
    average = sum(t for _, t in batches) * ipt / sum(c for c, _ in batches)
    return BenchCounts(
        model_id, 0, samples, ipt, average, max(per_batch), average, max(per_batch), max(per_batch)
    )


@dataclass(frozen=True)
class Size:
    text: int  # code and const data (flash)
    data: int  # initialised data (flash and RAM)
    bss: int  # zeroed data (RAM)
    path: Path

    @property
    def flash(self) -> int:
        return self.text + self.data

    @property
    def ram(self) -> int:
        return self.data + self.bss


def sizes(*paths: Path) -> list[Size]:
    """``arm-none-eabi-size`` (Berkeley format) of objects or ELF files."""
    out = subprocess.run(["arm-none-eabi-size", *map(str, paths)], capture_output=True, text=True, check=True)
    rows = []
    for line, path in zip(out.stdout.splitlines()[1:], paths, strict=True):
        text, data, bss = (int(v) for v in line.split()[:3])
        rows.append(Size(text, data, bss, path))
    return rows


def build_env_note() -> str:
    return f"{gcc_version()}; {qemu_version()}; host {os.uname().machine}"
