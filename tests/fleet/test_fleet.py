"""``trainer fleet``: a simulated batch on a 2-worker LocalCluster, a bad file, a restart, the manifest.

The batch (``trainer.fleet.simulated``): 24 short units around one sensor with unit-to-unit spread,
U07 with a bias step and U18 with a tripled thermal lag; a 25th unit whose recording is corrupt.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import tomli_w

from tests.repo import REPO_ROOT
from trainer.checkpoint import load_model
from trainer.cli import main
from trainer.data.recording_io import read_recording
from trainer.errors import UserError, run_cli
from trainer.fleet.cache import unit_key
from trainer.fleet.cluster import open_client
from trainer.fleet.manifest import load_manifest
from trainer.fleet.outliers import Z_LIMIT, Finding, find_out_of_family
from trainer.fleet.result import UnitResult
from trainer.fleet.run import FleetRun, run_fleet
from trainer.fleet.simulated import DEFAULT_DEFECTS, write_fleet
from trainer.reference import value_at_temperature

N_UNITS = 24
BAD = "BAD01"
ROOT = REPO_ROOT


def _files(out: Path) -> dict[str, tuple[int, bytes]]:
    """Every unit file (relative path -> mtime_ns, content)."""
    units = out / "units"
    return {
        str(p.relative_to(units)): (p.stat().st_mtime_ns, p.read_bytes())
        for p in units.rglob("*")
        if p.is_file()
    }


@pytest.fixture(scope="module")
def client() -> Iterator[Any]:
    """One 2-worker LocalCluster for the module (starting one costs seconds)."""
    with open_client(None, 2) as active:
        yield active


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory, client: Any) -> tuple[Path, FleetRun]:
    root = tmp_path_factory.mktemp("fleet")
    manifest = write_fleet(root, N_UNITS)
    good = read_recording(root / "runs" / "U01_run1.npz")
    lines = ["time_s,temp_c,accel_mg"] + [
        f"{t:g},{c:.4f},{a:.5f}"
        for t, c, a in zip(good.time_s[:50], good.temp_c, good.accel_mg, strict=False)
    ]
    lines[13] = lines[13].rsplit(",", 1)[0] + ",0.1x5"  # a corrupt cell on data row 12 (file line 13)
    (root / "runs" / f"{BAD}_run1.csv").write_text("\n".join(lines) + "\n")
    data = load_toml(manifest)
    data["unit"].append({"id": BAD, "recordings": [f"runs/{BAD}_run1.csv", "runs/U01_run2.npz"]})
    manifest.write_text(tomli_w.dumps(data))
    return manifest, run_fleet(manifest, root / "out", progress=False, client=client)


def load_toml(path: Path) -> dict:
    import tomllib

    return tomllib.loads(path.read_text())


def test_every_unit_processed_and_verified(fleet: tuple[Path, FleetRun]) -> None:
    _manifest, run = fleet
    ids = [f"U{i:02d}" for i in range(1, N_UNITS + 1)]
    assert sorted(run.computed) == sorted([*ids, BAD]) and run.skipped == []
    for uid in ids:
        result = run.results[uid]
        assert result.status == "ok", result.errors
        unit = run.out_dir / "units" / uid
        for method in ("poly3", "pla"):
            verify = json.loads((unit / method / "verify.json").read_text())
            assert verify["passed"] and verify["mismatches"] == 0 and verify["samples"] == 9900
            # the C module was generated from this very model.pt (its stamped hash), which loads safely
            c_manifest = json.loads((unit / method / "c" / f"tdc_{uid}.manifest.json").read_text())
            assert (
                c_manifest["model"]["sha256"]
                == hashlib.sha256((unit / method / "model.pt").read_bytes()).hexdigest()
            )
            model, checkpoint = load_model(unit / method / "model.pt")
            assert checkpoint["method"] == method
            # simulated data: the residual against the truth is kept too, under its own name, as
            # trainer evaluate scores it: the model's drift is relative to its T_ref, so is the truth
            # (scored absolute, it reversed the ranking of the two methods against evaluate's)
            valid = read_recording(Path(result.recordings[1]))
            true = valid.columns["true_drift_mg"]
            assert model.offset is not None and model.offset.relative
            true = true - value_at_temperature(valid.temp_c, true, model.offset.t_ref_c)
            residual = true - model.predict_drift(valid.without_truth())
            scores = json.loads((unit / method / "scores.json").read_text())
            truth = float(np.sqrt(np.mean(residual**2)))
            assert scores["residual_vs_truth_mg"] == pytest.approx(truth, rel=1e-9)
        diagnosis = json.loads((unit / "diagnosis.json").read_text())
        assert "thermal_lag" in [e["effect"] for e in diagnosis["left_out"]]
    report = (run.out_dir / "report.md").read_text()
    for figure in ("drift_left.png", "parameters.png", "effects.png"):
        assert (run.out_dir / "figures" / figure).stat().st_size > 1000 and f"figures/{figure}" in report


def _report_rows(model: Path, recording: Path, out: Path, *holdout: str) -> dict[str, list[float]]:
    """``trainer report``'s drift-left table: row label -> RMS, max, uncompensated RMS, max."""
    args = ["report", str(model), "--recording", str(recording), "-o", str(out), *holdout]
    assert run_cli(main, args) in (0, 1)
    rows = {}
    for line in (out / "report.md").read_text().splitlines():
        cells = [c.strip() for c in line.strip("|").split("|")]
        if len(cells) == 6 and cells[1].isdigit():
            rows[cells[0]] = [float(c) if c != "n/a" else math.nan for c in cells[2:]]
    return rows


