"""codegen/family.py is the one list of C families: a new family is one unit plus one register() call.

A throwaway family (a line in temperature, its C template written here) is registered with a
throwaway method; export and verify then handle it without any other file knowing it.
"""

from __future__ import annotations

import json
import re
import shutil
from collections.abc import Iterator
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from codegen import family
from codegen.cli import main as codegen_main
from codegen.fixedpoint import INT32_MAX, round_half_away, rshift_round
from codegen.golden import GoldenBase
from codegen.imu import encode_blob, export_imu, imu_golden
from codegen.imu_record import ChannelTables
from codegen.imu_verify import host_run
from codegen.manifest import memoryless_rates
from codegen.quantize import ACCEL_PER_MG, TEMP_LIMITS_MDEGC, Limits
from codegen.render import FLAGS, TEMPLATES
from codegen.verify import verify
from tests.methods.test_method_registry import LinearInTemperature
from trainer import methods
from trainer.checkpoint import save_model
from trainer.cli import main as trainer_main
from trainer.errors import UserError, run_cli
from trainer.fields import DottedFields
from trainer.train_stats import TrainStats

NAME = "line-c"
FRAC = 16  # the line's fractional bits (a fixed format keeps the throwaway quantiser short)

TEMPLATE = """\
/* ---- a line in T (the throwaway family of tests/export/test_codegen_family_registry.py) ---- */
void {{ name }}_reset({{ name }}_state_t *state)
{
    (void)state;
}

void {{ name }}_init({{ name }}_state_t *state)
{
    state->flags = 0u;
    state->samples = 0u;
    {{ name }}_reset(state);
}

int32_t {{ name }}_step({{ name }}_state_t *state, int32_t accel_q4ug, int32_t temp_mdegc)
{
    int32_t t;
    int32_t drift;
    {{ p }}check_range(temp_mdegc, &state->flags);
    t = tdck_clamp32_flag(temp_mdegc, {{ temp_lo }}, {{ temp_hi }}, &state->flags, {{ NAME }}_FLAG_INPUT_CLAMPED);
    drift = tdck_sat32_flag(tdck_rshift_round64(INT64_C({{ slope }}) * t + INT64_C({{ offset }}), {{ frac }}u),
        &state->flags, {{ NAME }}_FLAG_SATURATED);
    return tdck_output(&state->samples, &state->flags, {{ NAME }}_FLAG_SATURATED, accel_q4ug, drift);
}
"""


@dataclass(frozen=True)
class LineSpec:
    method: str
    slope_mg_per_c: float
    offset_mg: float


@dataclass(frozen=True)
class QLine:
    method: str
    limits: Limits
    slope_q: int  # accel LSB per mdegC, Q(FRAC)
    offset_q: int  # accel LSB, Q(FRAC)


def _parse(root: DottedFields, payload: DottedFields, method: str) -> LineSpec:
    slope, offset = payload.numbers("coefficients", 2)
    return LineSpec(method, slope, offset)


def _quantise(spec: LineSpec, limits: Limits, schedule: str) -> QLine:
    slope = round_half_away(Fraction(spec.slope_mg_per_c) * ACCEL_PER_MG / 1000 * (1 << FRAC))
    offset = round_half_away(Fraction(spec.offset_mg) * ACCEL_PER_MG * (1 << FRAC))
    assert abs(slope) <= INT32_MAX and abs(offset) < 1 << 40  # the product stays inside int64
    return QLine(spec.method, limits, slope, offset)


class GoldenLine(GoldenBase):
    model: QLine

    def _run(self, accel: np.ndarray, temp: np.ndarray) -> np.ndarray:
        m = self.model
        t = self._clamp(temp, m.limits.temp_lo_mdegc, m.limits.temp_hi_mdegc)
        return self._output(accel, self._sat(rshift_round(m.slope_q * t + m.offset_q, FRAC)))


# The line's channel of an IMU module: its record (the slope and offset in the record's first
# piecewise-linear interval) and its macros, called by imu.h.j2 / imu.c.j2 at their places.
IMU_SNIPPETS = """\
{% macro kind_doc() %}; kind {{ kind }}: a line in T (the throwaway family){% endmacro %}
{% macro c_functions(kc) %}
/* A line in T, T clamped to the front end's range (the throwaway family). */
static int32_t {{ p }}line(const {{ name }}_channel_t *ch, int32_t temp_mdegc, uint32_t *flags)
{
    int32_t t = tdck_clamp32_flag(temp_mdegc, ch->clip_lo, ch->clip_hi, flags, {{ NAME }}_FLAG_INPUT_CLAMPED);
    return tdck_sat32_flag(tdck_rshift_round64((int64_t)ch->slope[0] * t + ch->intercept[0], ch->frac),
        flags, {{ NAME }}_FLAG_SATURATED);
}

{% endmacro %}
{% macro drift() %}{{ p }}line(ch, temp_mdegc[ch->sensor], flags){% endmacro %}
"""
LINE_KIND = 9


