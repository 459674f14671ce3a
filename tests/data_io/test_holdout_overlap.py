"""A held-out figure that is not held out is said so: ``evaluate``/``report --holdout`` on a model
trained on the rows they hold out warn in the output and in the report, whatever the path the
recording is given by (another working directory, a copy of the file): the checkpoint's
``train_stats`` (time range, row count, data fingerprint) prove the overlap by content."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tests.scoring.test_real_scoring import chamber_cycle
from trainer.cli import main
from trainer.data.holdout import overlap_warning, parse_holdout, split
from trainer.data.recording import data_fingerprint
from trainer.data.recording_io import read_recording, write_recording
from trainer.fitting import training_stats

HOLDOUT = "1100:"  # the part after t = 1100 s of the 1500 s run


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("overlap")
    write_recording(chamber_cycle(), root / "run.csv")
    train, _ = split(read_recording(root / "run.csv"), parse_holdout(HOLDOUT))
    write_recording(train, root / "train.csv")
    assert main(["fit", "--method", "poly3", str(root / "run.csv"), "-o", str(root / "whole.pt")]) == 0
    assert main(["fit", "--method", "poly3", str(root / "train.csv"), "-o", str(root / "part.pt")]) == 0
    shutil.copy(root / "run.csv", root / "copy.csv")
    return {"root": root, "run": root / "run.csv", "copy": root / "copy.csv"}


def _held_out_share(rec_path: Path, lo_s: float, hi_s: float) -> float:
    """Percentage of the held-out rows inside [lo_s, hi_s], computed here from the file."""
    _, held = split(read_recording(rec_path), parse_holdout(HOLDOUT))
    inside = (held.time_s >= lo_s) & (held.time_s <= hi_s)
    return 100.0 * float(inside.mean())


@pytest.mark.parametrize("given_as", ["copy", "relative from elsewhere"])
def test_evaluate_warns_when_the_held_out_part_is_training_data(
    run: dict[str, Path],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    given_as: str,
) -> None:
    if given_as == "copy":
        recording = str(run["copy"])  # same data, another file: no path matches the checkpoint's
    else:
        monkeypatch.chdir(tmp_path)  # the checkpoint's source path resolves elsewhere from here
        recording = str(Path("..") / Path(shutil.copy(run["run"], tmp_path.parent / "moved.csv")).name)
    capsys.readouterr()
    out = tmp_path / "e"
    assert (
        main(
            [
                "evaluate",
                str(run["root"] / "whole.pt"),
                recording,
                "--holdout",
                HOLDOUT,
                "--out-dir",
                str(out),
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    whole = read_recording(run["run"])
    share = _held_out_share(run["run"], float(whole.time_s[0]), float(whole.time_s[-1]))
    assert share == 100.0
    warnings = [line for line in printed.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and f"{share:.1f} % of the held-out rows are training rows" in warnings[0]
    assert warnings[0] in (out / "report.md").read_text()


def test_no_warning_when_the_model_never_saw_the_held_out_part(
    run: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    out = tmp_path / "e"
    assert (
        main(
            [
                "evaluate",
                str(run["root"] / "part.pt"),
                str(run["copy"]),
                "--holdout",
                HOLDOUT,
                "--out-dir",
                str(out),
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "training rows" not in printed and "training data" not in printed
    assert "training rows" not in (out / "report.md").read_text()


def test_a_partial_overlap_gives_its_share() -> None:
    """Trained up to t = 1300 s, held out from 1100 s: the share is counted on the held-out rows."""
    rec = chamber_cycle()
    cut = int((rec.time_s <= 1300.0).sum())
    stats = training_stats(rec.slice(0, cut))
    _, held = split(rec, parse_holdout(HOLDOUT))
    held_copy = type(held)(dict(held.columns), dict(held.meta), "elsewhere/copy.csv")
    whole_copy = type(rec)(dict(rec.columns), dict(rec.meta), "elsewhere/copy.csv")
    warning = overlap_warning(
        stats, held_copy, data_fingerprint(held_copy), whole=whole_copy, what="held-out"
    )
    expected = 100.0 * float(((held.time_s >= rec.time_s[0]) & (held.time_s <= rec.time_s[cut - 1])).mean())
    assert 0.0 < expected < 100.0
    assert warning is not None and f"{expected:.1f} % of the held-out rows" in warning
    # another run (other noise) at the same times is not the training data
    other = chamber_cycle(seed=1)
    other_held = split(other, parse_holdout(HOLDOUT))[1]
    other_held = type(other_held)(dict(other_held.columns), {}, "elsewhere/other.csv")
    assert (
        overlap_warning(stats, other_held, data_fingerprint(other_held), whole=other, what="held-out") is None
    )


def test_report_notes_a_held_out_part_that_was_trained_on(
    run: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "s"
    argv = ["report", str(run["root"] / "whole.pt"), "--recording", str(run["copy"]), "--holdout", HOLDOUT]
    assert main([*argv, "-o", str(out)]) == 0
    assert (
        "held-out part: warning: 100.0 % of the held-out rows are training rows"
        in (out / "report.md").read_text()
    )


def test_a_split_that_leaves_too_few_rows_says_which_part_is_which(run: dict[str, Path]) -> None:
    """Held out before the second sample (one row), or all but the first (one row to train on): the
    message names the rows to train on and those held out, not "N and M rows"."""
    from trainer.errors import UserError

    rec = read_recording(run["run"])
    n = len(rec)
    second_s = float(rec.time_s[1] - rec.time_s[0])
    for spec, train, held in ((f":{second_s / 2:g}", n - 1, 1), (f"last:{(n - 1) / n:.9f}", 1, n - 1)):
        with pytest.raises(UserError) as refused:
            split(rec, parse_holdout(spec))
        assert f"leaves {train} rows to train on and {held} held out" in str(refused.value), str(
            refused.value
        )
