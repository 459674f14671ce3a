"""A cubic module's header states the drift its step computes, where the firmware engineer reads it:
the formula in the channel's unit, the clamp, T_ref, the coefficients in physical units, the fixed
point (the Q format of d0..d3 and of u, the rounding) and where the cost is measured.

Before, ``accel_z_tdc.h`` gave units, the valid range and the state's ownership but neither the
formula nor its coefficients, and the Q format only in the .c's comment. Here the coefficients are
parsed back from the header text and must give the float model's own drift (``drift_at``) to their
printed precision, beyond the range too (the clamp); the Q format the header states must be the one
the .c's code (not its comments) computes with. The IMU module's header says the same per channel.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import torch

from codegen.cli import main as codegen_main
from codegen.export import export
from tests import testmodels as tm
from trainer.baselines.poly3 import CubicPolynomial
from trainer.checkpoint import load_model

NUMBER = r"(-?[0-9][0-9.]*(?:e[-+]?[0-9]+)?)"
UNITS = {"mg": "mg", "dps": "deg/s", "pa": "Pa"}
LSB_PER_UNIT = 16000  # the step's LSB is 1/16000 of the channel's unit (docs/codegen.md, "Units")
RANGE_C = (-17.60306168, 73.96678925)  # the bundled real run's
# temperatures (degC) to compare at: inside the range, at T_ref, and beyond both ends (clamped)
TEMPS_C = np.array([-40.0, -17.6, -5.25, 0.0, 12.3456, 28.1818, 40.0, 55.5, 73.9, 90.0])


@dataclass(frozen=True)
class Case:
    channel: str
    unit: str
    coefficients: tuple[float, float, float, float]  # c0..c3 of (T - t_ref)^k, the unit / degC^k
    degree: int
    t_ref_c: float  # not a whole mdegC: the C's T_ref is rounded and the cubic re-expanded about it


CASES = {
    "accel-poly3": Case(
        "accel0_z", "mg", (-0.0123, -0.225499764, 0.0204153721, -1.21315194e-4), 3, 28.181863785
    ),
    "gyro-poly2": Case("gyro0_x", "dps", (0.000731, 0.00605212, 3.5654e-4, 0.0), 2, 28.181863785),
    "baro-poly1": Case("baro0", "pa", (1.5, -2.75, 0.0, 0.0), 1, 21.0004),
}


def _checkpoint(case: Case, path: Path) -> Path:
    payload = {
        "coefficients_mg": torch.tensor(case.coefficients, dtype=torch.float64),
        "t_ref_c": case.t_ref_c,
        "temp_range_c": list(RANGE_C),
        "remove_median": False,
        "median_kernel": 31,
        "n_bins": 2000,
        "degree": case.degree,
    }
    checkpoint = tm.checkpoint_dict("poly3", payload, RANGE_C)
    checkpoint["train_stats"] = {"channel": case.channel, "unit": case.unit}
    tm.save_checkpoint(checkpoint, path)
    return path


def _comment(text: str) -> str:
    """The header's first comment block, one line per comment line, without the leading " * "."""
    block = text[text.index("/*") : text.index("*/")]
    return "\n".join(line.removeprefix(" *").strip() for line in block.splitlines())


def _code(text: str) -> str:
    """C source without its comments (what the compiler sees)."""
    return re.sub(r"/\*.*?\*/", "", text, flags=re.S)


@dataclass(frozen=True)
class Stated:
    """What a header says of one cubic: T_ref (degC), the clamp (degC), c0..c_degree (unit / degC^k),
    and the fixed point: Q of d0..d3, u's shift, T_ref in mdegC."""

    t_ref_c: float
    clamp_c: tuple[float, float] | None
    coefficients: dict[int, float]
    q: int
    u_shift: int
    t_ref_mdegc: int

    def drift(self, temp_c: np.ndarray, clamp_c: tuple[float, float]) -> np.ndarray:
        d_t = np.clip(temp_c, *clamp_c) - self.t_ref_c
        return sum((c * d_t**k for k, c in self.coefficients.items()), np.zeros_like(temp_c))

    def tolerance(self, temp_c: np.ndarray, clamp_c: tuple[float, float]) -> np.ndarray:
        """What 9 significant digits of each coefficient allow (half a unit of the 9th digit, doubled)."""
        d_t = np.abs(np.clip(temp_c, *clamp_c) - self.t_ref_c)
        return sum(
            (abs(c) * d_t**k * 1e-8 for k, c in self.coefficients.items()), np.full_like(temp_c, 1e-15)
        )


