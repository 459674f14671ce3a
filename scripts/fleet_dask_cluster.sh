#!/usr/bin/env bash
# `trainer fleet` on a separately started Dask cluster: a `dask scheduler` and two `dask worker`
# processes on this machine, then the same manifest on the embedded LocalCluster; the two result
# trees must be identical (every unit file except timing.json, the report, fleet.json).
#
# Usage: scripts/fleet_dask_cluster.sh [WORKDIR]     (default: a new temporary directory)
#   FLEET_UNITS=N  units of the simulated fleet (default 12)
# The processes it starts are stopped on exit. See docs/fleet.md, "A Dask cluster".
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
WORK=${1:-$(mktemp -d -t fleet-cluster.XXXXXX)}
UNITS=${FLEET_UNITS:-12}
BIN=$ROOT/.venv/bin
# Every process (scheduler, workers, client) imports the same code from the same checkout.
export PYTHONPATH=$ROOT${PYTHONPATH:+:$PYTHONPATH}
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MPLBACKEND=Agg
mkdir -p "$WORK"
WORK=$(cd "$WORK" && pwd)

PIDS=()
stop() { for pid in "${PIDS[@]}"; do kill "$pid" 2>/dev/null || true; done; wait 2>/dev/null || true; }
trap stop EXIT

"$BIN/python" - "$WORK" "$UNITS" <<'EOF'
import sys
from pathlib import Path

from trainer.fleet.simulated import write_fleet

print(f"simulated fleet: {write_fleet(Path(sys.argv[1]), int(sys.argv[2]))}")
EOF

rm -f "$WORK/scheduler.json"
"$BIN/dask" scheduler --scheduler-file "$WORK/scheduler.json" --port 0 --no-dashboard \
    >"$WORK/scheduler.log" 2>&1 &
PIDS+=($!)
for _ in $(seq 100); do [ -s "$WORK/scheduler.json" ] && break; sleep 0.2; done
[ -s "$WORK/scheduler.json" ] || { echo "error: the scheduler did not start (see $WORK/scheduler.log)" >&2; exit 1; }
for i in 1 2; do
    "$BIN/dask" worker --scheduler-file "$WORK/scheduler.json" --nworkers 1 --nthreads 1 --no-dashboard \
        --name "fleet-worker-$i" --local-directory "$WORK/worker-$i" >"$WORK/worker-$i.log" 2>&1 &
    PIDS+=($!)
done
ADDRESS=$("$BIN/python" - "$WORK/scheduler.json" <<'EOF'
import json
import sys

from distributed import Client

address = json.load(open(sys.argv[1]))["address"]
with Client(address, timeout=30) as client:
    client.wait_for_workers(2, timeout=120)
print(address)
EOF
)
echo "cluster: scheduler $ADDRESS, 2 workers"

"$BIN/python" -m trainer.cli fleet "$WORK/fleet.toml" -o "$WORK/out-cluster" --scheduler "$ADDRESS" --quiet
"$BIN/python" -m trainer.cli fleet "$WORK/fleet.toml" -o "$WORK/out-local" --workers 2 --quiet

diff -r --exclude=timing.json "$WORK/out-local/units" "$WORK/out-cluster/units"
cmp "$WORK/out-local/report.md" "$WORK/out-cluster/report.md"
cmp "$WORK/out-local/fleet.json" "$WORK/out-cluster/fleet.json"
echo "identical: $UNITS units on the separate cluster and on the LocalCluster (results in $WORK)"
