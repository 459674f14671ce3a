"""Cost of the generated module on the target: instructions per 200 Hz sample on a Cortex-M4F (QEMU
mps2-an386, -icount shift=0), flash and RAM (arm-none-eabi-size, -fstack-usage), next to the
multiply-accumulate lower bound counted from the architecture.

Models (default): the paper's 2x10 recursive DLSTM, *trained quickly* with the real trainer
(dlstm-issa, population 2, 5 iterations, 2 sparrow cycles: the instruction count does not depend on
the weight values, only on the architecture and the path through the saturations), the
temperature-input DLSTM (2x10, trained the same way), PLA, the PX4-style cubic and the grey-box
physics model (lag, rate and branch-offset terms forced: a ramp does not identify them), all on a
simulated 10-minute oven run (seed 1). The timed stream is another simulated run (seed 2, 5 minutes
at 200 Hz, the whole temperature ramp), loaded into the target's RAM before anything is timed.

How it counts: QEMU's -icount shift=0 advances the virtual clock by 1 ns per executed instruction;
SysTick, clocked at 25 MHz, then ticks once per 40 instructions (checked by a calibration loop).
The bench app times every network-step sample alone and the other samples of each period as one
batch, and repeats every timed loop with an empty function of the same signature: the difference
is the cost of the NAME_step calls (call and return included). QEMU counts instructions, not
cycles (no wait states, no pipeline effects).

    python bench/bench_cortex_m.py [--model model.pt ...] [--json costs.json]

Modules with a time base are exported for the stream's 200 Hz (codegen export --rate 200) and the
bench app refuses, at compile time, a module built for another rate. --json writes each generated
module's model_id, instructions_per_sample, flash_bytes and ram_bytes for 'trainer report --bench'.

Anchors, in the same run, for every DLSTM: the generated module with its SMLAD path (the default on
a Cortex-M4) and with the portable path (-DTDCK_PORTABLE), both checked bit-exact against the
golden model on the target, and the same network as plain float32 C (bench/float_anchor.py) with
libm activations and with a rational fast tanh; the ratio of the network-step costs is printed.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from float_anchor import write_float_module

from codegen import cortex_m as cm
from codegen.export import LoadedModel, export
from codegen.families.cubic import QPoly3
from codegen.families.physics.quantise import QPhysics
from codegen.families.pla import QPla
from codegen.families.stream.quantise import QStream
from codegen.families.stream.spec import DlstmModelSpec
from codegen.golden_select import golden_for
from codegen.hostbuild import write_vectors
from codegen.verify import to_step_units
from trainer import methods as registry
from trainer.cli import main as trainer_main
from trainer.data.recording_io import read_recording
from trainer.options.methods import DLSTM_OPTIONS

CLOCK_MHZ = 168.0  # a typical Cortex-M4F flight computer (STM32F4): time per sample at 1 instruction/cycle
STREAM_RATE_HZ = 200  # the timed stream's rate: modules with a time base are exported for it (--rate)
FIT_QUICK = ["--population", "2", "--iterations", "5", "--cycles", "2", "--quiet"]
# physics: the structure forced to the terms the real run shows (a single simulated ramp identifies
# none of them, so 'auto' would export a plain cubic); the cost does not depend on the values
PHYSICS_FORCED = ["--effects", "thermal_lag,temp_rate,hysteresis_offset", "--quiet"]


@dataclass(frozen=True)
class LowerBound:
    """Multiply-accumulates of the model, counted from its architecture."""

    per_step: int  # weight MACs of one network step (or of one sample for memoryless models)
    bias_adds: int
    per_sample: float  # averaged over the decimation
    text: str


def lower_bound(model: LoadedModel) -> LowerBound:
    q = model.quantised
    if isinstance(q, QStream) and q.layers:
        H = q.hidden_size
        rows = [(lay.wx.q.shape[0], lay.wx.q.shape[1]) for lay in q.layers]
        macs = sum(r * (n_in + H) for r, n_in in rows) + H
        assert macs == q.macs_per_step(), "architecture count disagrees with the quantiser's"
        text = " + ".join(f"4x{H}x({n_in}+{H})" for _, n_in in rows) + f" + {H}"
        D = q.frontend.decimation
        return LowerBound(macs, sum(r for r, _ in rows) + 1, macs / D, text)
    if isinstance(q, QPla):
        return LowerBound(1, 1, 1.0, "slope x T + intercept")
    if isinstance(q, QPoly3):
        return LowerBound(3, 3, 3.0, "Horner, degree 3")
    if isinstance(q, QPhysics):  # Horner, two products per low-pass, one per drift term
        macs = 3 + 2 * len(q.filters) + len(q.gains)
        return LowerBound(
            macs, macs, float(macs), f"Horner 3 + {len(q.filters)} low-passes x 2 + {len(q.gains)} gains"
        )
    return LowerBound(0, 0, 0.0, "window mean only")


def stack_bound(build: Any, name: str) -> int:
    """Sum of the frames of every function in the module (-fstack-usage): no recursion, so this
    bounds the deepest call chain from NAME_step."""
    su = Path(build.out) / f"{name}.su"
    return sum(int(line.split("\t")[1]) for line in su.read_text().splitlines() if line.strip())


def bit_exact_on_target(
    build: Any, model: LoadedModel, accel: np.ndarray, temp: np.ndarray, work: Path
) -> tuple[int, int]:
    """Mismatches against the golden model over the stream on the target, and sizeof(NAME_state_t) there."""
    result = cm.stream(build, accel, temp, np.zeros(accel.size, dtype=np.int64), work)
    golden = golden_for(model.quantised).run(accel, temp)
    return int(np.count_nonzero(result.outputs.astype(np.int64) != golden)), result.state_bytes


# ------------------------------------------------------------------------------------ models


def default_models(work: Path) -> list[tuple[str, Path]]:
    train = work / "train.npz"
    assert trainer_main(["simulate", "--seed", "1", "--duration", "600", "-o", str(train)]) == 0
    models = []
    # The paper's best recursive DLSTM (the last of the shared population), then every other method
    # with its own C that 'trainer fit' offers, with default options (DLSTMs: 2 x 10, quick fit).
    fittable = [m for m in registry.entries() if m.in_fit_cli and m.renderer is not None]
    sharing = [m for m in fittable if m.shares_population]
    for method in [*sharing[-1:], *(m for m in fittable if not m.shares_population)]:
        extra = FIT_QUICK if method.options is DLSTM_OPTIONS else ["--quiet"]
        if method.renderer == registry.PHYSICS_RENDERER:
            extra = PHYSICS_FORCED
        path = work / f"{method.name}.pt"
        assert trainer_main(["fit", "--method", method.name, str(train), "-o", str(path), *extra]) == 0
        models.append((f"{method.name} ({method.family})", path))
    return models


@dataclass(frozen=True)
class Row:
    label: str
    variant: str
    counts: Any  # cm.BenchCounts
    bound: LowerBound
    module: Any  # cm.Size of NAME.o
    state_bytes: int
    stack_bytes: int
    mismatches: int | None  # None: not a fixed-point module (the float32 anchors)


def measure(
    label: str,
    variant: str,
    model: LoadedModel,
    build: Any,
    vectors: Path,
    stream: tuple[np.ndarray, np.ndarray],
    work: Path,
    exact: bool = True,
) -> Row:
    """Bit-exactness (fixed-point modules), instruction counts, sizes of one build."""
    build.make("module")
    mismatches: int | None = None
    if exact:
        mismatches, state_bytes = bit_exact_on_target(build, model, *stream, work / "exact")
    else:
        zeros = np.zeros(stream[0].size, dtype=np.int64)
        state_bytes = cm.stream(build, stream[0], stream[1], zeros, work / "run").state_bytes
    counts = cm.bench(build, work / "bench", vectors, rate_millihz=STREAM_RATE_HZ * 1000)
    (module,) = cm.sizes(Path(build.out) / f"{build.name}.o")
    return Row(
        label,
        variant,
        counts,
        lower_bound(model),
        module,
        state_bytes,
        stack_bound(build, build.name),
        mismatches,
    )


def write_json(rows: list[Row], path: Path) -> None:
    """The generated modules' costs, keyed by model id (docs/signoff.md: ``trainer report --bench``)."""
    modules = [
        {
            "model_id": r.counts.model_id,
            "label": r.label,
            "variant": r.variant,
            "rate_hz": STREAM_RATE_HZ,
            "instructions_per_sample": r.counts.average,
            "worst_instructions_per_sample": r.counts.worst,
            "flash_bytes": r.module.flash,
            "ram_bytes": r.module.ram + r.state_bytes,
            "stack_bytes": r.stack_bytes,
        }
        for r in rows
        if r.variant in ("generated", "generated, SMLAD")
    ]
    path.write_text(json.dumps({"modules": modules}, indent=2, sort_keys=True) + "\n", encoding="utf-8")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", action="append", type=Path, help="model.pt to measure (repeatable)")
    parser.add_argument(
        "--json", type=Path, help="also write the generated modules' costs (for 'trainer report')"
    )
    args = parser.parse_args()
    reason = cm.ensure_toolchain()
    if reason is not None:
        print(f"bench_cortex_m: {reason}", file=sys.stderr)
        return 1
    rows: list[Row] = []
    apps: list[Path] = []
    delays: list[tuple[str, int, bool, float]] = []
    with tempfile.TemporaryDirectory(prefix="bench-cortex-m-") as tmp:
        work = Path(tmp)
        models = [(p.name, p) for p in args.model] if args.model else default_models(work)
        stream_path = work / "stream.npz"
        assert trainer_main(["simulate", "--seed", "2", "--duration", "300", "-o", str(stream_path)]) == 0
        accel, temp = (v.astype(np.int64) for v in to_step_units(read_recording(stream_path)))
        vectors = work / "vectors.bin"
        write_vectors(vectors, accel, temp, np.zeros(accel.size, dtype=np.int64))
        for k, (label, path) in enumerate(models):
            name = f"bench{k}"
            model, _ = export(path, work / f"m{k}", name=name, rate_millihz=STREAM_RATE_HZ * 1000)
            build = cm.Build(work / f"m{k}", name, work / f"build{k}")
            network = isinstance(model.quantised, QStream) and bool(model.quantised.layers)
            variant = "generated, SMLAD" if network else "generated"
            rows.append(measure(label, variant, model, build, vectors, (accel, temp), work / f"r{k}"))
            build.make("test-app", "bench-app")
            apps += [build.elf("test_app"), build.elf("bench_app")] if k == 0 else []
            q, spec = model.quantised, model.checkpoint.model
            if not (isinstance(q, QStream) and q.layers and isinstance(spec, DlstmModelSpec)):
                continue
            portable = cm.Build(work / f"m{k}", name, work / f"pbuild{k}", extra_cflags="-DTDCK_PORTABLE")
            rows.append(
                measure(label, "generated, portable", model, portable, vectors, (accel, temp), work / f"p{k}")
            )
            spread, _ = export(path, work / f"s{k}", name=name, schedule="spread")
            sbuild = cm.Build(work / f"s{k}", name, work / f"sbuild{k}")
            rows.append(
                measure(label, "generated, spread", spread, sbuild, vectors, (accel, temp), work / f"s{k}r")
            )
            delays.append((label, *spread_delay(model, spread, accel, temp)))
            for variant in ("libm", "fast"):
                folder = work / f"f{k}{variant}"
                write_float_module(spec, q, name, folder, variant)
                fb = cm.Build(folder, name, work / f"fb{k}{variant}", ldlibs="-lm")
                row = measure(
                    label,
                    f"float32, {variant}",
                    model,
                    fb,
                    vectors,
                    (accel, temp),
                    work / f"fr{k}{variant}",
                    exact=False,
                )
                rows.append(row)
        app_sizes = cm.sizes(*apps) if apps else []
    report(rows, app_sizes, accel.size, delays)
    if args.json:
        write_json(rows, args.json)
    return 0 if all(r.mismatches in (0, None) for r in rows) else 1


