"""The one way tests reach ``../shared``: a file there, or a skip naming where it was looked for."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import REAL_RUN, SHARED_ENV, shared_path


def test_an_absent_shared_directory_skips_and_says_where_it_looked(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(SHARED_ENV, str(tmp_path / "absent"))
    with pytest.raises(pytest.skip.Exception, match=SHARED_ENV) as info:
        shared_path(*REAL_RUN)
    assert str(tmp_path / "absent" / "data" / "real") in str(info.value)


def test_the_override_names_the_shared_directory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    spec = tmp_path / "specs" / "recording-format.md"
    spec.parent.mkdir()
    spec.write_text("# format\n")
    monkeypatch.setenv(SHARED_ENV, str(tmp_path))
    assert shared_path("specs", "recording-format.md") == spec
    with pytest.raises(pytest.skip.Exception):
        shared_path("specs", "missing.md")  # the directory is there, the file is not
