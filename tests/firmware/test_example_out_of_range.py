"""Beyond a model's valid temperature range: what the module declares and what the GNC example does.

A cubic or physics module clamps the temperature to its valid range and keeps the edge's correction
(as PX4 and ArduPilot clamp to TMIN .. TMAX); a PLA extends its end segments, a temperature-input
DLSTM clamps T to its front end's -100 .. 200 degC only, and a recursive DLSTM or persistence module
corrects by what its raw input does (docs/firmware.md, "Outside the valid temperature range"). The
header declares it (``NAME_HOLDS_EDGE_BEYOND_RANGE``); here the declaration is checked against the
compiled module's own outputs: beyond the range, whatever the input signal and the temperature
there, the correction (input - output) is the one at the edge, or it is not.

The example (firmware_c/example) then uses, when neither model is usable in range, the one holding
its edge (the active one first; quality HELD, the module's output at the edge temperature), and the
raw value only when no model holds its edge or the holding one saturates. The example's sources are
compiled on the host with a driver written here (samples in on stdin, qualities and outputs out).
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from codegen.export import export
from codegen.hostbuild import HostModule, compile_c, load_module
from tests import testmodels as tm
from tests.repo import REPO_ROOT
from trainer.data.recording import Recording

EXAMPLE = REPO_ROOT / "firmware_c" / "example"
RATE_HZ = 200  # the example's sensor task (gnc_integration.c checks its modules against it)
WARMUP_SAMPLES = 15 * RATE_HZ  # a streaming model's warm-up in the example (firmware_c/Makefile: 15 s)
INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1

DRIVER = r"""
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "gnc_integration.h"
#include "tdc_models.h"

