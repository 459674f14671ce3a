"""Benchmark ``trainer fleet``: units per minute on 1 and 2 workers in one run, and the scheduler's cost.

The simulated fleet of ``trainer.fleet.simulated`` (short units: 9,900 samples, the default
methods, the finder on 120 blocks) runs on a fresh ``LocalCluster`` of each size. The cluster is started and
every worker has imported the pipeline before the clock starts, so the figure is the steady
throughput a long production run sees (start-up is printed apart). The scheduler's overhead per
task is measured on the largest cluster with tasks that do nothing: the wall time per task of a
batch (throughput cost) and of one task submitted and awaited alone (round trip). The workers' CPU
time per unit and the share of their cores they got are printed too: on a shared machine the
ratio of throughputs is only as good as the cores the other processes leave free.

    python bench/bench_fleet.py                     # 24 units on 1 and 2 workers
    python bench/bench_fleet.py --units 48 --workers 1,2
"""

from __future__ import annotations

import argparse
import importlib
import os
import platform
import tempfile
import time
from pathlib import Path

NOOP_BATCH = 2000
NOOP_ROUND_TRIPS = 100


def machine() -> str:
    cpu = platform.processor() or "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import dask

    return (
        f"{platform.node()} | {cpu} | {os.cpu_count()} cores | Python {platform.python_version()} | "
        f"dask {dask.__version__}"
    )


def load_average() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def warm() -> None:
    """Import what a unit's tasks import, so that the timed run does not pay for it."""
    for module in ("codegen.verify", "trainer.diagnose", "trainer.fitting", "trainer.scoring.evaluate"):
        importlib.import_module(module)


def noop(x: int) -> int:
    return x


def scheduler_overhead(client: object) -> tuple[float, float]:
    """(seconds per task in a batch of no-op tasks, seconds per no-op round trip)."""
    from distributed import Client, wait

    assert isinstance(client, Client)
    client.gather(client.map(noop, range(100), pure=False))  # warm the path
    start = time.perf_counter()
    wait(client.map(noop, range(NOOP_BATCH), pure=False))
    batch = (time.perf_counter() - start) / NOOP_BATCH
    start = time.perf_counter()
    for i in range(NOOP_ROUND_TRIPS):
        client.submit(noop, i, pure=False).result()
    return batch, (time.perf_counter() - start) / NOOP_ROUND_TRIPS


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--units", type=int, default=24, help="units in the simulated fleet (24)")
    parser.add_argument("--workers", default="1,2", help="LocalCluster sizes to compare (1,2)")
    args = parser.parse_args()
    sizes = [int(w) for w in args.workers.split(",")]

    from trainer.fleet.cluster import open_client
    from trainer.fleet.manifest import load_manifest
    from trainer.fleet.run import run_fleet
    from trainer.fleet.simulated import write_fleet

    print(f"machine: {machine()}")
    print(f"load average before: {load_average()} (other processes share these cores)")
    with tempfile.TemporaryDirectory(prefix="bench-fleet-") as tmp:
        root = Path(tmp)
        manifest = write_fleet(root, args.units)
        # load, diagnose, one per method, assemble
        tasks_per_unit = 3 + len(load_manifest(manifest).units[0].methods)
        rates: dict[int, float] = {}
        overhead: tuple[float, float] | None = None
        for size in sizes:
            started = time.perf_counter()
            with open_client(None, size) as client:
                client.run(warm)
                ready = time.perf_counter() - started
                cpu_before = client.run(time.process_time)
                start = time.perf_counter()
                run = run_fleet(manifest, root / f"out-{size}", progress=False, client=client)
                elapsed = time.perf_counter() - start
                cpu = sum(t - cpu_before[w] for w, t in client.run(time.process_time).items())
                assert len(run.computed) == args.units
                rates[size] = 60.0 * args.units / elapsed
                print(
                    f"{size} worker(s): {args.units} units in {elapsed:.1f} s = {rates[size]:.1f} units/min "
                    f"({elapsed / args.units:.2f} s per unit; cluster start and imports {ready:.1f} s, not counted); "
                    f"workers' CPU {cpu / args.units:.2f} s per unit, {100 * cpu / (elapsed * size):.0f} % of "
                    f"{size} core(s) while it ran"
                )
                if size == max(sizes):
                    overhead = scheduler_overhead(client)
        if len(sizes) > 1:
            low, high = min(sizes), max(sizes)
            print(f"throughput ratio {high} vs {low} worker(s): {rates[high] / rates[low]:.2f}")
        if overhead is not None:
            batch, trip = overhead
            per_unit = 60.0 / rates[max(sizes)]
            share = 100.0 * tasks_per_unit * batch / per_unit
            print(
                f"scheduler overhead per task ({max(sizes)} workers, no-op tasks): {1e3 * batch:.2f} ms in a "
                f"batch of {NOOP_BATCH}, {1e3 * trip:.2f} ms round trip; {tasks_per_unit} tasks per unit = "
                f"{share:.2f} % of a unit's wall time"
            )
    print(f"load average after: {load_average()}")


if __name__ == "__main__":
    main()
