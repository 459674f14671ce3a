"""The spread schedule (``codegen export --schedule spread``): the network step split into tasks over
the samples of the decimation period. The C equals its own golden schedule (which replays the task
split) sample for sample and state for state, also when a stream is cut or reset mid-period and
under the sanitizers; and the drift it removes is the "step" schedule's, delayed by exactly the
documented latency of D - 1 samples (so the drift left is unchanged up to that delay)."""

from __future__ import annotations

import itertools
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from codegen import cortex_m as cm
from codegen.export import export
from codegen.families.stream.quantise import QStream
from codegen.golden_select import golden_for
from codegen.hostbuild import (
    CMD_INIT,
    CMD_RESET,
    build_harness,
    load_module,
    run_harness,
    write_vectors,
)
from codegen.render import render_template
from tests import refvectors as ref
from tests.golden_checks import assert_states_equal, replay
from tests.repo import REPO_ROOT

ROOT = REPO_ROOT
NETWORKS = ("dlstm", "dlstm-temp")  # the frozen 2x10 recursive and 2x4 temperature networks (D = 10)


@pytest.mark.parametrize("method", NETWORKS)
def test_c_equals_its_golden_schedule_cut_mid_period(method: str, tmp_path: Path) -> None:
    model, _ = export(ref.REF_DIR / f"{method}.pt", tmp_path / "out", name="spr", schedule="spread")
    q = model.quantised
    assert isinstance(q, QStream) and q.tasks > q.frontend.decimation  # several tasks on some samples
    accel, temp = ref.load_stream()
    host = load_module(tmp_path / "out", "spr", flags=("-O1",))
    state, golden = host.new_state(), golden_for(q)
    for a, b in itertools.pairwise([0, 3, 1_777, 2_003, 2_004, accel.size]):  # cuts at several phases
        np.testing.assert_array_equal(
            host.run(state, accel[a:b], temp[a:b]), golden.run(accel[a:b], temp[a:b])
        )
        assert_states_equal(host.read_state(state), golden.state())


@pytest.mark.parametrize("method", NETWORKS)
def test_drift_is_the_step_schedules_delayed_by_the_latency(method: str, tmp_path: Path) -> None:
    """On a stream whose outputs do not saturate: drift_spread[n] = drift_step[n - (D - 1)], and no
    drift is removed before the first estimate takes effect."""
    spread, _ = export(ref.REF_DIR / f"{method}.pt", tmp_path / "s", name="spr", schedule="spread")
    step, _ = export(ref.REF_DIR / f"{method}.pt", tmp_path / "t", name="stp")
    q = spread.quantised
    assert isinstance(q, QStream)
    lat = q.latency_samples
    assert lat == q.frontend.decimation - 1 > 0
    accel, temp = (v[:2_400] for v in ref.load_stream())  # before the full-scale bursts
    drift_step = accel - golden_for(step.quantised).run(accel, temp)
    drift_spread = accel - golden_for(q).run(accel, temp)
    assert np.count_nonzero(drift_step) > accel.size // 2  # the model removes a drift
    np.testing.assert_array_equal(drift_spread[lat:], drift_step[:-lat])
    assert not np.any(drift_spread[:lat])


def test_under_address_and_undefined_behaviour_sanitizers(tmp_path: Path) -> None:
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed (scripts/install_c_tools.sh)")
    model, _ = export(ref.REF_DIR / "dlstm.pt", tmp_path / "out", name="san", schedule="spread")
    accel, temp = ref.load_stream()  # with bursts at the input limits
    commands = np.zeros(accel.size, dtype=np.int64)
    commands[[1_003, 2_222]] = CMD_RESET  # mid-period
    commands[2_601] = CMD_INIT
    write_vectors(tmp_path / "vectors.bin", accel, temp, commands)
    source = render_template("harness_vectors.c.j2", model.quantised, "san", model.sha256)
    binary = build_harness(tmp_path / "out", "san", source, tmp_path / "harness", cc="gcc")
    state_bytes = run_harness(binary, tmp_path / "vectors.bin", tmp_path / "outputs.bin")
    c_out = np.frombuffer((tmp_path / "outputs.bin").read_bytes(), dtype="<i4")
    golden = golden_for(model.quantised)
    np.testing.assert_array_equal(c_out, replay(golden, accel, temp, commands))
    host = load_module(tmp_path / "out", "san", flags=("-O0",))
    assert_states_equal(host.state_from_bytes(state_bytes), golden.state())


def _codegen(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "codegen.cli", *args], cwd=ROOT, capture_output=True, text=True, check=False
    )