/* stdin: "boot p|a", "select p|a" or "s ACCEL_X ACCEL_Y TEMP"; stdout: one line per command. */
int main(void)
{
    char cmd[16];
    while (scanf("%15s", cmd) == 1) {
        if (strcmp(cmd, "s") == 0) {
            long ax;
            long ay;
            long t;
            int32_t accel[GNC_AXES];
            gnc_accel_sample_t out;
            if (scanf("%ld %ld %ld", &ax, &ay, &t) != 3) {
                return 2;
            }
            accel[0] = (int32_t)ax;
            accel[1] = (int32_t)ay;
            gnc_tdc_sensor_task(accel, (int32_t)t, &out);
            printf("%d %ld %d %ld\n", (int)out.quality[0], (long)out.accel_q4ug[0], (int)out.quality[1],
                (long)out.accel_q4ug[1]);
        } else {
            char which[16];
            const char *id;
            if (scanf("%15s", which) != 1) {
                return 2;
            }
            id = which[0] == 'p' ? primary_model_id() : alt_model_id();
            printf("%d\n", strcmp(cmd, "boot") == 0 ? gnc_tdc_boot(id) : gnc_tdc_select(id));
        }
    }
    {
        const gnc_tdc_health_t *h = gnc_tdc_health();
        printf("health fallback %lu held %lu raw %lu\n", (unsigned long)h->fallback, (unsigned long)h->held,
            (unsigned long)h->raw);
    }
    return 0;
}
"""


def recording(top_c: float, seed: int) -> Recording:
    """Two minutes at 200 Hz, -10 .. top_c degC, a smooth drift plus noise (mg)."""
    rng = np.random.default_rng(seed)
    temp = np.linspace(-10.0, top_c, 24_000)
    signal = 0.02 * (temp - 20.0) + 1e-4 * (temp - 20.0) ** 2 + rng.normal(0, 0.01, temp.size)
    return Recording(
        {"time_s": np.arange(temp.size) / RATE_HZ, "temp_c": temp, "accel_mg": signal},
        {"sample_rate_hz": str(RATE_HZ)},
        f"edge-{seed}",
    )


@pytest.fixture(scope="module")
def recs() -> dict[str, Recording]:
    return {"wide": recording(50.0, 5), "narrow": recording(30.0, 6)}


@pytest.fixture(scope="module")
def modules(
    recs: dict[str, Recording], tmp_path_factory: pytest.TempPathFactory
) -> dict[str, tuple[Path, str]]:
    """key -> (module directory, NAME), each exported once."""
    specs = {  # key: (method, recording, schedule)
        "poly3": ("poly3", "wide", "step"),
        "poly3_narrow": ("poly3", "narrow", "step"),
        "physics": ("physics", "wide", "step"),
        "pla": ("pla", "wide", "step"),
        "dlstm": ("dlstm", "wide", "step"),
        "dlstm_spread": ("dlstm", "wide", "spread"),
        "dlstm_temp": ("dlstm-temp", "wide", "step"),
        "persistence": ("persistence", "wide", "step"),
    }
    folder = tmp_path_factory.mktemp("edge-modules")
    out = {}
    for key, (method, rec, schedule) in specs.items():
        tm.save_checkpoint(tm.checkpoint_for(method, recs[rec], hidden=4, layers=2), folder / f"{key}.pt")
        name = f"m_{key}"
        export(folder / f"{key}.pt", folder / key, name=name, schedule=schedule)
        out[key] = (folder / key, name)
    return out


def macro(header: str, name: str, key: str) -> int:
    found = re.search(rf"^#define {name.upper()}_{key} (-?\d+)u?\b", header, re.MULTILINE)
    assert found is not None, f"{name}.h: no {key}"
    return int(found.group(1))


def header_of(module: tuple[Path, str]) -> str:
    directory, name = module
    return (directory / f"{name}.h").read_text()


def corrections(host: HostModule, accel: np.ndarray, temp: np.ndarray) -> np.ndarray:
    """input - output of a fresh instance over the stream."""
    return accel.astype(np.int64) - host.run(host.new_state(), accel, temp).astype(np.int64)


# family -> whether it holds its edge, as docs/firmware.md describes each (independent of the renderer)
EXPECTED_HOLDS = {
    "poly3": True,
    "physics": True,
    "pla": False,
    "dlstm": False,
    "dlstm_spread": False,
    "dlstm_temp": False,
    "persistence": False,
}


@pytest.mark.parametrize("key", sorted(EXPECTED_HOLDS))
def test_the_header_says_whether_the_module_holds_its_edge_as_its_c_does(
    key: str, modules: dict[str, tuple[Path, str]]
) -> None:
    directory, name = modules[key]
    header = header_of(modules[key])
    declared = macro(header, name, "HOLDS_EDGE_BEYOND_RANGE")
    assert declared in (0, 1)
    lo, hi = macro(header, name, "VALID_TEMP_MIN_MDEGC"), macro(header, name, "VALID_TEMP_MAX_MDEGC")
    host = load_module(directory, name)
    rng = np.random.default_rng(3)
    n = 2_000  # ten network steps of a streaming model at 200 Hz
    held = []
    for edge, sign in ((hi, 1), (lo, -1)):
        beyond = edge + sign * rng.integers(1, 30_000, n)  # mdegC, 1 m°C .. 30 °C beyond the edge
        # two different signals (1/16 ug) near the training data's: +3 mg and -3 mg, +-1 mg of noise
        signal_a = 48_000 + rng.integers(-16_000, 16_000, n)
        signal_b = -48_000 + rng.integers(-16_000, 16_000, n)
        at_beyond = corrections(host, signal_a, beyond)
        at_edge = corrections(host, signal_b, np.full(n, edge))
        held.append(bool(np.array_equal(at_beyond, at_edge)))
    assert held[0] == held[1], f"{key}: holds beyond one end of its range and not the other"
    assert declared == int(held[0]), (
        f"{key}: the header says {declared}, the compiled module {'holds' if held[0] else 'does not hold'} its edge"
    )
    assert held[0] is EXPECTED_HOLDS[key]
    comment = next(line for line in header.splitlines() if "_HOLDS_EDGE_BEYOND_RANGE" in line)
    assert ("holds the edge's correction" in comment) is held[0], comment


class Example:
    """The GNC example's sources built on the host for two modules, driven through stdin."""

    def __init__(self, primary: tuple[Path, str], alt: tuple[Path, str], folder: Path) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "driver.c").write_text(DRIVER)
        defines = []
        for role, (directory, name) in (("PRIMARY", primary), ("ALT", alt)):
            streaming = f"#define {name.upper()}_DECIMATION " in header_of((directory, name))
            defines += [
                f"-D{role}_WARMUP_S={15 if streaming else 0}u",  # as firmware_c/Makefile sets it
                f"-DBIND_{role}={name}",
                f"-DBIND_{role}_U={name.upper()}",
                f'-DBIND_{role}_HEADER="{name}.h"',
            ]
        self.binary = folder / "example_driver"
        compile_c(
            [
                folder / "driver.c",
                EXAMPLE / "gnc_integration.c",
                primary[0] / f"{primary[1]}.c",
                alt[0] / f"{alt[1]}.c",
            ],
            self.binary,
            include_dirs=[primary[0], alt[0], EXAMPLE],
            flags=("-O2", *defines),
        )
        self.qualities = {
            int(v): k
            for k, v in re.findall(r"GNC_ACCEL_(\w+) = (\d+)", (EXAMPLE / "gnc_integration.h").read_text())
        }

    def run(self, commands: list[str]) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
        """Qualities and outputs per sample, shape (samples, axes), and the health counters."""
        result = subprocess.run(
            [str(self.binary)], input="\n".join(commands) + "\n", capture_output=True, text=True, check=True
        )
        lines = result.stdout.splitlines()
        health = dict(zip(lines[-1].split()[1::2], map(int, lines[-1].split()[2::2]), strict=True))
        samples = [line.split() for line in lines[:-1] if len(line.split()) == 4]
        quality = np.array([[self.qualities[int(s[0])], self.qualities[int(s[2])]] for s in samples])
        out = np.array([[int(s[1]), int(s[3])] for s in samples], dtype=np.int64)
        return quality, out, health


