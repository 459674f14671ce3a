"""Seeded random mutations of valid inputs through every command: no traceback, no leftover, no
silent acceptance of impossible data, no run above a memory limit.

Each seed mutates a valid recording (CSV and NPZ), model file, simulation TOML, thresholds TOML,
fleet manifest, calibration blob and flight log (ULog, DataFlash): byte flips, truncations,
inserted garbage, huge numbers, NaN, full-width or other unicode digits, non-breaking spaces,
duplicated, removed or swapped fields, rows and columns, wrong value types and deep nesting. Every
mutant runs in-process through the entry points' own ``run_cli`` (the commands and argument lists
of tests/cli_corpus.py). A run fails the test when it raises (a traceback), exits other than 0 or 2
(1 where the command documents it: a failed sign-off, fleet unit or verification), prints more than
one ``error:`` line, leaves any file in its output directory on an error or a temporary file on
success, or accepts a recording whose values are not finite or lie outside the plausibility bounds.
One mutant per seed also runs in a child process under an address-space limit.

``FUZZ_SEED=123 pytest tests/robustness/test_fuzz.py`` runs other mutations (a comma-separated list is several
seeds); ``--runslow`` adds a longer run of more seeds. A failing mutant is kept under
``/tmp/fuzz-findings`` with its command line.
"""

from __future__ import annotations

import io
import math
import os
import re
import resource
import shutil
import subprocess
import sys
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import tomli_w
import torch

from codegen.cli import main as codegen_main
from tests.cli_corpus import (
    IMPORT_OWN_CSV,
    Case,
    Main,
    config_cases,
    hidden_files,
    model_cases,
    npz_bytes,
    recording_cases,
    valid_files,
    valid_flight_logs,
    write_file,
)
from tests.repo import REPO_ROOT
from trainer.checkpoint import load_checkpoint
from trainer.cli import main as trainer_main
from trainer.data.plausibility import TEMP_MAX_C, TEMP_MIN_C
from trainer.errors import EXIT_USER_ERROR, run_cli

ROOT = REPO_ROOT
DEFAULT_SEEDS = (0, 1)
SLOW_SEEDS = tuple(range(100, 110))
SEEDS = (
    tuple(int(s) for s in os.environ["FUZZ_SEED"].split(","))
    if os.environ.get("FUZZ_SEED")
    else DEFAULT_SEEDS
)
FINDINGS = Path("/tmp/fuzz-findings")
ADDRESS_SPACE_BYTES = 6 << 30  # torch and numpy map ~2 GB at import; a runaway allocation fails far above
MAX_RSS_BYTES = 1536 << 20  # a mutant of a 400-row recording needs far less
ACCEL_LIMIT_MG = 16 * 1000 * 4  # beyond any MEMS accelerometer's range (+-16 g) with margin

# what a mutated number may become: huge, tiny, not a number, unicode digits, separators, text
HOSTILE_NUMBERS = (
    "1e308", "-1e308", "1e300", "nan", "NaN", "inf", "-inf", "-500", "1e-320", "0", "-0", "9" * 400,
    "１２３", "٣.٥", "1\u00a0000", "1_000", "0x1F", "1,5", "", " ", "abc", "\u200b7", "1e", "--1", "1e999",
)  # fmt: skip
HOSTILE_VALUES: tuple[Any, ...] = (
    None, "abc", "", -1, 0, 10**18, -(10**18), 1e308, -1e308, float("nan"), float("inf"), True, [], {},
    [1.0, 2.0, 3.0], {"a": 1}, "１２", 2**63,
)  # fmt: skip
Mutator = Callable[[np.random.Generator, bytes], bytes]


# --- byte and text mutations -----------------------------------------------------------------------


def _flip(rng: np.random.Generator, data: bytes) -> bytes:
    out = bytearray(data)
    for _ in range(int(rng.integers(1, 8))):
        if out:
            out[int(rng.integers(len(out)))] = int(rng.integers(256))
    return bytes(out)