def _line_record(m: QLine, sensor: int) -> ChannelTables:
    lo, hi = m.limits.temp_lo_mdegc, m.limits.temp_hi_mdegc
    return ChannelTables(LINE_KIND, sensor, FRAC, 0, lo, hi, 0, (0, 0, 0, 0), (), (m.slope_q,), (m.offset_q,))


def _register_line(directory: Path, imu: family.ImuForm | None) -> family.CFamily:
    template = directory / "line.c.j2"
    template.write_text(TEMPLATE, encoding="utf-8")
    methods.register(methods.Method(NAME, LinearInTemperature, methods.MEMORYLESS, renderer=NAME))
    return family.register(
        family.CFamily(
            name=NAME,
            parse=_parse,
            quantise=_quantise,
            golden=GoldenLine,
            template=template,
            context=lambda m: {"slope": m.slope_q, "offset": m.offset_q, "frac": FRAC},
            manifest=lambda m: {"rates": memoryless_rates(), "quantisation": {"frac_bits": FRAC}},
            tables=lambda m: {},
            imu=imu,
        )
    )


@pytest.fixture
def line_family(tmp_path_factory: pytest.TempPathFactory) -> Iterator[family.CFamily]:
    yield _register_line(tmp_path_factory.mktemp("line_family"), None)
    family.unregister(NAME)
    methods.unregister(NAME)


@pytest.fixture
def line_imu_family(tmp_path_factory: pytest.TempPathFactory) -> Iterator[family.CFamily]:
    """The line with an IMU-module form: its record, its label and code, its macros."""
    directory = tmp_path_factory.mktemp("line_imu_family")
    snippets = directory / "_line_imu.j2"
    snippets.write_text(IMU_SNIPPETS, encoding="utf-8")
    form = family.ImuForm(LINE_KIND, _line_record, code="LINE", label="line", snippets=snippets)
    yield _register_line(directory, form)
    family.unregister(NAME)
    methods.unregister(NAME)


@pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None, reason="no C compiler")
def test_a_registered_family_exports_and_verifies_bit_exact(
    line_family: family.CFamily, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    recording = tmp_path / "run.npz"
    assert (
        trainer_main(["simulate", "--seed", "4", "--duration", "120", "--rate", "20", "-o", str(recording)])
        == 0
    )
    temp_c = np.linspace(10.0, 50.0, 50)
    model = LinearInTemperature().fit_arrays(temp_c, 0.8 * temp_c - 3.0)
    model_path = tmp_path / "line.pt"
    save_model(model, model_path, train_stats=TrainStats(), valid_temp_range_c=(10.0, 50.0))

    out = tmp_path / "c"
    assert run_cli(codegen_main, ["export", str(model_path), "-o", str(out), "--name", "tdc_line"]) == 0
    source = (out / "tdc_line.c").read_text()
    assert "a line in T (the throwaway family" in source  # its own template, found through the registry
    header = (out / "tdc_line.h").read_text()
    assert "memoryless: any rate" in header and "_restore" not in header  # the defaults of CFamily
    manifest = json.loads((out / "tdc_line.manifest.json").read_text())
    assert manifest["method"] == NAME and manifest["quantisation"] == {"frac_bits": FRAC}

    result = verify(model_path, out, recording, table1=False)
    assert result.samples > 0 and result.mismatches == 0 and result.state_equal
    # the golden model is the family's: its drift is the line (1 LSB of rounding)
    quantised = line_family.quantise(_parse_line(model_path), Limits(signal_lsb=16_000_000), "step")
    drift = GoldenLine(quantised).run(np.zeros(3, dtype=np.int64), np.array([10_000, 30_000, 50_000]))
    expected_lsb = -(0.8 * np.array([10.0, 30.0, 50.0]) - 3.0) * ACCEL_PER_MG
    np.testing.assert_allclose(drift, expected_lsb, atol=1.0)


@pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None, reason="no C compiler")
def test_a_registered_imu_form_joins_the_imu_module_bit_exact(
    line_imu_family: family.CFamily, tmp_path: Path
) -> None:
    """A family's ImuForm is all the IMU module needs: its channels compile and match their golden
    model, beside the blob kinds every module holds."""
    temp_c = np.linspace(10.0, 50.0, 50)
    paths = []
    for channel, slope in (("accel0_x", 0.8), ("accel0_y", -1.5)):
        model = LinearInTemperature().fit_arrays(temp_c, slope * temp_c - 3.0)
        path = tmp_path / f"{channel}.pt"
        save_model(
            model, path, train_stats=TrainStats(channel=channel, unit="mg"), valid_temp_range_c=(10.0, 50.0)
        )
        paths.append(path)
    out = tmp_path / "c"
    imu, _ = export_imu(paths, out, name="imu_line")
    assert [c.kind for c in imu.channels] == [LINE_KIND, LINE_KIND]
    source = (out / "imu_line.c").read_text()
    assert f"#define IMU_LINE_KIND_LINE {LINE_KIND}u" in source and "imu_line_line(ch, " in source
    rng = np.random.default_rng(5)
    n = 400
    raw = rng.integers(-2_000_000, 2_000_000, size=(n, 2))
    lo, hi = TEMP_LIMITS_MDEGC
    temp = np.linspace(lo - 20_000, hi + 20_000, n, dtype=np.int64)[:, None]  # beyond the front end: clamped
    out_c, flags_c, samples_c = host_run(out, "imu_line", raw, temp, None, None)
    out_g, flags_g, samples_g = imu_golden(imu, raw, temp)
    np.testing.assert_array_equal(out_c, out_g)
    assert flags_c == flags_g and samples_c == samples_g == n
    assert all(f & FLAGS["input_clamped"] for f in flags_g)  # the clamp was exercised
    with pytest.raises(UserError, match="a line channel has no calibration-blob record"):
        encode_blob(imu)


