"""``trainer fleet`` end to end: key every unit, skip the finished ones, run the rest, report.

Units are submitted as Dask graphs (:mod:`.stages`) and written as each one finishes, so an
interrupted run keeps every unit it finished; the report is rebuilt at the end from the results on
disk of every unit in the manifest (computed now or by an earlier run).
"""

from __future__ import annotations

import uuid
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, TypeVar

from trainer.errors import UserError
from trainer.fleet import stages
from trainer.fleet.cache import (
    UNITS_DIR,
    clean_staging,
    is_done,
    publish_unit,
    read_result,
    unit_key,
)
from trainer.fleet.manifest import FleetSettings, Manifest, UnitSpec, load_manifest
from trainer.fleet.result import RESULT_FILE, Failure, UnitResult

T = TypeVar("T")


@dataclass
class FleetRun:
    """What one invocation did: units computed now, units skipped (already done), the report."""

    manifest: Manifest
    out_dir: Path
    computed: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    results: dict[str, UnitResult] = field(default_factory=dict)
    report: Path | None = None


def _submit(
    client: Any, unit: UnitSpec, key: str, settings: FleetSettings, sim_text: str | None, run_tag: str
) -> Any:
    """The unit's graph; only the ``assemble`` future is kept (Dask keeps what it needs).

    Task keys carry ``run_tag``, one per run: a scheduler that outlives a run (``--scheduler``, a
    test's client) would otherwise hand a rerun the previous run's result for the same key, a failed
    export included, until it has processed the release of the old futures."""
    tag = f"{unit.id}-{key[:12]}-{run_tag}"
    data = client.submit(stages.load, unit, settings, key=f"load-{tag}")
    diagnosis = client.submit(stages.diagnose, data, settings, sim_text, key=f"diagnose-{tag}")
    outputs = [client.submit(stages.method, data, unit, m, key=f"method-{m}-{tag}") for m in unit.methods]
    return client.submit(stages.assemble, unit, key, data, diagnosis, *outputs, key=f"assemble-{tag}")


def _failed(unit: UnitSpec, key: str | None, stage: str, exc: BaseException) -> stages.UnitOutcome:
    """A unit that never reached ``assemble`` (unreadable input, lost worker): its result only."""
    message, retry = stages.one_line(exc)
    retry = retry or key is None  # no key: an unreadable recording, read again next run
    result = UnitResult.failed(unit, key, Failure(stage, message, retry))
    return stages.UnitOutcome(unit.id, {RESULT_FILE: result.to_json()}, result)


def _written(what: Path, write: Callable[[], T]) -> T:
    """Run a client-side write; a failed one (a full disk, a read-only OUTDIR) is one line naming the
    path. Units already written stay whole and a restart computes the rest (none is cached as done)."""
    try:
        return write()
    except OSError as exc:
        where = exc.filename or what
        raise UserError(
            f"{where}: cannot write ({exc.strerror or exc}); the units finished so far are kept, run the same "
            "command again when it is fixed"
        ) from None


def run_fleet(
    manifest_path: str | Path,
    out_dir: str | Path,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool = True,
    client: Any | None = None,
) -> FleetRun:
    """Run every unit of the manifest not already done in ``out_dir``, then write the report.

    ``client``: a ``distributed.Client`` to use instead of opening one (``scheduler`` and
    ``workers`` are then ignored); a caller running several fleets keeps one cluster up.
    """
    from trainer.fleet.report import remove_stale_report_parts, write_report
    from trainer.physics.config import parse_config_text
    from trainer.progress import progress_bar

    manifest = load_manifest(manifest_path)
    settings = manifest.settings
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise UserError(f"-o {out}: exists and is not a directory")
    if not (out.parent if str(out.parent) else Path(".")).is_dir():
        raise UserError(f"-o {out}: parent directory {out.parent} does not exist")
    sim_text = None
    if settings.sim is not None:
        sim_text = settings.sim.read_text(encoding="utf-8")
        parse_config_text(sim_text, str(settings.sim))  # a bad simulation fails the run before any work
    from trainer.fleet.cluster import open_client

    # one connection per run: the cluster named is checked before any work (a bad address was ignored
    # when no unit reached it) and then runs the units
    with ExitStack() as cluster:
        if scheduler is not None and client is None:
            client = cluster.enter_context(open_client(scheduler, workers))
        remove_stale_report_parts(out)
        # OUTDIR itself is created by the first result: a run that cannot start leaves none
        clean_staging(out)
        run = FleetRun(manifest, out)

        todo: list[tuple[UnitSpec, str]] = []
        for unit in manifest.units:
            try:
                key = unit_key(unit, settings)
            except UserError as exc:  # a missing or unreadable recording: this unit fails, the fleet goes on
                files = _failed(unit, None, "load", exc).files
                _written(out / UNITS_DIR, partial(publish_unit, out, unit.id, files))
                run.computed.append(unit.id)
                continue
            if is_done(out, unit.id, key):
                run.skipped.append(unit.id)
            else:
                todo.append((unit, key))

        if todo:
            from distributed import as_completed

            active = client if client is not None else cluster.enter_context(open_client(scheduler, workers))
            run_tag = uuid.uuid4().hex[:8]
            futures = {
                _submit(active, unit, key, settings, sim_text, run_tag): (unit, key) for unit, key in todo
            }
            bar = progress_bar(progress=progress, total=len(futures), unit="unit", desc="fleet")
            for future in as_completed(futures):
                unit, key = futures[future]
                try:
                    outcome = future.result()
                except Exception as exc:  # the task itself was lost (e.g. its worker died)
                    outcome = _failed(unit, key, "cluster", exc)
                _written(out / UNITS_DIR, partial(publish_unit, out, unit.id, outcome.files))
                run.computed.append(unit.id)
                bar.update()
            bar.close()

    for unit in manifest.units:
        result = read_result(out, unit.id)
        if result is not None:
            run.results[unit.id] = result
    _written(out, lambda: out.mkdir(exist_ok=True))
    run.report = _written(out, lambda: write_report(manifest, out, run.results))
    return run
