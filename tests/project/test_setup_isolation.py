"""The README's two commands (scripts/test.sh, scripts/pipeline.sh) never touch the system's Python.

The scripts run in a scratch copy of the repository where every program they could reach is a stub
that logs its arguments: the base ``python3`` (and ``PYTHON``), ``pip``/``pip3`` on PATH, and the
project environment's ``.venv/bin`` tools, which the base ``python3 -m venv`` stub creates. The
check: the base interpreter is only ever asked to create ``.venv`` (``-m venv``), no ``pip`` outside
``.venv`` runs, and every install and tool run goes through ``.venv/bin``. Takes about a second.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tomllib
from importlib import metadata
from pathlib import Path

import pytest

from tests.repo import REPO_ROOT

REPO = REPO_ROOT
SCRIPTS = ("setup.sh", "test.sh", "pipeline.sh", "main_job.sh")

LOGGER = """#!/bin/sh
printf '%s %s\\n' "{name}" "$(printf '%s' "$*" | tr '\\n' ' ')" >> "{log}"  # one write: side-by-side steps log at once
{body}
exit 0
"""
# The base interpreter's stub creates a venv whose tools are stubs too.
VENV_MAKER = """
if [ "$1" = "-m" ] && [ "$2" = "venv" ]; then
  mkdir -p "$3/bin"
  for tool in python pip ruff mypy trainer codegen; do
    cat > "$3/bin/$tool" <<'STUB'
#!/bin/sh
printf '%s %s\\n' "venv/$(basename "$0")" "$(printf '%s' "$*" | tr '\\n' ' ')" >> "{log}"
exit 0
STUB
    chmod +x "$3/bin/$tool"
  done
fi
"""


def _stub(path: Path, name: str, log: Path, body: str = "") -> None:
    path.write_text(LOGGER.format(name=name, log=log, body=body.format(log=log)))
    path.chmod(0o755)


@pytest.fixture
def scratch(tmp_path: Path) -> tuple[Path, Path, dict[str, str]]:
    """A copy of the scripts and pyproject.toml, stub programs first on PATH, the log file."""
    repo = tmp_path / "repo"
    (repo / "scripts").mkdir(parents=True)
    for script in SCRIPTS:
        shutil.copy2(REPO / "scripts" / script, repo / "scripts" / script)
    shutil.copy2(REPO / "pyproject.toml", repo / "pyproject.toml")
    shutil.copy2(REPO / "scripts" / "constraints.txt", repo / "scripts" / "constraints.txt")
    stubs = tmp_path / "stubs"
    stubs.mkdir()
    log = tmp_path / "calls.log"
    _stub(stubs / "python3", "base-python", log, VENV_MAKER)
    for name in ("pip", "pip3", "python"):
        _stub(stubs / name, f"base-{name}", log)
    env = {
        "PATH": f"{stubs}:/usr/bin:/bin",
        "HOME": str(tmp_path),
        "PYTHON": str(stubs / "python3"),
        "OUT": str(tmp_path / "out"),
    }
    return repo, log, env


def _run(repo: Path, env: dict[str, str], script: str) -> None:
    result = subprocess.run(
        ["bash", str(repo / "scripts" / script)],
        cwd=repo,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 0, result.stderr


def _calls(log: Path) -> list[str]:
    return log.read_text().splitlines() if log.exists() else []


@pytest.mark.skipif(shutil.which("bash") is None, reason="bash not available")
@pytest.mark.parametrize("script", ["test.sh", "pipeline.sh"])
def test_scripts_use_only_the_project_environment(
    scratch: tuple[Path, Path, dict[str, str]], script: str
) -> None:
    repo, log, env = scratch
    _run(repo, env, script)  # a fresh clone: no .venv yet
    _run(repo, env, script)  # and again with .venv present
    calls = _calls(log)
    base = [call for call in calls if call.startswith("base-")]
    assert base == ["base-python -m venv .venv"], base  # created once, never asked to install
    installs = [
        call for call in calls if " -m pip " in f" {call} " or call.startswith(("venv/pip", "base-pip"))
    ]
    assert installs and all(call.startswith("venv/python -m pip install") for call in installs), installs
    assert all(call.startswith(("base-python -m venv", "venv/")) for call in calls), calls
    tools = {call.split()[0] for call in calls}
    expected = {"venv/ruff", "venv/mypy"} if script == "test.sh" else {"venv/trainer"}
    assert expected <= tools


def test_scripts_name_no_other_interpreter() -> None:
    """Static guard: only setup.sh names the base interpreter, and only to create the environment."""
    for script in SCRIPTS:
        for number, line in enumerate((REPO / "scripts" / script).read_text().splitlines(), start=1):
            code = line.split("#", 1)[0]
            if "pip " in code or "pip3" in code:
                assert '"$PY" -m pip' in code, f"{script}:{number}: pip outside .venv: {line.strip()}"
            if "BASE_PYTHON" in code and not code.strip().startswith("BASE_PYTHON="):
                assert code.strip().endswith('-m venv "$VENV"'), f"{script}:{number}: {line.strip()}"
    assert os.access(REPO / "scripts" / "setup.sh", os.X_OK)


def _name(requirement: str) -> str:
    """A requirement's distribution name as pip compares them (PEP 503: case and -_. folded)."""
    return re.sub(r"[-_.]+", "-", re.split(r"[\[<>=!~; ]", requirement, maxsplit=1)[0]).lower()


def test_every_dependency_is_pinned_and_the_suite_runs_on_the_pins() -> None:
    """A clean clone installs the versions the docs' numbers were measured with (a new numpy moved a
    knife-edge finder fold, a new ruff can fail the lint), and this suite runs on exactly those."""
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    declared = [*project["dependencies"], *project["optional-dependencies"]["test"]]
    pins = {}
    for line in (REPO / "scripts" / "constraints.txt").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, version = line.split("==")
            pins[_name(name)] = version.strip()
    for requirement in declared:
        name = _name(requirement)
        assert name in pins, f"{requirement}: not pinned in scripts/constraints.txt"
        assert metadata.version(name) == pins[name], (
            f"{name}: installed {metadata.version(name)}, pinned {pins[name]}"
        )
    assert '-c "$constraints"' in (REPO / "scripts" / "setup.sh").read_text()
