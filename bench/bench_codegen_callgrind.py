"""Cost of one 200 Hz sample of the generated C, in instructions (valgrind --tool=callgrind).

For each method a module is exported (the paper's 2x10 DLSTM with random weights unless --model is
given: the instruction count does not depend on the weight values), compiled with -O2 into a small
harness that streams synthetic samples, and run under callgrind twice: once collecting only inside
the wrapper called on samples where the network steps (the worst case), once only inside the
wrapper of the other samples. Printed per method: instructions per sample on average and in the
worst case, and the model's multiply-accumulates as the lower bound to compare with.

    python bench/bench_codegen_callgrind.py [--samples 20000] [--model model.pt ...]
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

# The test checkpoints live with the tests (tests/testmodels.py), outside the installed packages:
# put the repository root on the path so that ``tests`` is importable however the bench is run.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from codegen.export import export
from codegen.families.pla import QPla
from codegen.families.stream.quantise import QStream
from codegen.hostbuild import STRICT_FLAGS, find_compiler
from codegen.render import render_template
from tests import testmodels as tm
from trainer.cli import main as trainer_main
from trainer.data.recording_io import read_recording


def callgrind_instructions(binary: Path, function: str, work: Path) -> int:
    """Instructions executed inside ``function`` (inclusive) during the whole run."""
    out = work / f"callgrind.{function}.out"
    subprocess.run(
        [
            "valgrind",
            "--tool=callgrind",
            f"--toggle-collect={function}*",
            f"--callgrind-out-file={out}",
            str(binary),
        ],
        check=True,
        capture_output=True,
    )
    text = out.read_text()
    match = re.search(r"^(?:summary|totals):\s*(\d+)", text, flags=re.M)
    return int(match.group(1)) if match else 0


def bench_model(model_path: Path, work: Path, samples: int, cc: str) -> dict[str, object]:
    model, files = export(model_path, work / "out", name="bench")
    q = model.quantised
    harness = work / "harness.c"
    harness.write_text(render_template("harness_bench.c.j2", q, "bench", model.sha256, samples=samples))
    binary = work / "bench"
    flags = [f for f in STRICT_FLAGS if f != "-Werror"]
    subprocess.run(
        [
            cc,
            *flags,
            "-O2",
            "-gdwarf-4",  # valgrind 3.19 cannot read clang's DWARF 5
            f"-I{work / 'out'}",
            str(work / "out" / "bench.c"),
            str(harness),
            "-o",
            str(binary),
        ],
        check=True,
    )
    counts = subprocess.run([str(binary)], capture_output=True, text=True, check=True).stdout.split()
    n_network = int(counts[3])
    plain = callgrind_instructions(binary, "bench_plain_sample", work)
    network = callgrind_instructions(binary, "bench_network_sample", work) if n_network else 0
    obj = work / "bench.o"
    subprocess.run([cc, "-std=c99", "-O2", "-c", str(work / "out" / "bench.c"), "-o", str(obj)], check=True)
    size = (
        subprocess.run(["size", str(obj)], capture_output=True, text=True, check=True)
        .stdout.splitlines()[1]
        .split()
    )
    macs_step = q.macs_per_step() if isinstance(q, QStream) else (1 if isinstance(q, QPla) else 3)
    decimation = q.frontend.decimation if isinstance(q, QStream) else 1
    manifest = json.loads(files["bench.manifest.json"])
    return {
        "method": q.method,
        "avg": (plain + network) / samples,
        "worst": network / n_network if n_network else plain / samples,
        "plain": plain / (samples - n_network),
        "macs_step": macs_step,
        "macs_avg": macs_step / decimation,
        "flash": manifest["sizes"]["flash_table_bytes"],
        "ram": manifest["sizes"]["ram_state_bytes"],
        "text": int(size[0]),
    }


def default_models(work: Path) -> list[Path]:
    rec_path = work / "rec.npz"
    assert trainer_main(["simulate", "--seed", "2", "--duration", "600", "-o", str(rec_path)]) == 0
    rec = read_recording(rec_path)
    paths = []
    for method in tm.representatives():  # one per generated C; DLSTMs: the paper's 2 x 10, 1 s steps
        checkpoint = tm.checkpoint_for(method, rec)
        paths.append(work / f"{method}.pt")
        tm.save_checkpoint(checkpoint, paths[-1])
    return paths


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--samples", type=int, default=20_000, help="samples streamed (default 20000 = 100 s)"
    )
    parser.add_argument("--model", action="append", type=Path, help="model.pt to measure (repeatable)")
    parser.add_argument("--cc", default=None, help="C compiler (default $CC, cc, gcc)")
    args = parser.parse_args()
    if shutil.which("valgrind") is None:
        print("valgrind is not installed: run scripts/install_c_tools.sh", file=sys.stderr)
        return 1
    cc = find_compiler(args.cc)
    with tempfile.TemporaryDirectory(prefix="bench-codegen-") as tmp:
        work = Path(tmp)
        models = args.model or default_models(work)
        rows = []
        for k, path in enumerate(models):
            sub = work / f"m{k}"
            sub.mkdir()
            rows.append(bench_model(path, sub, args.samples, cc))
    print(f"instructions per 200 Hz sample ({cc} -O2, x86-64, valgrind callgrind, {args.samples} samples)")
    header = (
        f"{'method':<12} {'avg instr':>10} {'worst instr':>12} {'plain instr':>12} {'MAC/step':>9} "
        f"{'MAC/sample':>11} {'flash B':>8} {'RAM B':>6} {'.text B':>8}"
    )
    print(header)
    print("-" * len(header))
    for r in rows:
        print(
            f"{r['method']:<12} {r['avg']:>10.1f} {r['worst']:>12.0f} {r['plain']:>12.1f} {r['macs_step']:>9} "
            f"{r['macs_avg']:>11.2f} {r['flash']:>8} {r['ram']:>6} {r['text']:>8}"
        )
    print(
        "worst = a sample on which the network steps; MAC = multiply-accumulates of the model (lower bound);"
    )
    print(
        "flash = const tables + model id (manifest); RAM = the caller's state struct; .text = host object code."
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