def _truncate(rng: np.random.Generator, data: bytes) -> bytes:
    return data[: int(rng.integers(0, max(1, len(data))))]


def _insert_garbage(rng: np.random.Generator, data: bytes) -> bytes:
    at = int(rng.integers(0, len(data) + 1))
    junk = bytes(rng.integers(0, 256, int(rng.integers(1, 400)), dtype=np.uint8))
    return data[:at] + junk + data[at:]


BYTE_MUTATORS: tuple[Mutator, ...] = (_flip, _truncate, _insert_garbage)


def _lines_op(op: Callable[[np.random.Generator, list[str]], list[str]]) -> Mutator:
    def mutate(rng: np.random.Generator, data: bytes) -> bytes:
        lines = data.decode("utf-8", errors="replace").split("\n")
        return "\n".join(op(rng, lines)).encode("utf-8")

    mutate.__name__ = op.__name__
    return mutate


def _data_rows(lines: list[str]) -> list[int]:
    rows = [k for k, line in enumerate(lines) if line and not line.startswith("#")]
    return rows[1:] or rows  # after the header


def _hostile_field(rng: np.random.Generator, lines: list[str]) -> list[str]:
    for _ in range(int(rng.integers(1, 4))):
        k = int(rng.choice(_data_rows(lines)))
        fields = lines[k].split(",")
        fields[int(rng.integers(len(fields)))] = str(rng.choice(HOSTILE_NUMBERS))
        lines[k] = ",".join(fields)
    return lines


def _duplicate_row(rng: np.random.Generator, lines: list[str]) -> list[str]:
    k = int(rng.choice(_data_rows(lines)))
    return lines[: k + 1] + [lines[k]] * int(rng.integers(1, 3)) + lines[k + 1 :]


def _remove_rows(rng: np.random.Generator, lines: list[str]) -> list[str]:
    drop = set(rng.choice(_data_rows(lines), int(rng.integers(1, 30))).tolist())
    return [line for k, line in enumerate(lines) if k not in drop]


def _column_op(rng: np.random.Generator, lines: list[str]) -> list[str]:
    """Duplicate, remove or swap a column (header and rows), or swap two header names only."""
    width = max(len(line.split(",")) for line in lines if not line.startswith("#"))
    a, b = (int(x) for x in rng.integers(0, width, 2))
    kind = int(rng.integers(4))
    out = []
    header_seen = False
    for line in lines:
        if not line or line.startswith("#"):
            out.append(line)
            continue
        fields = line.split(",")
        if a < len(fields) and b < len(fields):
            if kind == 0:
                fields.insert(b, fields[a])
            elif kind == 1:
                del fields[a]
            elif kind == 2 or not header_seen:
                fields[a], fields[b] = fields[b], fields[a]
        header_seen = True
        out.append(",".join(fields))
    return out


def _swap_fields(rng: np.random.Generator, lines: list[str]) -> list[str]:
    k = int(rng.choice(_data_rows(lines)))
    fields = lines[k].split(",")
    rng.shuffle(fields)
    lines[k] = ",".join(fields)
    return lines


def _unicode_line(rng: np.random.Generator, lines: list[str]) -> list[str]:
    at = int(rng.integers(0, len(lines) + 1))
    junk = str(
        rng.choice(["\ufeff", "ß,∂,ø", "\u202e1,2,3", "１,２,３", "\x00\x00", "# sample_rate_hz=1e308"])
    )
    return [*lines[:at], junk, *lines[at:]]


TEXT_MUTATORS: tuple[Mutator, ...] = (
    *BYTE_MUTATORS,
    *(
        _lines_op(op)
        for op in (_hostile_field, _duplicate_row, _remove_rows, _column_op, _swap_fields, _unicode_line)
    ),
)


# --- structured mutations (NPZ members, checkpoint fields, TOML values) ----------------------------