def _same(fleet_value: float, report_cell: float) -> bool:
    """The report prints 4 significant digits."""
    return report_cell == pytest.approx(fleet_value, rel=6e-4, abs=1e-12)


def test_fleet_drift_left_is_the_report_s(fleet: tuple[Path, FleetRun], tmp_path: Path) -> None:
    """A unit with a second run: the fleet's figures are `trainer report`'s on that run."""
    _, run = fleet
    for uid in ("U01", "U07"):
        result = run.results[uid]
        for method in ("poly3", "pla"):
            summary = result.methods[method]
            rows = _report_rows(
                run.out_dir / "units" / uid / method / "model.pt",
                Path(result.recordings[1]),
                tmp_path / f"{uid}-{method}",
            )
            assert _same(summary["drift_left_mg"], rows["all"][0]), (summary, rows)
            assert _same(summary["drift_left_uncompensated_mg"], rows["all"][2]), (summary, rows)


def test_the_fleet_verify_json_is_what_report_verify_reads(
    fleet: tuple[Path, FleetRun], tmp_path: Path
) -> None:
    """A unit's ``verify.json`` is ``codegen verify --json``'s document: ``trainer report --verify`` takes
    it for the unit's model (it checks the model id) and prints the fleet's sample count and mismatches."""
    _, run = fleet
    result = run.results["U01"]
    unit = run.out_dir / "units" / "U01" / "poly3"
    verified = json.loads((unit / "verify.json").read_text())
    args = ["report", str(unit / "model.pt"), "--recording", str(result.recordings[1]), "--verify"]
    assert run_cli(main, [*args, str(unit / "verify.json"), "-o", str(tmp_path / "r")]) in (0, 1)
    text = (tmp_path / "r" / "report.md").read_text()
    assert verified["mismatches"] == 0 and f"{verified['samples']} samples" in text and "0 mismatches" in text