def _coefficients(lines: list[str], unit: str) -> dict[int, float]:
    """``cK = value unit/degC^K`` lines, each in the channel's unit per degC^K."""
    found: dict[int, float] = {}
    for line in lines:
        m = re.fullmatch(rf"c([0-3]) = {NUMBER} (\S+)", line)
        if m is None:
            continue
        k = int(m.group(1))
        per = "" if k == 0 else ("/degC" if k == 1 else f"/degC^{k}")
        assert m.group(3) == unit + per, line
        assert len(re.sub(r"e.*|[-.]", "", m.group(2)).lstrip("0")) <= 9, line  # %.9g
        found[k] = float(m.group(2))
    return found


def _module_stated(header: str, unit: str, degree: int) -> Stated:
    comment = _comment(header)
    flat = " ".join(comment.split())
    terms = ["c0", "c1 dT", *(f"c{k} dT^{k}" for k in range(2, degree + 1))]
    assert f"out = raw - drift, drift = {' + '.join(terms)}, dT = T - T_ref," in flat
    assert f"in {unit} (raw = " in flat
    t_ref = re.search(rf"T_ref = {NUMBER} degC", flat)
    clamp = re.search(rf"clamped to \[T_min, T_max\] = \[{NUMBER}, {NUMBER}\] degC", flat)
    q = re.search(r"d0\.\.d3 int32 Q([0-9]+) of the output LSB", flat)
    u = re.search(rf"u = \(T - T_ref\) / 2\^([0-9]+) with T, T_ref = {NUMBER} in mdegC", flat)
    assert t_ref and clamp and q and u, flat
    assert "Cost: 3 int64 multiplications per sample" in flat and "bench/bench_cortex_m.py" in flat
    assert "every rounding half away from zero" in flat
    return Stated(
        float(t_ref.group(1)),
        (float(clamp.group(1)), float(clamp.group(2))),
        _coefficients(comment.splitlines(), unit),
        int(q.group(1)),
        int(u.group(1)),
        int(u.group(2)),
    )


@dataclass(frozen=True)
class CodeSays:
    """What the C's code computes with: the coefficient table, Q, u's shift, T_ref and clamp (mdegC)."""

    d: tuple[int, ...]
    q: int
    u_shift: int
    t_ref_mdegc: int
    clamp_mdegc: tuple[int, int]


def _module_code(source: str) -> CodeSays:
    code = _code(source)
    table = re.search(r"_coefficient\[4\] = \{([^}]*)\}", code)
    shifts = set(re.findall(r"tdck_rshift_round64\(acc \* u, ([0-9]+)u\)", code))
    q = re.findall(r"tdck_rshift_round64\(acc, ([0-9]+)u\)", code)
    t_ref = re.search(r"\(int64_t\)t - (-?[0-9]+);", code)
    clamp = re.search(r"tdck_clamp32_flag\(temp_mdegc, (-?[0-9]+), (-?[0-9]+),", code)
    assert table and len(shifts) == 1 and len(q) == 1 and t_ref and clamp, code
    return CodeSays(
        tuple(int(v) for v in table.group(1).replace(",", " ").split()),
        int(q[0]),
        int(shifts.pop()),
        int(t_ref.group(1)),
        (int(clamp.group(1)), int(clamp.group(2))),
    )


def _inside(temps: np.ndarray, clamp_c: tuple[float, float]) -> np.ndarray:
    """Where the temperatures lie strictly inside the clamp (there, no edge rounding)."""
    lo, hi = clamp_c
    return (temps > lo) & (temps < hi)


def _float_model(path: Path) -> CubicPolynomial:
    model, _ = load_model(path)
    assert isinstance(model, CubicPolynomial)
    return model