def stream(segments: list[tuple[int, int]], seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(samples, temperature mdegC) segments -> accelerations of both axes (1/16 ug) and temperatures."""
    rng = np.random.default_rng(seed)
    temp = np.concatenate([np.full(n, t) for n, t in segments])
    accel = rng.integers(-16_000, 16_000, (temp.size, 2))  # +-1 mg, as the models were trained on
    return accel, temp


def commands_for(accel: np.ndarray, temp: np.ndarray, switches: dict[int, str], boot: str = "p") -> list[str]:
    lines = [f"boot {boot}"]
    for k in range(temp.size):
        if k in switches:
            lines.append(f"select {switches[k]}")
        lines.append(f"s {accel[k, 0]} {accel[k, 1]} {temp[k]}")
    return lines


def outputs_at(module: tuple[Path, str], accel: np.ndarray, temp: np.ndarray) -> np.ndarray:
    """The module's outputs on each axis (its own instance, every sample, as the example steps it)."""
    host = load_module(*module)
    return np.column_stack(
        [host.run(host.new_state(), accel[:, axis], temp) for axis in range(accel.shape[1])]
    )


def limits(module: tuple[Path, str]) -> tuple[int, int]:
    header = header_of(module)
    return macro(header, module[1], "VALID_TEMP_MIN_MDEGC"), macro(header, module[1], "VALID_TEMP_MAX_MDEGC")


@pytest.mark.parametrize("holder", ["poly3", "physics"])
def test_beyond_both_ranges_the_example_uses_the_model_holding_its_edge(
    holder: str, modules: dict[str, tuple[Path, str]], tmp_path: Path
) -> None:
    """A recursive DLSTM (primary, active) and a cubic or physics model over the same range: beyond
    it the output is the holder's at the edge temperature (quality HELD), not raw, at both ends, and
    after a switch to the holder too; in range the active model is used again."""
    example = Example(modules["dlstm"], modules[holder], tmp_path / "build")
    lo, hi = limits(modules[holder])
    assert limits(modules["dlstm"]) == (lo, hi)
    inside = 20_000
    accel, temp = stream(
        [
            (WARMUP_SAMPLES + 200, inside),
            (400, hi + 7_000),
            (400, inside),
            (400, lo - 12_000),
            (400, hi + 1),
            (200, inside),
        ],
        seed=1,
    )
    switch = WARMUP_SAMPLES + 200 + 400 + 400 + 400
    quality, out, health = example.run(commands_for(accel, temp, {switch: "a"}))
    assert out.shape == accel.shape

    at_edge = outputs_at(modules[holder], accel, np.clip(temp, lo, hi))  # the holder at the edge temperature
    beyond = (temp < lo) | (temp > hi)
    warm = np.arange(temp.size) >= WARMUP_SAMPLES
    assert (quality[beyond] == "HELD").all(), set(quality[beyond].ravel())
    np.testing.assert_array_equal(out[beyond], at_edge[beyond])
    assert not np.array_equal(out[beyond], accel[beyond])  # not the raw value
    assert (quality[~beyond & ~warm] == "FALLBACK").all()  # the DLSTM warming up: the holder in range
    active_primary = np.arange(temp.size) < switch
    assert (quality[~beyond & warm & active_primary] == "COMPENSATED").all()
    assert (quality[~beyond & ~active_primary] == "COMPENSATED").all()  # the holder, now active
    assert health["held"] == int(beyond.sum()) * 2 and health["raw"] == 0


def test_beyond_both_ranges_the_example_passes_raw_when_no_model_holds_its_edge(
    modules: dict[str, tuple[Path, str]], tmp_path: Path
) -> None:
    """A recursive DLSTM and a PLA (which extrapolates): raw beyond the range, whichever is active."""
    example = Example(modules["dlstm"], modules["pla"], tmp_path / "build")
    lo, hi = limits(modules["pla"])
    accel, temp = stream(
        [(WARMUP_SAMPLES + 200, 20_000), (400, hi + 7_000), (400, lo - 5_000), (400, hi + 3_000)], seed=2
    )
    switch = WARMUP_SAMPLES + 200 + 800
    quality, out, health = example.run(commands_for(accel, temp, {switch: "a"}))
    beyond = (temp < lo) | (temp > hi)
    assert (quality[beyond] == "RAW").all(), set(quality[beyond].ravel())
    np.testing.assert_array_equal(out[beyond], accel[beyond])
    assert health["held"] == 0 and health["raw"] == int(beyond.sum()) * 2


def test_in_range_beats_held_and_the_active_model_holds_first(
    modules: dict[str, tuple[Path, str]], tmp_path: Path
) -> None:
    """Two cubics, the active one fitted up to 30 degC, the other up to 50 degC: at 40 degC the other
    one in range (FALLBACK), at 60 degC the active one held at its own edge (30 degC), not the other
    at 50; after a switch, the other one held at 50 degC."""
    narrow, wide = modules["poly3_narrow"], modules["poly3"]
    example = Example(narrow, wide, tmp_path / "build")
    n_lo, n_hi = limits(narrow)
    w_lo, w_hi = limits(wide)
    assert n_hi + 5_000 < w_hi
    between, above = (n_hi + w_hi) // 2, w_hi + 10_000
    accel, temp = stream([(300, 0), (300, between), (300, above), (300, above)], seed=3)
    quality, out, health = example.run(commands_for(accel, temp, {900: "a"}))
    narrow_edge = outputs_at(narrow, accel, np.clip(temp, n_lo, n_hi))
    wide_edge = outputs_at(wide, accel, np.clip(temp, w_lo, w_hi))
    parts = [slice(0, 300), slice(300, 600), slice(600, 900), slice(900, 1200)]
    assert (quality[parts[0]] == "COMPENSATED").all()
    np.testing.assert_array_equal(out[parts[0]], narrow_edge[parts[0]])
    assert (quality[parts[1]] == "FALLBACK").all()
    np.testing.assert_array_equal(out[parts[1]], wide_edge[parts[1]])
    assert (quality[parts[2]] == "HELD").all()
    np.testing.assert_array_equal(out[parts[2]], narrow_edge[parts[2]])  # the active one, at 30 degC
    assert not np.array_equal(out[parts[2]], wide_edge[parts[2]])
    assert (quality[parts[3]] == "HELD").all()
    np.testing.assert_array_equal(out[parts[3]], wide_edge[parts[3]])  # now active, at 50 degC
    assert health == {"fallback": 600, "held": 1200, "raw": 0}


def test_a_holding_model_that_saturates_is_not_used(
    modules: dict[str, tuple[Path, str]], tmp_path: Path
) -> None:
    """Beyond the range, an input at the int32 limit saturates the cubic's output: raw, not held."""
    example = Example(modules["dlstm"], modules["poly3"], tmp_path / "build")
    hi = limits(modules["poly3"])[1]
    host = load_module(*modules["poly3"])
    drift = -host.step(host.new_state(), 0, hi)  # the correction at the edge
    assert drift != 0
    extreme = INT32_MIN if drift > 0 else INT32_MAX  # input - drift leaves int32
    accel, temp = stream([(WARMUP_SAMPLES + 10, 20_000), (50, hi + 5_000)], seed=4)
    accel[-50:, 0] = extreme
    quality, out, _ = example.run(commands_for(accel, temp, {}))
    assert (quality[-50:, 0] == "RAW").all() and (out[-50:, 0] == extreme).all()
    assert (quality[-50:, 1] == "HELD").all()  # the other axis, not saturated