def test_fleet_holdout_is_the_report_s(fleet: tuple[Path, FleetRun], client: Any, tmp_path: Path) -> None:
    """A unit with one run and `holdout = "first:0.3"`: the fleet fits and scores exactly what
    `trainer report --holdout first:0.3` scores (the same parser, split and scoring)."""
    manifest, _ = fleet
    run1 = manifest.parent / "runs" / "U02_run1.npz"
    (tmp_path / "m.toml").write_text(
        f'[fleet]\nmethods = ["poly3"]\nholdout = "first:0.3"\ndiagnose_blocks = 120\n'
        f'[[unit]]\nid = "H1"\nrecordings = ["{run1}"]\n'
    )
    done = run_fleet(tmp_path / "m.toml", tmp_path / "out", progress=False, client=client)
    result = done.results["H1"]
    assert result.status == "ok", result.errors
    summary = result.methods["poly3"]
    model = tmp_path / "out" / "units" / "H1" / "poly3" / "model.pt"
    _, checkpoint = load_model(model)
    first = read_recording(run1)
    assert checkpoint["train_stats"]["n_samples"] == len(first) - round(
        0.3 * len(first)
    )  # trained on the rest
    rows = _report_rows(model, run1, tmp_path / "report", "--holdout", "first:0.3")
    assert _same(summary["drift_left_mg"], rows["held-out all"][0]), (summary, rows)
    assert _same(summary["drift_left_uncompensated_mg"], rows["held-out all"][2]), (summary, rows)
    assert summary["drift_left_mg"] != pytest.approx(rows["all"][0], rel=1e-3)  # not the whole run's


def test_a_method_worse_than_uncompensated_fails_its_unit() -> None:
    """The fleet's verdict is the report's: the guard fails a model that leaves more drift."""
    from trainer.fleet.report import unit_verdict

    def result(model_mg: float, raw_mg: float = 2.0) -> UnitResult:
        figures = {"drift_left_mg": model_mg, "drift_left_uncompensated_mg": raw_mg, "noise_floor_mg": 0.1}
        methods = {"poly3": {**figures, "verify": {"passed": True}}}
        return UnitResult.from_dict({"id": "A", "status": "ok", "errors": [], "methods": methods})

    assert unit_verdict("A", result(1.5), []).status == "PASS"
    assert unit_verdict("A", result(1.5), [Finding("A", "x", "odd")]).status == "REVIEW"
    worse = unit_verdict("A", result(2.5), [])
    assert worse.status == "FAIL" and "worse than uncompensated" in worse.line()
    # both at the noise floor: "worse" by noise is not worse
    assert unit_verdict("A", result(0.11, 0.1), []).status == "PASS"
    assert unit_verdict("A", result(0.5, 0.1), []).status == "FAIL"


def test_a_method_that_carries_an_undetermined_parameter_asks_for_a_review() -> None:
    """The fleet's verdict reads what a model carries as ``trainer report`` does: a parameter its run
    does not determine turns PASS into REVIEW, with the same reason."""
    from trainer.fleet.report import unit_verdict
    from trainer.scoring.verdict import undetermined_reason

    flagged = ["thermal_lag.tau_s sits at the end of its search range"]
    figures = {"drift_left_mg": 1.5, "drift_left_uncompensated_mg": 2.0, "noise_floor_mg": 0.1}
    methods = {"physics": {**figures, "verify": {"passed": True}, "undetermined": flagged}}
    result = UnitResult.from_dict({"id": "A", "status": "ok", "errors": [], "methods": methods})
    decided = unit_verdict("A", result, [])
    assert decided.status == "REVIEW"
    assert (
        list(decided.review) == [undetermined_reason("A / physics", flagged)] and flagged[0] in decided.line()
    )


def test_flagged_units_are_exactly_the_planted_ones(fleet: tuple[Path, FleetRun]) -> None:
    _, run = fleet
    summary = json.loads((run.out_dir / "fleet.json").read_text())
    review = {u["id"]: u["out_of_family"] for u in summary["units"] if u["sign_off"] == "REVIEW"}
    assert set(review) == set(DEFAULT_DEFECTS)  # U07 bias step, U18 tripled lag
    assert any("bias_step" in reason for reason in review["U07"])
    assert any(reason.startswith("thermal_lag.tau_s") for reason in review["U18"])
    # the tripled lag is fitted near three times the fleet's median lag
    taus = [
        e["params"]["tau_s"]
        for uid, r in run.results.items()
        if r.status == "ok"
        for e in r.diagnosis["left_out"]
        if e["effect"] == "thermal_lag"
    ]
    lag_u18 = next(e for e in run.results["U18"].diagnosis["left_out"] if e["effect"] == "thermal_lag")
    assert lag_u18["params"]["tau_s"] / float(np.median(taus)) == pytest.approx(3.0, rel=0.25)


