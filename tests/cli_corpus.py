"""What the command-line robustness tests share: a small valid recording, and each command's
argument list by the kind of input it reads (see tests/robustness/test_malformed_corpus.py, tests/robustness/test_fuzz.py).

A case is ``(command label, main, argv(files, input file, output dir))``: ``files`` maps
``good.csv``, ``good.pt`` and ``module`` (a valid recording, its poly3 model and C module) to paths.
"""

from __future__ import annotations

import io
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

from codegen.cli import main as codegen_main
from tests.flightlogs import DataFlashWriter, imu_topic, write_ulog
from trainer.cli import main as trainer_main
from trainer.errors import run_cli

N_ROWS = 400  # 1 Hz: a cooling and a heating ramp of 50 degC
Main = Callable[[list[str] | None], int]
Case = tuple[str, Main, Callable[[dict, Path, Path], list[str]]]


def valid_lines() -> list[str]:
    rng = np.random.default_rng(0)
    temp = np.concatenate([np.linspace(40, -10, N_ROWS // 2), np.linspace(-10, 40, N_ROWS - N_ROWS // 2)])
    accel = 0.0002 * (temp - 15) ** 3 + 0.1 * (temp - 15) + rng.normal(0, 0.05, N_ROWS)
    return ["# sample_rate_hz=1", "time_s,temp_c,accel_mg"] + [
        f"{t:.3f},{c:.4f},{a:.5f}"
        for t, c, a in zip(np.arange(N_ROWS, dtype=float), temp, accel, strict=True)
    ]


def npz_bytes(**arrays: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)  # type: ignore[arg-type]
    return buffer.getvalue()


def with_member(data: bytes, name: str, content: bytes) -> bytes:
    buffer = io.BytesIO(data)
    with zipfile.ZipFile(buffer, "a") as archive:
        archive.writestr(name, content)
    return buffer.getvalue()


def garbage(seed: int, size: int = 3000) -> bytes:
    return bytes(np.random.default_rng(seed).integers(0, 256, size, dtype=np.uint8))


def write_file(path: Path, content: object) -> Path:
    """``content`` as the file: a dict saved with torch.save, bytes or text as they are."""
    if isinstance(content, dict):
        buffer = io.BytesIO()
        torch.save(content, buffer)
        content = buffer.getvalue()
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(str(content))
    return path


def valid_files(root: Path) -> dict[str, Path]:
    """``root`` and, in it, good.csv (:func:`valid_lines`), its poly3 model good.pt and C module."""
    good = write_file(root / "good.csv", "\n".join(valid_lines()) + "\n")
    assert run_cli(trainer_main, ["fit", "--method", "poly3", str(good), "-o", str(root / "good.pt")]) == 0
    assert run_cli(codegen_main, ["export", str(root / "good.pt"), "-o", str(root / "module")]) == 0
    return {"root": root, "good.csv": good, "good.pt": root / "good.pt", "module": root / "module"}


def valid_flight_logs(root: Path) -> dict[str, bytes]:
    """A ULog and a DataFlash log with one IMU (accelerometer and gyroscope, 600 samples at 200 Hz,
    20 to 40 degC), written into ``root`` as valid.ulg and valid.bin; returns their bytes by suffix."""
    n = 600
    time_us = (1_000_000 + np.arange(n) * 5000).astype(np.int64)
    xyz = np.random.default_rng(6).normal(0, 0.1, (n, 3))
    temp = np.linspace(20.0, 40.0, n)
    gravity = np.array([0.0, 0.0, -9.8])  # m/s^2, a level board
    ulog = write_ulog(
        root / "valid.ulg",
        [
            imu_topic("sensor_accel", 0, 1, time_us, xyz + gravity, temp),
            imu_topic("sensor_gyro", 0, 2, time_us + 37, xyz, temp),
        ],
    ).read_bytes()
    writer = DataFlashWriter()
    for k in range(n):
        writer.imu(int(time_us[k]), 0, xyz[k], xyz[k] + gravity, temp[k])
    dataflash = writer.write(root / "valid.bin").read_bytes()
    return {".ulg": ulog, ".bin": dataflash}


# ``trainer import`` of a recording this tool wrote (its CSV columns, accel_mg in mg)
IMPORT_OWN_CSV = ["--time", "time_s", "--temp", "temp_c", "--accel", "accel_mg", "--accel-unit", "mg"]


def recording_cases() -> list[Case]:
    """(command, main, argv(corpus, bad file, out dir)) of every command that reads a recording."""
    return [
        ("import", trainer_main, lambda c, f, o: ["import", str(f), "--delimiter", "comma", *IMPORT_OWN_CSV,
                                                  "-o", str(o / "r.csv")]),
        ("fit", trainer_main, lambda c, f, o: ["fit", "--method", "poly3", str(f), "-o", str(o / "m.pt")]),
        ("fit --channels", trainer_main, lambda c, f, o: ["fit", "--method", "pla", str(f), "--channels", "all",
                                                          "-o", str(o / "fit")]),
        ("evaluate", trainer_main, lambda c, f, o: ["evaluate", str(c["good.pt"]), str(f), "--out-dir", str(o / "e")]),
        ("compare", trainer_main, lambda c, f, o: ["compare", str(f), "--methods", "poly3", "--out-dir", str(o / "c")]),
        ("compare VALID", trainer_main, lambda c, f, o: ["compare", str(c["good.csv"]), str(f), "--methods",
                                                         "poly3", "--out-dir", str(o / "c")]),
        ("diagnose", trainer_main, lambda c, f, o: ["diagnose", str(f), "--json", str(o / "d.json"),
                                                    "--report", str(o / "d")]),
        ("report", trainer_main, lambda c, f, o: ["report", str(c["good.pt"]), "--recording", str(f),
                                                  "-o", str(o / "s")]),
        ("codegen verify", codegen_main, lambda c, f, o: ["verify", str(c["good.pt"]), str(c["module"]), str(f),
                                                          "--json", str(o / "v.json")]),
    ]  # fmt: skip


def model_cases() -> list[Case]:
    return [
        ("evaluate", trainer_main, lambda c, f, o: ["evaluate", str(f), str(c["good.csv"]), "--out-dir", str(o / "e")]),
        ("report", trainer_main, lambda c, f, o: ["report", str(f), "--recording", str(c["good.csv"]),
                                                  "-o", str(o / "s")]),
        ("codegen export", codegen_main, lambda c, f, o: ["export", str(f), "-o", str(o / "c")]),
        ("codegen export px4", codegen_main, lambda c, f, o: ["export", str(f), "-o", str(o / "p"), "--format",
                                                              "px4-params"]),
        ("codegen verify", codegen_main, lambda c, f, o: ["verify", str(f), str(c["module"]), str(c["good.csv"]),
                                                          "--json", str(o / "v.json")]),
    ]  # fmt: skip


def config_cases() -> list[Case]:
    return [
        ("simulate", trainer_main, lambda c, f, o: ["simulate", "--seed", "1", "--config", str(f), "--duration",
                                                    "100", "-o", str(o / "s.csv")]),
        ("diagnose --sim", trainer_main, lambda c, f, o: ["diagnose", str(c["good.csv"]), "--sim", str(f),
                                                          "--json", str(o / "d.json")]),
        ("report --config", trainer_main, lambda c, f, o: ["report", str(c["good.pt"]), "--recording",
                                                           str(c["good.csv"]), "--config", str(f), "-o", str(o / "s")]),
    ]  # fmt: skip


def hidden_files(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.rglob(".*"))