@pytest.mark.parametrize("key", sorted(CASES))
def test_the_header_s_formula_and_coefficients_give_the_float_model_s_drift(key: str, tmp_path: Path) -> None:
    case = CASES[key]
    path = _checkpoint(case, tmp_path / "m.pt")
    export(path, tmp_path / "out", name="tdc_x")
    header = (tmp_path / "out" / "tdc_x.h").read_text()
    stated = _module_stated(header, UNITS[case.unit], case.degree)
    assert sorted(stated.coefficients) == list(range(case.degree + 1))
    assert stated.clamp_c is not None
    model = _float_model(path)
    assert stated.clamp_c == pytest.approx(model.temp_range_c, abs=5e-4)  # whole mdegC
    expected = model.drift_at(TEMPS_C)
    said = stated.drift(TEMPS_C, stated.clamp_c)
    # the clamp in whole mdegC moves the held edge by at most its slope x 0.5 mdegC
    edge = np.abs(np.clip(TEMPS_C, *model.temp_range_c) - np.clip(TEMPS_C, *stated.clamp_c))
    slope = sum(abs(c) * k * 100.0 ** (k - 1) for k, c in stated.coefficients.items() if k)
    np.testing.assert_array_less(
        np.abs(said - expected), stated.tolerance(TEMPS_C, stated.clamp_c) + edge * slope
    )
    inside = _inside(TEMPS_C, stated.clamp_c)
    np.testing.assert_array_less(
        np.abs(said - expected)[inside], stated.tolerance(TEMPS_C, stated.clamp_c)[inside]
    )
    # the header's T_ref is the C's, in whole mdegC, not the float model's own
    assert stated.t_ref_mdegc == round(case.t_ref_c * 1000)
    assert stated.t_ref_c == pytest.approx(stated.t_ref_mdegc / 1000, abs=1e-12)
    if case.degree < 3:
        zeros = " = ".join(f"c{k}" for k in range(case.degree + 1, 4))
        assert f"order {case.degree} ({zeros} = 0):" in header


@pytest.mark.parametrize("key", sorted(CASES))
def test_the_header_s_q_format_is_the_one_the_c_computes_with(key: str, tmp_path: Path) -> None:
    case = CASES[key]
    path = _checkpoint(case, tmp_path / "m.pt")
    export(path, tmp_path / "out", name="tdc_x")
    stated = _module_stated((tmp_path / "out" / "tdc_x.h").read_text(), UNITS[case.unit], case.degree)
    code = _module_code((tmp_path / "out" / "tdc_x.c").read_text())
    assert (stated.q, stated.u_shift, stated.t_ref_mdegc) == (code.q, code.u_shift, code.t_ref_mdegc)
    assert stated.clamp_c is not None
    assert tuple(round(v * 1000) for v in stated.clamp_c) == code.clamp_mdegc
    # and the header's d_k = c_k 16000 (2^u_shift / 1000)^k 2^Q holds for the .c's table
    scale = [LSB_PER_UNIT * (2**code.u_shift / 1000) ** k * 2**code.q for k in range(4)]
    for k, d in enumerate(code.d):
        c = stated.coefficients.get(k, 0.0)
        assert abs(c * scale[k] - d) <= 0.5 + abs(d) * 1e-8, (k, c, d)
    # the manifest states the same format, from the same declaration
    manifest = (tmp_path / "out" / "tdc_x.manifest.json").read_text()
    assert f'"u": "(T - T_ref) / 2^{code.u_shift}"' in manifest
    assert f'"coefficients": "int32 Q{code.q} output LSB' in manifest


def test_the_export_is_deterministic(tmp_path: Path) -> None:
    path = _checkpoint(CASES["gyro-poly2"], tmp_path / "m.pt")
    texts = []
    for out in ("a", "b"):
        export(path, tmp_path / out, name="tdc_x")
        texts.append({p.name: p.read_bytes() for p in sorted((tmp_path / out).iterdir())})
    assert texts[0] == texts[1]


def _imu_channels(header: str) -> dict[str, list[str]]:
    """The IMU header's channel section: each channel's lines, by name."""
    out: dict[str, list[str]] = {}
    current = None
    for line in _comment(header).splitlines():
        m = re.fullmatch(r"[0-9]+: (\w+) \[.*", line)
        if m:
            current = m.group(1)
            out[current] = []
        elif current is not None and line.startswith("Units:"):
            break
        elif current is not None:
            out[current].append(line)
    return out


def _imu_records(source: str) -> dict[str, CodeSays]:
    """Each channel's record of the compiled-in calibration in the IMU .c (the comment names it)."""
    out = {}
    pattern = (
        r"\{ /\* [0-9]+: (\w+) .*?\*/\s*\{[^}]*\},\s*\{[^}]*\},\s*\{[^}]*\},\s*\{([^}]*)\},\s*"
        r"(-?[0-9]+), (-?[0-9]+), (-?[0-9]+),\s*([0-9]+)u, ([0-9]+)u, ([0-9]+)u, ([0-9]+)u"
    )
    for m in re.finditer(pattern, source):
        name, table, lo, hi, t_ref, kind, _sensor, frac, u_shift = m.groups()
        if kind == "1":  # NAME_KIND_CUBIC
            d = tuple(int(v) for v in table.replace(",", " ").split())
            out[name] = CodeSays(d, int(frac), int(u_shift), int(t_ref), (int(lo), int(hi)))
    return out