def test_a_bias_step_is_not_read_as_another_temperature_coefficient(fleet: tuple[Path, FleetRun]) -> None:
    """The step unit's polynomial is compared as the final model fitted it beside the step: calibrated
    alone, the polynomial bends to hold the step (tests/diagnose/test_baseline_final.py) and a unit was
    flagged for c0..c3 as well."""
    _, run = fleet
    summary = json.loads((run.out_dir / "fleet.json").read_text())
    reasons = next(u["out_of_family"] for u in summary["units"] if u["id"] == "U07")
    assert reasons and not [r for r in reasons if r.startswith("bias_poly.")], reasons


def test_bad_file_is_one_line_in_its_unit_and_the_fleet_goes_on(fleet: tuple[Path, FleetRun]) -> None:
    _, run = fleet
    result = run.results[BAD]
    assert result.status == "failed" and not result.retry
    assert len(result.errors) == 1, result.errors
    (error,) = result.errors
    assert error.stage == "load"
    assert f"{BAD}_run1.csv" in error.error and "\n" not in error.error and "accel_mg" in error.error
    assert not (run.out_dir / "units" / BAD / "poly3").exists()
    summary = json.loads((run.out_dir / "fleet.json").read_text())
    verdicts = {u["id"]: u["sign_off"] for u in summary["units"]}
    assert verdicts[BAD] == "FAIL" and list(verdicts.values()).count("FAIL") == 1
    assert f"- **{BAD}** (load): {error.error}" in (run.out_dir / "report.md").read_text()


def test_a_run_too_flat_for_its_methods_fails_at_load_as_trainer_fit_refuses_it(
    tmp_path: Path, client: Any, capsys: pytest.CaptureFixture[str]
) -> None:
    """A unit whose chamber did not run (0.2 degC) is refused as ``trainer fit`` refuses the same file,
    before its diagnosis fits a cubic to noise, and nothing of it is exported; the others go on."""
    from trainer.data.recording import Recording
    from trainer.data.recording_io import write_recording

    manifest = write_fleet(tmp_path, 1, defects={})
    run1 = read_recording(tmp_path / "runs" / "U01_run1.npz")
    flat_temp = 25.0 + 0.1 * np.sin(np.linspace(0.0, 6.0, len(run1)))
    flat = Recording({**run1.columns, "temp_c": flat_temp}, dict(run1.meta), run1.source)
    flat_path = tmp_path / "runs" / "FLAT_run1.npz"
    write_recording(flat.without_truth(), flat_path)
    data = load_toml(manifest)
    data["unit"].append({"id": "FLAT", "recordings": ["runs/FLAT_run1.npz", "runs/U01_run2.npz"]})
    manifest.write_text(tomli_w.dumps(data))
    run = run_fleet(manifest, tmp_path / "out", progress=False, client=client)

    assert run.results["U01"].status == "ok"
    result = run.results["FLAT"]
    assert result.status == "failed" and not result.retry
    (error,) = result.errors
    assert error.stage == "load" and "\n" not in error.error
    assert not (run.out_dir / "units" / "FLAT" / "poly3").exists()
    assert run_cli(main, ["fit", "--method", "poly3", str(flat_path), "-o", str(tmp_path / "m.pt")]) == 2
    refusal = capsys.readouterr().err.strip().removeprefix("error: ")
    assert "temperature spans" in refusal and refusal in error.error
    assert not (tmp_path / "m.pt").exists()