def test_cli_export_manifest_and_verify(tmp_path: Path) -> None:
    out = tmp_path / "out"
    done = _codegen("export", str(ref.REF_DIR / "dlstm.pt"), "-o", str(out), "--schedule", "spread")
    assert done.returncode == 0, done.stderr
    manifest = json.loads((out / "tdc_dlstm.manifest.json").read_text())
    assert manifest["schedule"] == {
        "name": "spread",
        "tasks_per_step": 1 + 4 * 2 * 10 + 1,  # the input, 4 per unit of the 2x10 network, the head
        "latency_samples": 9,
        "latency_s": 9 / 200,
    }
    recording = tmp_path / "rec.npz"
    from trainer.cli import main as trainer_main

    assert trainer_main(["simulate", "--seed", "4", "--duration", "20", "-o", str(recording)]) == 0
    checked = _codegen("verify", str(ref.REF_DIR / "dlstm.pt"), str(out), str(recording), "--no-table")
    assert checked.returncode == 0, checked.stdout + checked.stderr
    assert "mismatches: 0" in checked.stdout and "final state identical: yes" in checked.stdout
    assert (
        "schedule spread: the estimate takes effect 9 samples (0.045 s) later; drift removed = the step "
        "schedule's delayed by 9 samples on every sample: yes" in checked.stdout
    )
    # the error budget is the arithmetic's (measured on the step schedule's output), not the delay's
    rms, worst = (
        float(v) for v in re.search(r"error budget .*?RMS (\S+) mg, max (\S+) mg", checked.stdout).groups()
    )
    assert rms <= 1e-3 and worst <= 5e-3
    # the sign-off report states the schedule and the module's drift left under both schedules
    assert trainer_main(["report", str(ref.REF_DIR / "dlstm.pt"), "--recording", str(recording), "--verify",
                         str(out), "-o", str(tmp_path / "signoff")]) in (0, 1)  # fmt: skip
    text = (tmp_path / "signoff" / "report.md").read_text()
    line = next(row for row in text.splitlines() if row.startswith("- schedule `spread`"))
    assert "9 samples later than with `step`" in line and "every sample: yes" in line
    step_rms, spread_rms = (float(v) for v in re.findall(r"(?:step|spread) ([0-9.]+) mg RMS", line))
    # the same estimates, 9 of 4,000 samples later: the same drift left within 5 %
    assert abs(spread_rms - step_rms) <= 0.05 * step_rms


def test_report_reads_the_schedule_of_a_verify_json_and_refuses_a_bad_one(tmp_path: Path) -> None:
    out, recording, result = tmp_path / "out", tmp_path / "rec.npz", tmp_path / "verify.json"
    assert (
        _codegen("export", str(ref.REF_DIR / "dlstm.pt"), "-o", str(out), "--schedule", "spread").returncode
        == 0
    )
    from trainer.cli import main as trainer_main

    assert trainer_main(["simulate", "--seed", "4", "--duration", "20", "-o", str(recording)]) == 0
    model = str(ref.REF_DIR / "dlstm.pt")
    done = _codegen("verify", model, str(out), str(recording), "--no-table", "--json", str(result))
    assert done.returncode == 0, done.stderr
    data = json.loads(result.read_text())
    assert data["schedule"] == {"name": "spread", "latency_samples": 9, "delayed_equal": True}

    def report(json_path: Path, target: Path) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "trainer.cli", "report", model, "--recording", str(recording),
             "--verify", str(json_path), "-o", str(target)],
            cwd=ROOT, capture_output=True, text=True, check=False,
        )  # fmt: skip

    done = report(result, tmp_path / "ok")
    assert done.returncode in (0, 1), done.stderr
    assert (
        "- schedule `spread`: the estimate takes effect 9 samples later"
        in (tmp_path / "ok" / "report.md").read_text()
    )
    data["schedule"]["latency_samples"] = "nine"
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(data))
    done = report(bad, tmp_path / "bad")
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and "Traceback" not in done.stderr
    assert "field 'latency_samples'" in lines[0] and str(bad) in lines[0]
    assert not (tmp_path / "bad").exists()


@pytest.mark.parametrize(
    ("model", "extra", "message"),
    [
        ("pla", [], "method 'pla' takes only step; spread is for dlstm"),
        ("dlstm", ["--format", "px4-params"], "--schedule applies to the C module"),
    ],
)
def test_cli_refuses_a_schedule_without_a_network_step(
    model: str, extra: list[str], message: str, tmp_path: Path
) -> None:
    done = _codegen(
        "export", str(ref.REF_DIR / f"{model}.pt"), "-o", str(tmp_path / "o"), "--schedule", "spread", *extra
    )
    assert done.returncode != 0 and message in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and "Traceback" not in done.stderr
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("flags", ["", "-DTDCK_PORTABLE"])
def test_bit_exact_on_the_cortex_m4(flags: str, tmp_path: Path) -> None:
    """The spread module on the target (QEMU), SMLAD and portable paths, with resets mid-period."""
    reason = cm.ensure_toolchain()
    if reason is not None:
        pytest.skip(f"Cortex-M toolchain unavailable: {reason}")
    model, _ = export(ref.REF_DIR / "dlstm.pt", tmp_path / "out", name="spr", schedule="spread")
    accel, temp = ref.load_stream()
    commands = np.zeros(accel.size, dtype=np.int64)
    commands[[1_003, 2_222]] = CMD_RESET
    build = cm.Build(tmp_path / "out", "spr", tmp_path / "build", extra_cflags=flags)
    result = cm.stream(build, accel, temp, commands, tmp_path / "run")
    golden = golden_for(model.quantised)
    np.testing.assert_array_equal(result.outputs, replay(golden, accel, temp, commands))