def spread_delay(
    model: LoadedModel, spread: LoadedModel, accel: np.ndarray, temp: np.ndarray
) -> tuple[int, bool, float]:
    """The spread schedule's latency (samples), whether its drift estimate, on the whole stream,
    is the step schedule's delayed by exactly that many samples (goldens: the C equals them), and
    the sample rate."""
    q = spread.quantised
    assert isinstance(q, QStream)
    lat = q.latency_samples
    step_drift = accel - golden_for(model.quantised).run(accel, temp)
    spread_drift = accel - golden_for(spread.quantised).run(accel, temp)
    same = bool(np.array_equal(spread_drift[lat:], step_drift[: step_drift.size - lat]))
    return lat, same and not np.any(spread_drift[:lat]), q.frontend.rate_hz


def report(
    rows: list[Row], app_sizes: list[Any], stream_samples: int, delays: list[tuple[str, int, bool, float]]
) -> None:
    print("Cortex-M4F (-mcpu=cortex-m4 -mthumb -mfloat-abi=hard -O2) under QEMU mps2-an386, -icount shift=0;")
    print(f"{cm.build_env_note()}; {platform.platform()}")
    print(f"stream: {stream_samples} samples (5 min at 200 Hz, simulated oven run, seed 2); "
          "instructions per call of NAME_step, call and return included\n")  # fmt: skip
    head = (f"{'model':<25} {'variant':<19} {'avg':>7} {'worst':>7} {'max/avg':>7} {'plain':>6} {'MAC/step':>9} "
            f"{'MAC/smp':>8} {'instr/MAC':>9} {'us@168':>7} {'flash B':>8} {'state B':>8} {'stack B':>8} "
            f"{'exact':>6}")  # fmt: skip
    print(head)
    print("-" * len(head))
    for r in rows:
        c = r.counts
        worst = c.worst_phase if r.variant == "generated, spread" else c.worst
        ratio = worst / r.bound.per_step if r.bound.per_step else float("nan")
        print(
            f"{r.label:<25} {r.variant:<19} {c.average:>7.1f} {worst:>7.0f} {c.worst_phase / c.average:>7.2f} "
            f"{c.plain:>6.1f} {r.bound.per_step:>9} {r.bound.per_sample:>8.2f} {ratio:>9.1f} "
            f"{worst / CLOCK_MHZ:>7.1f} {r.module.flash:>8} {r.state_bytes:>8} {r.stack_bytes:>8} "
            f"{'n/a' if r.mismatches is None else 'yes' if r.mismatches == 0 else 'NO':>6}"
        )
    print()
    print("avg   = instructions per sample averaged over the stream (streaming models: whole 1 s periods)")
    print(
        "worst = a sample on which the network steps (streaming), the costliest batch of 250 samples (PLA, poly3);"
    )
    print("        spread schedule: the costliest phase of the period (averaged over the periods)")
    print("max/avg = the costliest phase of the period / avg (streaming: every sample timed alone)")
    print("plain = a sample without network step; MAC/step = weight multiply-accumulates of one network step")
    print(
        "        (PLA, poly3: per sample), the lower bound: one MAC per instruction (SMLABB), two with SMLAD;"
    )
    for r in rows:
        if r.variant == "generated, SMLAD" and r.bound.per_step > 1:
            print(
                f"        {r.label}: {r.bound.text} = {r.bound.per_step} MACs (+ {r.bound.bias_adds} bias adds)"
            )
    print(
        "us@168 = worst-case sample in microseconds at 168 MHz, assuming 1 instruction per cycle (QEMU counts"
    )
    print("        instructions, not cycles: flash wait states and multi-cycle instructions add to it)")
    print("flash = text + data of the module object NAME.o (code and const tables); state = the caller's")
    print(
        "        NAME_state_t (RAM, one per instance); stack = sum of all the module's frames (upper bound)"
    )
    print("exact = the module on the target equals the golden model on every sample of the stream\n")
    by_label: dict[str, dict[str, Row]] = {}
    for r in rows:
        by_label.setdefault(r.label, {})[r.variant] = r
    for label, variants in by_label.items():
        gen = variants.get("generated, SMLAD")
        for anchor in ("float32, libm", "float32, fast"):
            if gen is not None and anchor in variants:
                ratio = variants[anchor].counts.worst / gen.counts.worst
                print(f"{label}: network step of {anchor} / generated (SMLAD) = {ratio:.2f}")
    for label, lat, same, rate in delays:
        print(
            f"{label}: spread schedule latency {lat} samples ({lat / rate:g} s at {rate:g} Hz); its drift estimate "
            f"= the step schedule's delayed by {lat} samples on every sample of the stream: {'yes' if same else 'NO'}"
        )
    print()
    for s in app_sizes:
        print(f"whole app {s.path.name:<14} text {s.text:>7} data {s.data:>6} bss {s.bss:>7}  (newlib stdio and "
              "semihosting included; bss holds the I/O buffers)")  # fmt: skip


if __name__ == "__main__":
    sys.exit(main())
