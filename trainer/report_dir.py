"""A report directory holds one command's report, never a mix of two runs or two commands.

``trainer compare``, ``trainer evaluate`` and ``trainer report`` write a report (``report.md``,
figures, models) into ``--out-dir``. Each records what it wrote in :data:`OUTPUTS_LIST`, so that
the next run into the same directory can tell its own earlier files from the user's:

- the same command again removes the files of the earlier run that the new one does not write (a
  ``models/pla.pt`` of a comparison run before with ``--methods poly3,pla`` beside the new
  ``poly3``-only report would be read as part of it);
- another command is refused before any work, in one line: its ``report.md`` would replace the
  first one's and sit among the first one's figures and models.

Files the list does not name (the user's, or a directory written before the list existed) are
never touched.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path

from trainer.errors import UserError

OUTPUTS_LIST = ".mems-tdc-outputs.json"  # {"command": ..., "files": [paths relative to the directory]}


def _previous(out_dir: Path) -> tuple[str, list[str]] | None:
    """(command, files) of the last report written into ``out_dir``; None without a readable list."""
    try:
        data = json.loads((out_dir / OUTPUTS_LIST).read_text(encoding="utf-8"))
        return str(data["command"]), [str(f) for f in data["files"]]
    except (OSError, ValueError, KeyError, TypeError):
        return None


def check_report_dir(out_dir: Path, command: str) -> None:
    """Refuse, before any work, a directory that holds another command's report (or that cannot be
    written: :func:`trainer.atomic_dir.check_output_directory`)."""
    from trainer.atomic_dir import check_output_directory

    check_output_directory(out_dir)
    previous = _previous(out_dir)
    if previous is not None and previous[0] != command:
        other, files = previous
        raise UserError(
            f"{out_dir}: holds the report of trainer {other} ({len(files)} files); trainer {command} would put "
            "its report.md among that report's files: give another --out-dir, or remove that one"
        )


def record_outputs(folder: Path, command: str, files: Iterable[str]) -> None:
    """Write the list of ``files`` (relative paths) that ``command`` puts in a report directory."""
    listed = sorted(set(files) - {OUTPUTS_LIST})
    (folder / OUTPUTS_LIST).write_text(
        json.dumps({"command": command, "files": listed}, indent=1) + "\n", encoding="utf-8"
    )


def remove_stale(out_dir: Path, previous: list[str], written: Iterable[str]) -> list[str]:
    """Remove the files the earlier run of the same command wrote (``previous``) and this one did not;
    returns them. Folders left empty by it go too."""
    kept = set(written)
    removed = []
    for name in previous:
        path = out_dir / name
        if name in kept or ".." in Path(name).parts or Path(name).is_absolute() or not path.is_file():
            continue
        path.unlink()
        removed.append(name)
        for parent in path.parents:
            if parent == out_dir or not parent.is_relative_to(out_dir) or any(parent.iterdir()):
                break
            parent.rmdir()
    return removed


def previous_outputs(out_dir: Path, command: str) -> list[str]:
    """The files the last run of ``command`` recorded in ``out_dir`` (none for another command's list)."""
    previous = _previous(out_dir)
    return previous[1] if previous is not None and previous[0] == command else []