def test_restart_skips_finished_units(
    fleet: tuple[Path, FleetRun], capsys: pytest.CaptureFixture[str]
) -> None:
    manifest, run = fleet
    before = _files(run.out_dir)
    assert run_cli(main, ["fleet", str(manifest), "-o", str(run.out_dir), "--quiet"]) == 1  # 1: BAD01 failed
    assert f"({0} computed, {N_UNITS + 1} already done)" in capsys.readouterr().out
    assert _files(run.out_dir) == before  # nothing rewritten, nothing recomputed


def test_interrupted_unit_is_computed_again_alone(fleet: tuple[Path, FleetRun], client: Any) -> None:
    manifest, run = fleet
    before = _files(run.out_dir)
    # killed while U03 was running: no U03 directory, a staging directory left behind
    shutil.rmtree(run.out_dir / "units" / "U03")
    (run.out_dir / "units" / ".U03.x.part").mkdir()
    again = run_fleet(manifest, run.out_dir, progress=False, client=client)
    assert again.computed == ["U03"] and len(again.skipped) == N_UNITS
    after = _files(run.out_dir)
    assert after.keys() == before.keys() and not (run.out_dir / "units" / ".U03.x.part").exists()
    for path, (mtime, content) in before.items():
        if path.startswith("U03/"):  # recomputed, and byte-identical apart from its wall times
            assert path == "U03/timing.json" or after[path][1] == content, path
        else:  # untouched
            assert after[path] == (mtime, content), path


def test_changed_input_changes_the_key(fleet: tuple[Path, FleetRun], tmp_path: Path) -> None:
    manifest, _ = fleet
    units = {u.id: u for u in load_manifest(manifest).units}
    settings = load_manifest(manifest).settings
    key = unit_key(units["U01"], settings)
    copy = tmp_path / "U01_run1.npz"
    shutil.copy(units["U01"].recordings[0], copy)
    moved = type(units["U01"])(**{**units["U01"].__dict__, "recordings": (copy, units["U01"].recordings[1])})
    assert unit_key(moved, settings) == key  # the content counts, not the path
    with open(copy, "ab") as handle:
        handle.write(b"\0")
    assert unit_key(moved, settings) != key
    other = type(settings)(**{**settings.__dict__, "method_options": {"pla": "--intervals 12"}})
    assert unit_key(units["U01"], other) != key


# ------------------------------------------------------------------------------- manifest