def test_the_imu_header_states_each_cubic_channel_s_drift_and_format(tmp_path: Path) -> None:
    paths = [
        _checkpoint(CASES[key], tmp_path / f"{CASES[key].channel}.pt")
        for key in ("accel-poly3", "gyro-poly2")
    ]
    pla = tm.checkpoint_for("pla", tm.ramp_recording(3, "pla-ch"))
    pla["train_stats"] = {"channel": "accel1_x", "unit": "mg"}  # another sensor: its own valid range
    tm.save_checkpoint(pla, tmp_path / "accel1_x.pt")
    paths.append(tmp_path / "accel1_x.pt")
    out = tmp_path / "imu"
    assert codegen_main(["export", *map(str, paths), "-o", str(out), "--name", "imu0"]) == 0
    header = (out / "imu0.h").read_text()
    channels = _imu_channels(header)
    records = _imu_records((out / "imu0.c").read_text())
    assert sorted(records) == ["accel0_z", "gyro0_x"]
    assert not any(line.startswith("drift") for line in channels["accel1_x"])  # a PLA channel: none
    for key in ("accel-poly3", "gyro-poly2"):
        case = CASES[key]
        lines = channels[case.channel]
        unit = UNITS[case.unit]
        flat = " ".join(lines)
        terms = ["c0", "c1 dT", *(f"c{k} dT^{k}" for k in range(2, case.degree + 1))]
        m = re.search(
            rf"drift \[{re.escape(unit)}\] = {re.escape(' + '.join(terms))}, dT = T - {NUMBER} degC", flat
        )
        fixed = re.search(
            rf"d0\.\.d3 int32 Q([0-9]+) output LSB of u\^k, u = \(T - T_ref\) / 2\^([0-9]+), T_ref = {NUMBER} mdegC",
            flat,
        )
        assert m and fixed, flat
        record = records[case.channel]
        assert (int(fixed.group(1)), int(fixed.group(2)), int(fixed.group(3))) == (
            record.q,
            record.u_shift,
            record.t_ref_mdegc,
        )
        stated = Stated(
            float(m.group(1)), None, _coefficients(lines, unit), record.q, record.u_shift, record.t_ref_mdegc
        )
        assert sorted(stated.coefficients) == list(range(case.degree + 1))
        clamp_c = (record.clamp_mdegc[0] / 1000, record.clamp_mdegc[1] / 1000)
        model = _float_model(tmp_path / f"{case.channel}.pt")
        inside = TEMPS_C[_inside(TEMPS_C, clamp_c)]
        np.testing.assert_array_less(
            np.abs(stated.drift(inside, clamp_c) - model.drift_at(inside)), stated.tolerance(inside, clamp_c)
        )
    flat = " ".join(_comment(header).split())
    assert "A cubic channel computes its one-channel module's step" in flat
    assert "Cost: 3 int64 multiplications per channel and sample" in flat


def test_an_imu_header_without_a_cubic_channel_says_nothing_of_cubics(tmp_path: Path) -> None:
    paths = []
    for channel in ("accel0_x", "accel0_y"):
        pla = tm.checkpoint_for("pla", tm.ramp_recording(3, "pla-only"))
        pla["train_stats"] = {"channel": channel, "unit": "mg"}
        tm.save_checkpoint(pla, tmp_path / f"{channel}.pt")
        paths.append(str(tmp_path / f"{channel}.pt"))
    out = tmp_path / "imu"
    assert codegen_main(["export", *paths, "-o", str(out), "--name", "imu0"]) == 0
    header = (out / "imu0.h").read_text()
    assert "A cubic channel" not in header and "drift [" not in header


def test_where_the_header_says_the_cost_is_measured_exists(tmp_path: Path) -> None:
    """The header names benches and doc sections, no figure: each must be there."""
    path = _checkpoint(CASES["accel-poly3"], tmp_path / "m.pt")
    export(path, tmp_path / "out", name="tdc_x")
    flat = " ".join(_comment((tmp_path / "out" / "tdc_x.h").read_text()).split())
    cost = flat[flat.index("Cost:") : flat.index("Rate contract:")]
    root = Path(__file__).resolve().parents[2]
    benches = re.findall(r"bench/\w+\.py", cost)
    assert benches and all((root / b).is_file() for b in benches), benches
    sections = re.findall(r'(docs/\w+\.md), "([^"]+)"(?: and "([^"]+)")?', cost)
    assert len(sections) == 2, cost
    for doc, *titles in sections:
        headings = re.findall(r"^#+ (.+)$", (root / doc).read_text(), flags=re.M)
        assert all(t in headings for t in titles if t), (doc, titles)