def _parse_line(model_path: Path) -> LineSpec:
    from codegen.spec import parse_checkpoint
    from trainer.checkpoint import load_checkpoint

    spec = parse_checkpoint(load_checkpoint(model_path), str(model_path)).model
    assert isinstance(spec, LineSpec)
    return spec


def test_the_one_channel_templates_test_no_family() -> None:
    """A family supplies data (its template, usage paragraph, kernel headers, restore, context); the
    shared templates of a one-channel module never branch on which family it is (the IMU module's
    templates, imu*.j2 and harness_imu.c.j2, lay out each kind of channel by design)."""
    shared = [p for p in sorted(TEMPLATES.glob("*.j2")) if "imu" not in p.name]
    names = "|".join(re.escape(name) for name in family.names())
    family_test = re.compile(rf"""\bfamily\b|["']({names}|stream)["']""")
    found = [
        f"{path.name}: {tag}"
        for path in shared
        for tag in re.findall(r"{%.*?%}", path.read_text(encoding="utf-8"))
        if family_test.search(tag)
    ]
    assert not found, "templates testing a family:\n" + "\n".join(found)
    assert {"module.c.j2", "module.h.j2", "harness_bench.c.j2"} <= {p.name for p in shared}
    assert family_test.search('{% if family == "physics" %}')  # what it is there to find


def test_the_imu_module_tests_no_family() -> None:
    """The IMU module's code and templates are generic over families: each family's part (its
    ImuForm: record, blob record, variables, macros) is in its unit; imu.py imports no unit and no
    kind code, and no template tag of imu*.j2 / harness_imu.c.j2 names a family or a kind."""
    import ast

    import codegen.imu

    tree = ast.parse(Path(codegen.imu.__file__).read_text(encoding="utf-8"))
    imported = [
        (node.module or "", alias.name)
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom)
        for alias in node.names
    ]
    assert not [m for m, _ in imported if m.startswith("codegen.families")]
    assert not [name for _, name in imported if name.startswith("KIND_")]
    kinds = re.compile(r"physics|stream|cubic|\bpla\b|dlstm|poly3|lstm", re.IGNORECASE)
    templates = [*sorted(TEMPLATES.glob("imu*.j2")), TEMPLATES / "harness_imu.c.j2"]
    found = [
        f"{path.name}: {tag}"
        for path in templates
        for tag in re.findall(r"{[%{].*?[%}]}", path.read_text(encoding="utf-8"), re.DOTALL)
        if kinds.search(tag)
    ]
    assert not found, "IMU templates naming a family:\n" + "\n".join(found)
    assert kinds.search("{% if physics_channels %}")  # what it is there to find
    every = [f.imu for f in family.entries() if f.imu is not None]
    assert {form.code for form in every} == {"CUBIC", "PLA", "PHYSICS", "STREAM"}
    assert all(form.snippets is not None and form.snippets.is_file() for form in every)


def test_registering_a_built_in_name_is_refused() -> None:
    with pytest.raises(ValueError, match="registered already"):
        family.register(family.get("cubic"))
    with pytest.raises(ValueError, match="built in"):
        family.unregister("cubic")