def test_csv_manifest_with_import_options(tmp_path: Path) -> None:
    (tmp_path / "a.tsv").write_text("t\tT\tacc\n0\t20\t1\n")
    (tmp_path / "fleet.csv").write_text(
        "# production batch 7\n"
        "id,recordings,methods,export_name,import\n"
        "SN-1,a.tsv;b.npz,poly3,,--time t --temp T --accel acc --accel-unit g\n"
        "SN-2,c.npz,,tdc_two,\n"
    )
    manifest = load_manifest(tmp_path / "fleet.csv")
    one, two = manifest.units
    assert one.recordings == (tmp_path / "a.tsv", tmp_path / "b.npz") and one.methods == ("poly3",)
    assert one.export_name == "tdc_SN_1" and one.importer is not None
    assert one.importer.text_options().accel_unit == "g" and one.importer.text_options().temp == "T"
    assert set(two.methods) == {"pla", "poly3"} and two.export_name == "tdc_two" and two.import_text == ""


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('[[unit]]\nid = "A"\nrecordings = ["a.npz"]\nmethods = ["poly4"]\n', "unknown method 'poly4'"),
        ('[[unit]]\nid = "a/b"\nrecordings = ["a.npz"]\n', "id must be"),
        ('[[unit]]\nid = "A"\n', "recordings is missing"),
        (
            '[[unit]]\nid = "A"\nrecordings = ["a.npz"]\n[[unit]]\nid = "A"\nrecordings = ["b.npz"]\n',
            "appears twice",
        ),
        (
            '[fleet]\nmethod_options = { pla = "--intervalz 3" }\n[[unit]]\nid = "A"\nrecordings = ["a.npz"]\n',
            "--intervalz",
        ),
        (
            '[fleet]\neval_fraction = 0.3\n[[unit]]\nid = "A"\nrecordings = ["a.npz"]\n',
            'holdout = "last:F"',
        ),
        (
            '[fleet]\nholdout = "middle:0.3"\n[[unit]]\nid = "A"\nrecordings = ["a.npz"]\n',
            "holdout: --holdout 'middle:0.3'",
        ),
        ('[[unit]]\nid = "A"\nrecordings = ["a.npz"]\nexport_name = "2x"\n', "export_name"),
        ('[[unit]]\nid = "A"\nrecordings = ["a.npz"]\ncolour = "red"\n', "unknown key 'colour'"),
    ],
)
def test_bad_manifest_is_one_line(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "m.toml"
    path.write_text(text)
    with pytest.raises(UserError, match=None) as info:
        load_manifest(path)
    assert message in str(info.value) and str(path) in str(info.value) and "\n" not in str(info.value)


def test_method_list_comes_from_the_registry(tmp_path: Path) -> None:
    """A method registered later (e.g. the physics method) is accepted with no change here."""
    from trainer import methods
    from trainer.baselines.poly3 import CubicPolynomial

    class Later(CubicPolynomial):
        pass

    methods.register(methods.Method("later-method", Later, methods.MEMORYLESS))
    try:
        (tmp_path / "m.toml").write_text(
            '[fleet]\nmethods = ["later-method"]\n[[unit]]\nid = "A"\nrecordings = ["a.npz"]\n'
        )
        assert load_manifest(tmp_path / "m.toml").units[0].methods == ("later-method",)
    finally:
        methods.unregister("later-method")


def test_robust_z_flags_only_the_outlier() -> None:
    rng = np.random.default_rng(3)
    c1_mg_per_c = rng.normal(0.12, 0.01, 20)
    c1_mg_per_c[7] = 0.12 + 2 * Z_LIMIT * 0.01
    results = {
        f"u{i}": UnitResult.from_dict(
            {
                "id": f"u{i}",
                "status": "ok",
                "diagnosis": {
                    "baseline_calibrated": {"bias_poly": {"c1_mg_per_c": float(v)}},
                    "left_out": [],
                },
            }
        )
        for i, v in enumerate(c1_mg_per_c)
    }
    findings = find_out_of_family(results)
    assert [(f.unit, f.feature) for f in findings] == [("u7", "bias_poly.c1_mg_per_c")]


# ---------------------------------------------------------------------- a separate Dask cluster


@pytest.mark.slow
def test_separate_dask_cluster_gives_identical_results(tmp_path: Path) -> None:
    """``scripts/fleet_dask_cluster.sh``: dask scheduler + 2 dask workers, compared with a LocalCluster."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), FLEET_UNITS="10")
    done = subprocess.run(
        ["bash", str(ROOT / "scripts" / "fleet_dask_cluster.sh"), str(tmp_path)],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert "identical" in done.stdout
    local, remote = tmp_path / "out-local" / "units", tmp_path / "out-cluster" / "units"
    names = sorted(str(p.relative_to(local)) for p in local.rglob("*") if p.is_file())
    assert names == sorted(str(p.relative_to(remote)) for p in remote.rglob("*") if p.is_file())
    for name in names:
        if not name.endswith("timing.json"):
            assert (local / name).read_bytes() == (remote / name).read_bytes(), name


def test_a_scheduler_that_is_not_an_address_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    manifest = write_fleet(tmp_path, 1, defects={})
    argv = ["fleet", str(manifest), "-o", str(tmp_path / "out"), "--scheduler", "notaurl", "--quiet"]
    assert run_cli(main, argv) == 2
    err = capsys.readouterr().err
    assert "--scheduler 'notaurl': not a scheduler address" in err and err.count("\n") == 1
    assert not (tmp_path / "out").exists()
