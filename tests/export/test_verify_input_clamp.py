"""``codegen verify`` keeps the input clamp apart from the quantisation budget, and exits non-zero when
the arithmetic itself is over the budget.

A recording with an acceleration sample at +-32 g through a module that clamps at +-16 g: verify
blamed the quantisation ("RMS 1.45 mg ... OVER THE BUDGET") and exited 0. The samples the module
clamps are counted and compared apart (here counted from the recording and the model file alone);
the budget is the arithmetic's, and a budget the arithmetic exceeds is exit status 3
(docs/codegen.md, "Exit status").
"""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from codegen import verify as verify_module
from codegen.cli import main as codegen_main
from codegen.export import export
from codegen.fixedpoint import round_half_away
from codegen.verify import verify
from tests import testmodels as tm
from tests.cli_capture import run_captured
from trainer.cli import main as trainer_main
from trainer.data.recording import Recording
from trainer.data.recording_io import read_recording, write_recording

CLAMP_MG = 16_000.0  # the default --accel-limit-g, 16 g
OVER_BUDGET = 3  # docs/codegen.md: the C equals its golden model, the arithmetic is over the budget


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("clamp_run")
    assert (
        trainer_main(
            ["simulate", "--seed", "3", "--duration", "600", "--rate", "20", "-o", str(root / "sim.npz")]
        )
        == 0
    )
    rec = read_recording(root / "sim.npz")
    for method in ("persistence", "poly3"):
        tm.save_checkpoint(tm.checkpoint_for(method, rec), root / f"{method}.pt")
        export(root / f"{method}.pt", root / method, name=f"c_{method.replace('-', '_')}")
    accel = rec.accel_mg.copy()
    accel[[500, 901, 4_444]] = [
        32_000.0,
        -32_000.0,
        20_000.0,
    ]  # beyond the clamp, within an accelerometer's range
    write_recording(
        Recording({**rec.columns, "accel_mg": accel}, dict(rec.meta), "spikes"), root / "spikes.npz"
    )
    return root


def test_samples_beyond_the_acceleration_clamp_are_compared_apart(
    run: Path, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    rec = read_recording(run / "spikes.npz")
    beyond = int(np.count_nonzero(np.abs(np.rint(rec.accel_mg * 16_000)) > CLAMP_MG * 16_000))
    assert beyond == 3
    result = verify(run / "persistence.pt", run / "persistence", run / "spikes.npz", table1=False)
    assert result.mismatches == 0 and result.state_equal
    budget = result.budget
    assert budget.clamped is not None and budget.clamped.count == beyond
    assert budget.compared == len(rec) - beyond
    assert budget.clamped.effect_max_mg > 100.0  # the clamp moves a window mean by hundreds of mg
    assert budget.met and budget.arithmetic_max_abs_mg < verify_module.ERROR_BUDGET_MAX_MG
    code, out, _ = run_captured(
        codegen_main,
        capsys,
        "verify", str(run / "persistence.pt"), str(run / "persistence"), str(run / "spikes.npz"), "--no-table",
        "--json", str(tmp_path / "v.json"),
    )  # fmt: skip
    assert code == 0
    assert f"{beyond} samples beyond the input clamp, compared apart" in out
    assert "within the budget" in out and "OVER THE BUDGET" not in out
    document = json.loads((tmp_path / "v.json").read_text())["error_budget"]
    assert document["clamped_samples"] == beyond and document["compared_samples"] == len(rec) - beyond
    assert document["met"] is True


def test_the_same_recording_without_spikes_has_nothing_apart(run: Path) -> None:
    result = verify(run / "persistence.pt", run / "persistence", run / "sim.npz", table1=False)
    assert result.budget.clamped is None and result.budget.compared is None and result.budget.met


def test_temperatures_beyond_the_cubic_s_clip_are_compared_apart(run: Path, tmp_path: Path) -> None:
    """The cubic clips T to its fitted range (flagged): samples beyond it are counted apart too."""
    rec = read_recording(run / "sim.npz")
    from trainer.checkpoint import load_checkpoint

    lo, hi = load_checkpoint(run / "poly3.pt")["valid_temp_range_c"]
    temp = rec.temp_c.copy()
    temp[:40] = hi + 5.0
    temp[-25:] = lo - 3.0
    write_recording(Recording({**rec.columns, "temp_c": temp}, dict(rec.meta), "hot"), tmp_path / "hot.npz")
    read_mdegc = np.rint(temp * 1000)
    lo_q, hi_q = round_half_away(Fraction(lo) * 1000), round_half_away(Fraction(hi) * 1000)
    beyond = int(np.count_nonzero((read_mdegc < lo_q) | (read_mdegc > hi_q)))
    assert beyond == 65
    result = verify(run / "poly3.pt", run / "poly3", tmp_path / "hot.npz", table1=False)
    assert result.mismatches == 0 and result.budget.met
    assert result.budget.clamped is not None and result.budget.clamped.count == beyond


def test_a_budget_the_arithmetic_exceeds_is_exit_status_3(
    run: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Within the budget: 0; the same module and recording judged by a budget below its arithmetic's
    error (a stand-in for a quantiser that misses it): 3, the C still equal to its golden model."""
    argv = ["verify", str(run / "poly3.pt"), str(run / "poly3"), str(run / "sim.npz"), "--no-table"]
    code, out, _ = run_captured(codegen_main, capsys, *argv)
    assert code == 0 and "within the budget" in out
    monkeypatch.setattr(verify_module, "ERROR_BUDGET_RMS_MG", 1e-9)
    monkeypatch.setattr(verify_module, "ERROR_BUDGET_MAX_MG", 1e-9)
    code, out, err = run_captured(codegen_main, capsys, *argv)
    assert code == OVER_BUDGET
    assert "mismatches: 0" in out and "OVER THE BUDGET" in out
    assert (
        len(err.strip().splitlines()) == 1
        and "over the error budget" in err
        and "equals its golden model" in err
    )
