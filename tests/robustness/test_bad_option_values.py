"""Option values a fuzz of every command's options found accepted, crashing or misnamed: each is now one
``error:`` line naming the option or file, exit status 2, and nothing written.

The cases: numbers that are not finite or absurdly large (``nan``, ``inf``, ``1e300``) where a plain
``< 0`` test let them through to a traceback deep in the work; an output place the permissions allow
and the file system refuses (``/proc``), found only after the work; an output over an input
(``codegen verify --json`` replaced the recording it verified); import options that contradict each
other or produce no recording; a scheduler address ignored when no unit reached it.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from codegen.cli import main as codegen_main
from tests.cli_corpus import IMPORT_OWN_CSV
from trainer.cli import main as trainer_main
from trainer.errors import run_cli


@pytest.fixture(scope="module")
def work(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short simulated run (CSV and NPZ) and a cubic fitted on it."""
    root = tmp_path_factory.mktemp("bad_values")
    for name in ("s.npz", "s.csv"):
        argv = ["simulate", "--seed", "1", "--duration", "600", "--rate", "5", "-o", str(root / name)]
        assert run_cli(trainer_main, argv) == 0
    assert (
        run_cli(trainer_main, ["fit", "--method", "poly3", str(root / "s.npz"), "-o", str(root / "p.pt")])
        == 0
    )
    return root


def _refused(capsys: pytest.CaptureFixture[str], main: object, argv: list[str], root: Path) -> str:
    """Run, expect one error line and exit 2, and no new file in ``root``; return the line."""
    before = set(root.rglob("*"))
    capsys.readouterr()
    assert run_cli(main, argv) == 2  # type: ignore[arg-type]
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in err, err
    assert set(root.rglob("*")) == before
    return lines[0]


COLUMNS = IMPORT_OWN_CSV  # the simulated CSV's, for import
DLSTM = ["fit", "--method", "dlstm", "--iterations", "2", "--cycles", "0", "--quiet"]