def _hostile_value(rng: np.random.Generator) -> Any:
    if rng.random() < 0.1:  # deep nesting
        value: Any = 1.0
        for _ in range(int(rng.integers(20, 150))):  # pickling recurses: deeper comes as TOML text
            value = [value]
        return value
    return HOSTILE_VALUES[int(rng.integers(len(HOSTILE_VALUES)))]


def _paths(value: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every key path into nested dicts and lists (the containers themselves included)."""
    found = [prefix] if prefix else []
    if isinstance(value, dict):
        for key, item in value.items():
            found += _paths(item, (*prefix, key))
    elif isinstance(value, list) and len(value) < 50:
        for index, item in enumerate(value):
            found += _paths(item, (*prefix, index))
    return found


def _mutate_tree(rng: np.random.Generator, tree: dict, make: Callable[[np.random.Generator], Any]) -> dict:
    """Replace (or delete, or add beside) a random node of ``tree`` by ``make(rng)``."""
    paths = _paths(tree)
    path = paths[int(rng.integers(len(paths)))]
    parent = tree
    for key in path[:-1]:
        parent = parent[key]
    kind = rng.random()
    if kind < 0.15 and isinstance(parent, dict):
        del parent[path[-1]]
    elif kind < 0.25 and isinstance(parent, dict):
        parent[f"unknown_{int(rng.integers(100))}"] = make(rng)
    else:
        parent[path[-1]] = make(rng)
    return tree


def _toml_value(rng: np.random.Generator) -> Any:
    value = _hostile_value(rng)
    if isinstance(value, list) and value and isinstance(value[0], list):
        return [[[1.0]]]  # deeper nesting comes as text (tomli_w recurses)
    if value is None:
        return "none"
    if isinstance(value, int) and not -(2**63) <= value < 2**63:
        return float(value)
    return value


def _mutate_toml(rng: np.random.Generator, data: bytes) -> bytes:
    if rng.random() < 0.3:
        return TEXT_MUTATORS[int(rng.integers(len(TEXT_MUTATORS)))](rng, data)
    if rng.random() < 0.05:
        return b"x = " + b"[" * 5000 + b"]" * 5000 + b"\n" + data  # nesting beyond any parser's stack
    tree = _mutate_tree(rng, tomllib.loads(data.decode()), _toml_value)
    return tomli_w.dumps(tree).encode()


def _tensor_or_value(rng: np.random.Generator) -> Any:
    if rng.random() < 0.3:
        shape = tuple(int(n) for n in rng.integers(0, 5, int(rng.integers(0, 3))))
        fill = float(rng.choice([np.nan, np.inf, 1e308, -1e308, 0.0, 1e9]))
        return torch.full(shape, fill, dtype=torch.float64)
    return _hostile_value(rng)


def _mutate_model(rng: np.random.Generator, data: bytes) -> bytes:
    if rng.random() < 0.25:
        return BYTE_MUTATORS[int(rng.integers(len(BYTE_MUTATORS)))](rng, data)
    tree = torch.load(io.BytesIO(data), weights_only=True)
    for _ in range(int(rng.integers(1, 3))):
        tree = _mutate_tree(rng, tree, _tensor_or_value)
    buffer = io.BytesIO()
    torch.save(tree, buffer)
    return buffer.getvalue()


def _mutate_npz(rng: np.random.Generator, data: bytes) -> bytes:
    if rng.random() < 0.25:
        return BYTE_MUTATORS[int(rng.integers(len(BYTE_MUTATORS)))](rng, data)
    with np.load(io.BytesIO(data)) as archive:
        arrays = {name: archive[name] for name in archive.files}
    name = str(rng.choice(sorted(arrays)))
    values = arrays[name]
    kind = int(rng.integers(8))
    if kind == 0:
        values = values.copy()
        values[rng.integers(0, len(values), int(rng.integers(1, 4)))] = rng.choice(
            [np.nan, np.inf, -np.inf, 1e308, -1e308, 1e300, -500.0, 1e6]
        )
    elif kind == 1:
        values = values.astype(rng.choice(["<U8", "complex128", "int8", "bool", "float16", "uint64"]))
    elif kind == 2:
        values = values.reshape(-1, 2) if len(values) % 2 == 0 else values[None, :]
    elif kind == 3:
        del arrays[name]
        return npz_bytes(**arrays)
    elif kind == 4:
        values = values[: int(rng.integers(0, len(values)))]
    elif kind == 5:
        values = np.array(float(values[0]) if len(values) else 0.0)
    elif kind == 6:
        arrays[f"extra_{int(rng.integers(9))}"] = _hostile_npz_member(rng)
    else:
        values = np.repeat(values, 2)
    arrays[name] = values
    return npz_bytes(**arrays)


def _hostile_npz_member(rng: np.random.Generator) -> np.ndarray:
    return np.array(
        [np.zeros(3), "x", np.array([[1.0]]), np.full(4, np.nan)][int(rng.integers(4))],
        dtype=object if rng.random() < 0.3 else None,
    )


def _mutate_text(rng: np.random.Generator, data: bytes) -> bytes:
    return TEXT_MUTATORS[int(rng.integers(len(TEXT_MUTATORS)))](rng, data)


def _mutate_bytes(rng: np.random.Generator, data: bytes) -> bytes:
    return BYTE_MUTATORS[int(rng.integers(len(BYTE_MUTATORS)))](rng, data)


# --- the inputs, their commands and their checks ---------------------------------------------------


THRESHOLDS = "[thresholds]\nresidual_rms_mg = 5.0\nbranch_max_mg = 9.0\nmin_coverage = 0.5\nmax_verify_mismatches = 0\n"


def _manifest_toml(files: dict[str, Path]) -> str:
    return (
        '[fleet]\nmethods = ["poly3"]\ndiagnose_blocks = 50\nholdout = "last:0.25"\n'
        f'[[unit]]\nid = "U1"\nrecordings = ["{files["good.csv"].name}"]\nexport_name = "tdc_u1"\n'
    )


def _import_case() -> Case:
    return (
        "import",
        trainer_main,
        lambda c, f, o: ["import", str(f), *IMPORT_OWN_CSV,
                         "-o", str(o / "r.csv")],
    )  # fmt: skip


def _cheap(cases: list[Case]) -> list[Case]:
    """The cases without the finder (seconds per accepted mutant): diagnose runs once per seed."""
    return [case for case in cases if not case[0].startswith("diagnose")]


def _kinds(
    files: dict[str, Path],
) -> dict[str, tuple[Path, Callable[[np.random.Generator, bytes], bytes], list[Case], int]]:
    """Input kind -> (valid file, mutator, commands that read it, mutants per seed)."""
    fleet_case: Case = (
        "fleet",
        trainer_main,
        lambda c, f, o: ["fleet", str(f), "-o", str(o / "f"), "--quiet", "--scheduler", c["scheduler"]],
    )
    blob_case: Case = (
        "codegen verify --channels",
        codegen_main,
        lambda c, f, o: [
            "verify",
            str(c["fitdir"]),
            str(f.parent),
            str(c["multi.csv"]),
            "--channels",
            "all",
            "--json",
            str(o / "v.json"),
        ],
    )
    flight_case: Case = (
        "import",
        trainer_main,
        lambda c, f, o: ["import", str(f), "--channels", "all", "-o", str(o / "r.csv")],
    )
    sim, report_config = _cheap(config_cases())[0], _cheap(config_cases())[-1]
    return {
        "recording.csv": (files["good.csv"], _mutate_text, [_import_case(), *_cheap(recording_cases())], 12),
        "recording.npz": (files["good.npz"], _mutate_npz, [_import_case(), *_cheap(recording_cases())], 6),
        "model.pt": (files["good.pt"], _mutate_model, model_cases(), 8),
        "simulation.toml": (files["sim.toml"], _mutate_toml, [sim], 6),
        "thresholds.toml": (files["thresholds.toml"], _mutate_toml, [report_config], 5),
        "manifest.toml": (files["manifest.toml"], _mutate_toml, [fleet_case], 2),
        "manifest.csv": (files["manifest.csv"], _mutate_text, [fleet_case], 2),
        "blob": (files["blob"], _mutate_bytes, [blob_case], 2),
        "flightlog.ulg": (files["valid.ulg"], _mutate_bytes, [flight_case], 4),
        "flightlog.bin": (files["valid.bin"], _mutate_bytes, [flight_case], 4),
    }  # fmt: skip


@pytest.fixture(scope="module")
def client() -> Any:
    """One LocalCluster for the fleet mutants (starting one per run costs seconds)."""
    from trainer.fleet.cluster import open_client

    with open_client(None, 1) as active:
        yield active


@pytest.fixture(scope="module")
def valid(tmp_path_factory: pytest.TempPathFactory, client: Any) -> dict[str, Any]:
    root = tmp_path_factory.mktemp("fuzz")
    files: dict[str, Any] = valid_files(root)
    files["good.npz"] = write_file(root / "good.npz", npz_bytes(**_read_csv(files["good.csv"])))
    files["sim.toml"] = write_file(root / "sim.toml", (ROOT / "trainer/physics/default.toml").read_text())
    files["thresholds.toml"] = write_file(root / "thresholds.toml", THRESHOLDS)
    files["manifest.toml"] = write_file(root / "manifest.toml", _manifest_toml(files))
    files["manifest.csv"] = write_file(
        root / "manifest.csv", f"id,recordings,methods\nU1,{files['good.csv'].name},poly3\n"
    )
    for suffix, data in valid_flight_logs(root).items():
        files[f"valid{suffix}"] = root / f"valid{suffix}"
        assert files[f"valid{suffix}"].read_bytes() == data
    assert (
        run_cli(
            trainer_main, ["import", str(files["valid.ulg"]), "--channels", "all", "-o", str(root / "m.csv")]
        )
        == 0
    )
    files["multi.csv"] = root / "m_accel0.csv"
    files["fitdir"] = root / "fit"
    assert run_cli(trainer_main, ["fit", "--method", "poly3", "--channels", "all", str(files["multi.csv"]),
                                  "-o", str(files["fitdir"])]) == 0  # fmt: skip
    assert run_cli(codegen_main, ["export", str(files["fitdir"]), "--channels", "all", "--blob",
                                  "-o", str(root / "blobmod")]) == 0  # fmt: skip
    files["blob"] = root / "blobmod" / "imu_tdc.cal.bin"
    files["scheduler"] = client.scheduler.address
    return files


def _keep_finding(label: str, seed: int, source: Path, argv: list[str]) -> str:
    FINDINGS.mkdir(exist_ok=True)
    kept = FINDINGS / f"{re.sub(r'[^A-Za-z0-9_.-]+', '_', label)}.seed{seed}{source.suffix}"
    shutil.copy(source, kept)
    (kept.parent / (kept.name + ".argv")).write_text(" ".join(argv) + "\n")
    return f"{label} (seed {seed}; mutant kept as {kept})"


def _allowed_codes(command: str) -> set[int]:
    documented_failure = ("fleet", "report", "codegen verify")  # a failed unit, sign-off or verification
    return {0, EXIT_USER_ERROR} | ({1} if command.startswith(documented_failure) else set())


ASCII_NUMBER = re.compile(r"[-+]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][-+]?[0-9]+)?|[-+]?(nan|inf)", re.IGNORECASE)


def _number(cell: str) -> float:
    """A CSV cell as recording-format.md writes numbers (ASCII only), else NaN: never a silent read."""
    return float(cell) if ASCII_NUMBER.fullmatch(cell) else math.nan


def _read_csv(path: Path) -> dict[str, np.ndarray]:
    """A recording CSV's columns by name (comment lines skipped), read without the tool's reader."""
    text = path.read_bytes().decode("utf-8", errors="replace")
    lines = [line for line in text.splitlines() if line and not line.startswith("#")]
    names = lines[0].split(",")
    rows = [line.split(",") for line in lines[1:]]
    return {
        name: np.array([_number(row[k]) if k < len(row) else math.nan for row in rows], dtype=float)
        for k, name in enumerate(names)
    }


def _read_npz(path: Path) -> dict[str, np.ndarray]:
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {name: archive[name] for name in archive.files}
    except Exception:
        return {"time_s": np.array([math.nan])}
    return {
        n: (a.astype(float) if a.dtype.kind in "iuf" else np.array([math.nan])) for n, a in arrays.items()
    }


def _accepted_recording_is_possible(path: Path) -> str | None:
    """What is impossible in a recording (None: its time, temperature and acceleration columns are
    finite and within the plausibility bounds)."""
    columns = _read_npz(path) if path.suffix == ".npz" else _read_csv(path)
    for name, values in columns.items():
        if not (name == "time_s" or name.endswith(("temp_c", "_mg"))):
            continue
        if values.size == 0:
            continue
        if not np.all(np.isfinite(values)):
            return f"column {name} is not all finite"
        if name.endswith("temp_c") and (values.min() < TEMP_MIN_C or values.max() > TEMP_MAX_C):
            return f"column {name} spans {values.min():g} .. {values.max():g} degC"
        if name.endswith("_mg") and np.abs(values).max() > ACCEL_LIMIT_MG:
            return f"column {name} reaches {np.abs(values).max():g} mg"
    return None


def _accepted_model_is_possible(path: Path) -> str | None:
    low, high = load_checkpoint(path)["valid_temp_range_c"]
    if not (math.isfinite(low) and math.isfinite(high) and TEMP_MIN_C <= low <= high <= TEMP_MAX_C):
        return f"valid range {low:g} .. {high:g} degC"
    return None


def _run_one(
    label: str, seed: int, main: Main, argv: list[str], source: Path, out: Path, inputs: Path,
    capfd: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    before = hidden_files(inputs)
    capfd.readouterr()
    try:
        code = run_cli(main, argv)
    except Exception as exc:
        where = _keep_finding(label, seed, source, argv)
        raise AssertionError(f"{where}: traceback {type(exc).__name__}: {exc}") from exc
    err = capfd.readouterr().err
    problems = []
    if code not in _allowed_codes(label):
        problems.append(f"exit {code}")
    if "Traceback" in err or len([line for line in err.splitlines() if line.startswith("error:")]) > 1:
        problems.append(f"stderr not one error line: {err[-600:]!r}")
    if code == EXIT_USER_ERROR and any(out.iterdir()):
        problems.append(f"left {sorted(p.name for p in out.iterdir())}")
    leftovers = [p for p in hidden_files(out) if ".part" in p or p.endswith(".old")]
    if leftovers or hidden_files(inputs) != before:
        problems.append(f"temporary files left: {leftovers or hidden_files(inputs)}")
    if code == 0 and label.split(" <- ")[1].startswith("recording"):
        impossible = _accepted_recording_is_possible(source)
        problems += [f"silently accepted a mutant with {impossible}"] if impossible else []
    if code == 0 and (out / "r.csv").is_file():
        impossible = _accepted_recording_is_possible(out / "r.csv")
        problems += [f"silently accepted: {impossible}"] if impossible else []
    if code == 0 and (out / "m.pt").is_file():
        impossible = _accepted_model_is_possible(out / "m.pt")
        problems += [f"silently accepted: {impossible}"] if impossible else []
    if problems:
        where = _keep_finding(label, seed, source, argv)
        raise AssertionError(f"{where}: {'; '.join(problems)}")


def _fuzz_kind(
    valid: dict[str, Any], kind: str, seed: int, work: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    source, mutate, cases, count = _kinds(valid)[kind]
    rng = np.random.default_rng([seed, sorted(_kinds(valid)).index(kind)])
    original = source.read_bytes()
    for number in range(count):
        mutant_dir = work / f"m{number}"
        mutant_dir.mkdir()
        mutant = mutant_dir / source.name
        mutant.write_bytes(mutate(rng, original))
        if kind == "blob":  # a blob is read from its module folder
            shutil.copytree(
                source.parent, mutant_dir, dirs_exist_ok=True, ignore=shutil.ignore_patterns(source.name)
            )
        if kind.startswith("manifest"):  # a manifest names its recordings relative to itself
            shutil.copy(valid["good.csv"], mutant_dir / valid["good.csv"].name)
        label, main, argv = cases[int(rng.integers(len(cases)))]
        out = work / f"out{number}"
        out.mkdir()
        _run_one(
            f"{label} <- {kind} #{number}",
            seed,
            main,
            argv(valid, mutant, out),
            mutant,
            out,
            mutant_dir,
            capfd,
        )


KINDS = (
    "recording.csv", "recording.npz", "model.pt", "simulation.toml", "thresholds.toml", "manifest.toml",
    "manifest.csv", "blob", "flightlog.ulg", "flightlog.bin",
)  # fmt: skip


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("kind", KINDS)
def test_mutants_fail_cleanly_or_pass_with_possible_values(
    valid: dict[str, Any], kind: str, seed: int, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    _fuzz_kind(valid, kind, seed, tmp_path, capfd)


@pytest.mark.slow
@pytest.mark.parametrize("seed", SLOW_SEEDS)
@pytest.mark.parametrize("kind", KINDS)
def test_more_mutants(
    valid: dict[str, Any], kind: str, seed: int, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    _fuzz_kind(valid, kind, seed, tmp_path, capfd)


def _limit_address_space() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE_BYTES, ADDRESS_SPACE_BYTES))


@pytest.mark.parametrize("seed", SEEDS)
def test_a_mutant_runs_within_a_memory_limit(valid: dict[str, Any], seed: int, tmp_path: Path) -> None:
    """A mutated recording through ``fit`` (even seeds) or ``diagnose`` (odd seeds) in a child
    process under an address-space limit: exit 0 or 2, no traceback, peak resident memory under
    MAX_RSS_BYTES."""
    rng = np.random.default_rng([seed, 99])
    code = "import sys; from trainer.cli import entry; sys.argv[0] = 'trainer'; entry()"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    for command in (("fit", "diagnose")[seed % 2],):
        mutant = tmp_path / f"{command}.csv"
        mutant.write_bytes(_mutate_text(rng, valid["good.csv"].read_bytes()))
        argv = (
            ["fit", "--method", "poly3", str(mutant), "-o", str(tmp_path / "m.pt")]
            if command == "fit"
            else ["diagnose", str(mutant), "--json", str(tmp_path / "d.json")]
        )
        child = subprocess.Popen(
            [sys.executable, "-c", code, *argv], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
            preexec_fn=_limit_address_space,
        )  # fmt: skip
        assert child.stderr is not None
        err = child.stderr.read().decode(errors="replace")
        _pid, status, usage = os.wait4(child.pid, 0)
        child.returncode = os.waitstatus_to_exitcode(status)
        where = f"{command} <- seed {seed}"
        assert child.returncode in (0, EXIT_USER_ERROR) and "Traceback" not in err, (
            f"{_keep_finding(command, seed, mutant, argv)}: exit {child.returncode}: {err[-800:]}"
        )
        assert usage.ru_maxrss * 1024 < MAX_RSS_BYTES, f"{where}: peak RSS {usage.ru_maxrss / 1024:.0f} MB"