@pytest.mark.parametrize(
    ("options", "named"),
    [
        (["--lr", "inf"], "--lr"),
        (["--lr", "1e300"], "--lr"),
        (["--temp-smoothing", "inf"], "--temp-smoothing"),
        (["--temp-smoothing", "1e308"], "--temp-smoothing"),
        (["--run-smoothing", "nan"], "--run-smoothing"),
        (["--target-loss", "nan"], "--target-loss"),
        (["--target-loss", "-5"], "--target-loss"),
        (["--threads", "1000000"], "--threads"),  # a segmentation fault, and a lock file left
        (["--iterations", "0"], "--iterations"),  # wrote an untrained network (its initial weights)
    ],
)
def test_a_dlstm_option_that_is_no_usable_number_is_refused(
    options: list[str], named: str, work: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    line = _refused(
        capsys, trainer_main, [*DLSTM, *options, str(work / "s.npz"), "-o", str(work / "d.pt")], work
    )
    assert named in line


@pytest.mark.parametrize("value", ["nan", "inf", "1e308"])
def test_a_scoring_smoothing_that_is_no_usable_number_is_refused(
    value: str, work: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model, rec = str(work / "p.pt"), str(work / "s.npz")
    for argv in (
        ["evaluate", model, rec, "--out-dir", str(work / "ev"), "--smoothing", value],
        ["report", model, "--recording", rec, "-o", str(work / "rep"), "--smoothing", value],
        [
            "compare",
            rec,
            str(work / "s.csv"),
            "--methods",
            "poly3",
            "--out-dir",
            str(work / "c"),
            "--smoothing",
            value,
        ],
    ):
        assert "--smoothing must be a finite number" in _refused(capsys, trainer_main, argv, work)


@pytest.mark.skipif(
    not (os.path.isdir("/proc") and os.access("/proc", os.W_OK)), reason="needs a /proc that says writable"
)
def test_an_output_place_the_file_system_refuses_is_refused_before_the_work(
    work: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """/proc passes the permission test for root and refuses every new file: the commands found out
    after their work, with a traceback (a probe now asks the file system itself)."""
    model, rec = str(work / "p.pt"), str(work / "s.npz")
    for main, argv in (
        (
            trainer_main,
            [
                "import",
                str(work / "s.csv"),
                *COLUMNS,
                "-o",
                "/proc/x.csv",
            ],
        ),
        (trainer_main, ["fit", "--method", "poly3", rec, "-o", "/proc/m.pt"]),
        (trainer_main, ["evaluate", model, rec, "--out-dir", "/proc/ev"]),
        (trainer_main, ["compare", rec, str(work / "s.csv"), "--methods", "poly3", "--out-dir", "/proc/cmp"]),
        (trainer_main, ["report", model, "--recording", rec, "-o", "/proc/rep"]),
        (trainer_main, ["diagnose", rec, "--json", "/proc/d.json"]),
        (codegen_main, ["verify", model, str(work), rec, "--json", "/proc/v.json"]),
    ):
        assert "cannot write in /proc" in _refused(capsys, main, argv, work)


def test_verify_never_writes_its_json_over_an_input(work: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--json s.csv`` replaced the recording being verified (exit 0)."""
    assert run_cli(codegen_main, ["export", str(work / "p.pt"), "-o", str(work / "c99")]) == 0
    text = (work / "s.csv").read_text()
    argv = [
        "verify",
        str(work / "p.pt"),
        str(work / "c99"),
        str(work / "s.csv"),
        "--no-table",
        "--json",
        str(work / "s.csv"),
    ]
    assert "is also the input" in _refused(capsys, codegen_main, argv, work)
    assert (work / "s.csv").read_text() == text
    swapped = ["verify", str(work / "c99"), str(work / "p.pt"), str(work / "s.csv"), "--no-table"]
    assert "arguments swapped?" in _refused(capsys, codegen_main, swapped, work)


@pytest.mark.parametrize(
    ("options", "named"),
    [
        (["--resample", "0.0001"], "--resample"),  # one row at 0.0001 Hz
        (["--channels", "all", "--channel-map", "accel0_x=accel_mg,accel0_x=temp_c"], "mapped twice"),
        (["--channel-map", "accel0_x=accel_mg"], "give --channels too"),  # silently ignored
        (["--sensor", "a\nb=c"], "--sensor"),  # a traceback: metadata cannot be written
    ],
)
def test_import_options_that_make_no_recording_or_contradict_are_refused(
    options: list[str], named: str, work: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["import", str(work / "s.csv"), *COLUMNS]
    assert named in _refused(capsys, trainer_main, [*argv, *options, "-o", str(work / "o.csv")], work)


def test_an_import_whose_line_has_a_field_too_many_names_the_line(
    work: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lines = (work / "s.csv").read_text().splitlines()
    data = [i for i, line in enumerate(lines) if line and not line.startswith("#")]
    lines[data[3]] += ",7"  # the fourth data line (the header is data[0])
    bad = work / "extra" / "bad.csv"
    bad.parent.mkdir()
    bad.write_text("\n".join(lines) + "\n")
    argv = [
        "import",
        str(bad),
        *COLUMNS,
        "-o",
        str(work / "o.csv"),
    ]
    line = _refused(capsys, trainer_main, argv, work)
    fields = lines[data[0]].count(",") + 1
    assert (
        f"line {data[3] + 1}: {fields + 1} fields where the header (line {data[0] + 1}) has {fields}" in line
    )


def test_plan_sizes_beyond_any_budget_and_an_empty_output_name_are_refused(
    work: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = str(work / "plan")
    assert "--draws 1000000000" in _refused(
        capsys, trainer_main, ["plan", "-o", out, "--draws", "1000000000"], work
    )
    assert "--max-hours" in _refused(capsys, trainer_main, ["plan", "-o", out, "--max-hours", "1e9"], work)
    assert "--max-hours" in _refused(capsys, trainer_main, ["plan", "-o", out, "--max-hours", "nan"], work)
    empty = ["simulate", "--seed", "1", "--duration", "60", "-o", ""]
    assert "an empty file name" in _refused(capsys, trainer_main, empty, work)


def test_fleet_refuses_a_scheduler_address_before_any_unit(
    work: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Every unit failed to load, so no task reached the cluster and the bad address was ignored."""
    manifest = work / "fleet" / "units.csv"
    manifest.parent.mkdir()
    manifest.write_text("id,recordings\nu1,missing.csv\n")
    argv = ["fleet", str(manifest), "-o", str(work / "fleet" / "out"), "--scheduler", "garbage", "--quiet"]
    assert "--scheduler 'garbage'" in _refused(capsys, trainer_main, argv, work)
