"""Several instances of one streamed effect in the physics export: a Prandtl-Ishlinskii sum of
branch offsets (three ``hysteresis_offset`` terms 5, 20 and 80 degC wide) beside a thermal lag.

Each instance keeps its own play operator (``play``, ``play_2``, ``play_3`` in the float stream, the
golden model and the C state alike) and its own constants. On a temperature history that reverses
several times and crosses every play's width, the one-channel C equals the golden model bit for bit
(ASan/UBSan, strict warnings), the golden model follows the float64 ``PhysicsStream`` within the
export's budget, a saved state restores every word, and the IMU module carries a channel of three
instances beside a channel of one, each equal to its own one-channel module.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from codegen.cli import main as codegen_main
from codegen.export import LoadedModel, export
from codegen.families.physics.golden import GoldenPhysics
from codegen.families.physics.quantise import QPhysics
from codegen.golden_select import golden_for
from codegen.hostbuild import (
    CMD_INIT,
    CMD_RESET,
    FIRMWARE_WARNINGS,
    SANITIZER_FLAGS,
    STRICT_FLAGS,
    build_harness,
    load_module,
    run_harness,
    write_vectors,
)
from codegen.imu import imu_golden, load_imu
from codegen.imu_verify import host_run
from codegen.quantize import ACCEL_PER_MG, INT64_SAFE
from codegen.render import render_template
from codegen.verify import verify
from tests import testmodels as tm
from tests.golden_checks import assert_states_equal, replay
from tests.imu_checks import append_burst, golden_with_resets, sanitized_run_with_resets
from trainer.data.recording import Recording
from trainer.data.recording_io import write_recording
from trainer.errors import run_cli
from trainer.greybox.compensator import PhysicsCompensator
from trainer.greybox.stream import PhysicsModel, PhysicsStream
from trainer.physics.effects import EffectConfig

NAME = "tdc_pi"
RATE_HZ = 1.0
BUDGET_MG = 1e-3  # golden minus the float64 stream (docs/codegen.md), as tests/export/test_codegen_physics.py
RANGE_C = (-40.0, 85.0)
POLY = {"c0_mg": 0.4, "c1_mg_per_c": 0.15, "c2_mg_per_c2": 1e-3, "c3_mg_per_c3": -5e-6}
WIDTHS_C = (5.0, 20.0, 80.0)
BRANCHES = tuple(
    EffectConfig("hysteresis_offset", {"amp_mg": amp, "width_c": width})
    for amp, width in zip((0.3, 0.5, 0.9), WIDTHS_C, strict=True)
)
# given out of step order on purpose: the lag runs first, the instances keep the order given
EFFECTS = (
    EffectConfig("bias_poly", POLY),
    BRANCHES[0],
    EffectConfig("thermal_lag", {"tau_s": 120.0}),
    *BRANCHES[1:],
)
PLAYS = ("play", "play_2", "play_3")
# (duration s, from degC, to degC) at 1 Hz: excursions of 55, 115, 45, 15, 35, 3, 33 and 45 degC, so
# every play operator (5, 20, 80 degC wide) is dragged both ways, the narrow ones many times
SEGMENTS = ((200, 25.0, 25.0), (1100, 25.0, 80.0), (2300, 80.0, -35.0), (900, -35.0, 10.0),
            (300, 10.0, -5.0), (700, -5.0, 30.0), (60, 30.0, 27.0), (660, 27.0, 60.0),
            (900, 60.0, 15.0))  # fmt: skip


def history_c(seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    temp = np.concatenate([np.linspace(a, b, int(d * RATE_HZ), endpoint=False) for d, a, b in SEGMENTS])
    return temp + rng.normal(0, 0.02, temp.size)


def physics_model(effects: tuple[EffectConfig, ...], play_start_c: float | None) -> PhysicsCompensator:
    model = PhysicsCompensator()
    model.effects = effects
    model.temp_range_c, model.report, model.play_start_c = RANGE_C, {}, play_start_c
    return model


def save_physics(model: PhysicsCompensator, path: Path, channel: str | None = None) -> Path:
    checkpoint = tm.checkpoint_dict("physics", model.to_payload(), model.temp_range_c)
    checkpoint["train_stats"] = {"sample_rate_hz": RATE_HZ}
    if channel is not None:
        checkpoint["train_stats"] |= {"channel": channel, "unit": "mg"}
    tm.save_checkpoint(checkpoint, path)
    return path


def stream_mg(model: PhysicsModel, temp_mdegc: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The float64 stream's drift on the C's integer temperatures, and each play word's history (nan
    when the model lacks it)."""
    stream = PhysicsStream(model, 1.0 / RATE_HZ)
    drift, words = [], []
    for t in temp_mdegc.tolist():
        drift.append(stream.step(t / 1000.0))
        words.append([stream.state.values.get(w, np.nan) for w in PLAYS])
    history = np.array(words)
    return np.array(drift), {w: history[:, k] for k, w in enumerate(PLAYS)}


@dataclass(frozen=True)
class Exported:
    model: PhysicsCompensator
    path: Path
    out: Path
    loaded: LoadedModel
    quantised: QPhysics


@pytest.fixture(scope="module", params=[None, 25.0], ids=["half-way", "play-start-25"])
def exported(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Exported:
    folder = tmp_path_factory.mktemp("instances")
    model = physics_model(EFFECTS, request.param)
    path = save_physics(model, folder / "model.pt")
    loaded, _ = export(path, folder / "out", name=NAME)
    assert isinstance(loaded.quantised, QPhysics)
    return Exported(model, path, folder / "out", loaded, loaded.quantised)


def _inputs(n_burst: int = 0) -> tuple[np.ndarray, np.ndarray]:
    temp = np.round(1000 * history_c()).astype(np.int64)
    accel = np.random.default_rng(11).integers(-(2**24), 2**24, temp.size)
    if n_burst:
        rng = np.random.default_rng(12)
        accel = np.concatenate([accel, rng.choice([-(2**31), 2**31 - 1, 0], n_burst)])
        temp = np.concatenate([temp, rng.choice([-(2**31), 2**31 - 1, -300_000, 500_000], n_burst)])
    return accel, temp


def test_each_instance_has_its_own_state_word_constants_and_gain(exported: Exported) -> None:
    q = exported.quantised
    branches = [t for t in q.terms if t.identifier == "hysteresis_offset"]
    assert [t.suffix for t in branches] == ["", "_2", "_3"]  # the order given
    assert q.terms[0].identifier == "thermal_lag"  # step order: the chain first
    assert [w.name for w in q.words] == ["proof_mass", *PLAYS]
    margins = [t.margin_q for t in branches]
    assert margins == [round(w * 500 * 2**q.temp_frac) for w in WIDTHS_C]  # each its own half width
    assert len({t.gain.q for t in branches if t.gain is not None}) == 3
    assert [g.name for g in q.gains] == ["branch", "branch_2", "branch_3"]
    # the accumulator's bound counts every instance's term
    assert q.bound == (q.horner_bounds[0] << 32) + sum(g.bound for g in q.gains) < INT64_SAFE
    assert (q.play_start_q is None) == (exported.model.play_start_c is None)
    header = " ".join((exported.out / f"{NAME}.h").read_text().replace("*", " ").split())
    assert "branch gain (T_pm - P) + branch_2 gain (T_pm - P_2) + branch_3 gain (T_pm - P_3)" in header
    declared, source = (exported.out / f"{NAME}.h").read_text(), (exported.out / f"{NAME}.c").read_text()
    for word in PLAYS:
        assert f"    int32_t {word}; /* play operator output P" in declared, word
        assert f"state->{word} = tdcp_play(state->{word}, t_pm, " in source
        assert f"|| saved->{word} < -{q.word_bounds[word]} || saved->{word} > {q.word_bounds[word]}" in source
        start = "x" if q.play_start_q is None else str(q.play_start_q)
        assert f"state->{word} = {start};" in source
    manifest = json.loads((exported.out / f"{NAME}.manifest.json").read_text())["quantisation"]
    assert [g["name"] for g in manifest["gains"]] == ["branch", "branch_2", "branch_3"]
    assert [g["q"] for g in manifest["gains"]] == [g.q for g in q.gains]


def test_the_history_drags_every_play_operator_both_ways(exported: Exported) -> None:
    """What the bit-exact and budget tests below rely on: each play operator leaves both branches."""
    _, temp = _inputs()
    _, plays = stream_mg(exported.model.model, temp)
    for word, history in plays.items():
        moves = np.diff(history)
        reversals = np.count_nonzero(np.diff(np.sign(moves[moves != 0])) != 0)
        assert np.any(moves > 0) and np.any(moves < 0), word
        assert reversals >= (1 if word == "play_3" else 3), (word, reversals)


def test_the_c_equals_the_golden_model_under_sanitizers_with_resets_inits_and_extremes(
    exported: Exported, tmp_path: Path
) -> None:
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed")
    accel, temp = _inputs(n_burst=400)
    commands = np.zeros(accel.size, dtype=np.int64)
    commands[3_000], commands[6_000], commands[temp.size - 200] = CMD_RESET, CMD_INIT, CMD_RESET
    write_vectors(tmp_path / "v.bin", accel, temp, commands)
    q = exported.quantised
    harness = render_template("harness_vectors.c.j2", q, NAME, exported.loaded.sha256)
    binary = build_harness(exported.out, NAME, harness, tmp_path / "san", flags=("-O1", *SANITIZER_FLAGS))
    raw_state = run_harness(binary, tmp_path / "v.bin", tmp_path / "o.bin")
    c_out = np.frombuffer((tmp_path / "o.bin").read_bytes(), dtype="<i4").astype(np.int64)
    golden = golden_for(q)
    np.testing.assert_array_equal(c_out, replay(golden, accel, temp, commands))
    c_state = load_module(exported.out, NAME, flags=("-O0",)).state_from_bytes(raw_state)
    assert_states_equal(c_state, golden.state())
    assert all(word in c_state for word in PLAYS)


def test_codegen_verify_finds_no_mismatch_within_the_budget(exported: Exported, tmp_path: Path) -> None:
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed")
    temp_c = np.round(history_c(), 3)
    columns = {
        "time_s": np.arange(temp_c.size) / RATE_HZ,
        "temp_c": temp_c,
        "accel_mg": np.zeros_like(temp_c),
    }
    rec = Recording(columns, {"sample_rate_hz": f"{RATE_HZ:g}"}, "instances")
    rec.columns["accel_mg"] = exported.model.predict_drift(rec)  # a sensor with exactly this drift
    write_recording(rec, tmp_path / "rec.csv")
    result = verify(exported.path, exported.out, tmp_path / "rec.csv", name=NAME, table1=False)
    assert result.mismatches == 0 and result.state_equal and result.samples == temp_c.size
    assert result.budget.arithmetic_max_abs_mg < BUDGET_MG


def test_the_golden_model_follows_the_float_stream_within_the_budget_and_needs_every_instance(
    exported: Exported,
) -> None:
    accel, temp = _inputs()
    golden_mg = (accel - golden_for(exported.quantised).run(accel, temp)) / ACCEL_PER_MG
    reference, _ = stream_mg(exported.model.model, temp)
    err = golden_mg - reference
    assert np.max(np.abs(err)) < BUDGET_MG, np.max(np.abs(err))
    assert np.sqrt(np.mean(err**2)) < 0.1 * BUDGET_MG
    # each instance is carried: the stream without any one of them is far from the golden model
    for k, branch in enumerate(BRANCHES):
        others = tuple(e for e in EFFECTS if e is not branch)
        without, _ = stream_mg(physics_model(others, exported.model.play_start_c).model, temp)
        assert np.max(np.abs(golden_mg - without)) > 0.5 * branch.params["amp_mg"], k


def test_strict_flags_warning_free(exported: Exported, tmp_path: Path) -> None:
    compilers = [cc for cc in ("gcc", "clang") if shutil.which(cc) is not None]
    if not compilers:
        pytest.skip("no C compiler")
    for cc in compilers:
        for opt in ("-O0", "-O2", "-Os"):
            result = subprocess.run(
                [cc, *STRICT_FLAGS, *FIRMWARE_WARNINGS, opt, "-c", str(exported.out / f"{NAME}.c"),
                 "-o", str(tmp_path / "m.o")],
                capture_output=True, text=True,
            )  # fmt: skip
            assert result.returncode == 0 and not result.stderr, f"{cc} {opt}: {result.stderr}"


def test_a_saved_state_restores_every_play_operator_and_a_damaged_one_is_refused(exported: Exported) -> None:
    if shutil.which("gcc") is None and shutil.which("cc") is None:
        pytest.skip("no C compiler")
    accel, temp = (v.astype(np.int32) for v in _inputs())
    host = load_module(exported.out, NAME, flags=("-O1",))
    whole = host.run(host.new_state(), accel, temp)
    cut = 4_700  # on the cooling ramp, after the 80 degC peak: every play off its mid-way start
    first = host.new_state()
    host.run(first, accel[:cut], temp[:cut])
    saved = host.read_state(first)
    assert len({saved[w] for w in PLAYS}) == 3  # three distinct operator states to keep
    resumed = host.new_state()
    blob = host.ffi.from_buffer(f"{NAME}_state_t *", bytearray(bytes(host.ffi.buffer(first))))
    assert host.lib.tdc_pi_restore(resumed, blob) == 1
    np.testing.assert_array_equal(host.run(resumed, accel[cut:], temp[cut:]), whole[cut:])
    golden = golden_for(exported.quantised)
    assert isinstance(golden, GoldenPhysics)
    assert golden.restore(saved)
    np.testing.assert_array_equal(golden.run(accel[cut:], temp[cut:]), whole[cut:])
    # each play word alone, put back mid-way (at T_pm), changes what follows: each one is kept
    for word in PLAYS:
        other = host.new_state()
        lost = host.ffi.from_buffer(f"{NAME}_state_t *", bytearray(bytes(host.ffi.buffer(first))))
        setattr(lost, word, int(saved["proof_mass"]) >> 32)
        assert host.lib.tdc_pi_restore(other, lost) == 1
        assert np.any(host.run(other, accel[cut:], temp[cut:]) != whole[cut:]), word
    # a word beyond the bound the step's proofs assume: refused (and initialised) by both
    fresh = host.read_state(host.new_state())
    for word in PLAYS:
        bound = exported.quantised.word_bounds[word]
        for value in (bound + 1, -bound - 1):
            damaged = host.ffi.from_buffer(f"{NAME}_state_t *", bytearray(bytes(host.ffi.buffer(first))))
            setattr(damaged, word, value)
            target = host.new_state()
            assert host.lib.tdc_pi_restore(target, damaged) == 0, word
            assert host.read_state(target) == fresh, word
            again = golden_for(exported.quantised)
            assert isinstance(again, GoldenPhysics)
            assert not again.restore({**saved, word: value}), word


def test_two_effects_that_share_the_play_operator_are_refused_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """hysteresis and hysteresis_offset are the same C term: their first instances would share one
    state word (the trainer never fits both); the export says so instead of dropping one."""
    effects = (*EFFECTS[:3], EffectConfig("hysteresis", {"amp_mg": 0.2, "width_c": 10.0}))
    path = save_physics(physics_model(effects, None), tmp_path / "both.pt")
    capsys.readouterr()
    code = run_cli(codegen_main, ["export", str(path), "-o", str(tmp_path / "never"), "--name", NAME])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and "Traceback" not in err, err
    assert "share the C state word 'play'" in err
    assert not (tmp_path / "never").exists()


# ---- the IMU module: a channel of three instances beside a channel of one -------------------------
ONE = (
    EffectConfig("bias_poly", {**POLY, "c1_mg_per_c": -0.1}),
    EffectConfig("temp_rate", {"k_mg_per_c_per_min": 0.3, "tau_s": 60.0}),
    EffectConfig("hysteresis_offset", {"amp_mg": -0.6, "width_c": 12.0}),
)


@pytest.fixture(scope="module")
def imu_module(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("imu-instances")
    paths = {
        "accel0_x": save_physics(physics_model(EFFECTS, 25.0), root / "accel0_x.pt", "accel0_x"),
        "accel0_y": save_physics(physics_model(ONE, None), root / "accel0_y.pt", "accel0_y"),
    }
    argv = ["export", *map(str, paths.values()), "-o", str(root / "c"), "--name", "imu0"]
    assert codegen_main(argv) == 0
    return {"root": root, "out": root / "c", **paths}


def _imu_inputs() -> tuple[np.ndarray, np.ndarray]:
    temp = np.round(1000 * history_c()).astype(np.int64)[:, None]
    raw = np.random.default_rng(13).integers(-(2**24), 2**24, (temp.shape[0], 2))
    return raw, temp


def test_the_imu_module_lays_out_as_many_slots_as_the_most_instances(imu_module: dict[str, Path]) -> None:
    header = (imu_module["out"] / "imu0.h").read_text()
    for field in ("half_width_2", "half_width_3", "branch_2_q", "branch_3_q", "play_2", "play_3"):
        assert f" {field};" in header, field
    assert "half_width_4" not in header and "play_4" not in header
    assert "#define IMU0_PHYS_BRANCH_3 " in header


def test_the_imu_module_equals_the_golden_model_and_each_one_channel_module(
    imu_module: dict[str, Path], tmp_path: Path
) -> None:
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed")
    channels = [imu_module["accel0_x"], imu_module["accel0_y"]]
    imu = load_imu(channels)
    q = imu.channels[0].model.quantised
    assert isinstance(q, QPhysics) and [t.suffix for t in q.terms][-3:] == ["", "_2", "_3"]
    raw, temp = _imu_inputs()
    out, _, _ = host_run(imu_module["out"], "imu0", raw, temp, None, None)
    golden, _, _ = imu_golden(imu, raw, temp)
    np.testing.assert_array_equal(out, golden)
    for k, path in enumerate(channels):
        assert codegen_main(["export", str(path), "-o", str(tmp_path / f"one{k}"), "--name", "one"]) == 0
        one = load_module(tmp_path / f"one{k}", "one")
        single = one.run(one.new_state(), raw[:, k].astype(np.int32), temp[:, 0].astype(np.int32))
        np.testing.assert_array_equal(out[:, k], single)


def test_the_imu_module_under_sanitizers_with_resets_and_extremes(
    imu_module: dict[str, Path], tmp_path: Path
) -> None:
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed")
    imu = load_imu([imu_module["accel0_x"], imu_module["accel0_y"]])
    raw, temp = _imu_inputs()
    raw, temp = append_burst(raw, temp, 400, temp_lows=True)
    cuts = [2_500, 5_000, temp.shape[0] - 300]
    c_out, state = sanitized_run_with_resets(imu_module["out"], raw, temp, cuts, tmp_path)
    g_out, g_flags = golden_with_resets(imu, raw, temp, cuts)
    np.testing.assert_array_equal(c_out, g_out)
    assert list(state[:-1]) == g_flags and state[-1] == len(raw)


def test_the_imu_module_is_warning_free_under_strict_and_firmware_flags(
    imu_module: dict[str, Path], tmp_path: Path
) -> None:
    compilers = [cc for cc in ("gcc", "clang") if shutil.which(cc) is not None]
    if not compilers:
        pytest.skip("no C compiler")
    for cc in compilers:
        for opt in ("-O0", "-O2"):
            result = subprocess.run(
                [cc, *STRICT_FLAGS, *FIRMWARE_WARNINGS, opt, "-c", str(imu_module["out"] / "imu0.c"),
                 "-o", str(tmp_path / "m.o")],
                capture_output=True, text=True,
            )  # fmt: skip
            assert result.returncode == 0 and not result.stderr, f"{cc} {opt}: {result.stderr}"


def test_an_imu_module_refuses_more_instances_than_its_term_bits_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Each further instance takes a bit of ``NAME_physics_t.terms`` (uint32): a channel with sixteen
    branch offsets does not fit; the export names it and says what to do, and writes nothing. Its
    one-channel module carries them."""
    many = tuple(
        EffectConfig("hysteresis_offset", {"amp_mg": 0.05 * (k + 1), "width_c": 2.0 + 4 * k})
        for k in range(16)
    )
    effects = (EffectConfig("bias_poly", POLY), *many)
    x = save_physics(physics_model(effects, None), tmp_path / "accel0_x.pt", "accel0_x")
    y = save_physics(physics_model(ONE, None), tmp_path / "accel0_y.pt", "accel0_y")
    capsys.readouterr()
    code = run_cli(codegen_main, ["export", str(x), str(y), "-o", str(tmp_path / "never"), "--name", "imu0"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and "Traceback" not in err, err
    assert "channel accel0_x:" in err and "export that channel as a one-channel module" in err
    assert not (tmp_path / "never").exists()
    loaded, _ = export(x, tmp_path / "one", name=NAME)
    assert isinstance(loaded.quantised, QPhysics) and len(loaded.quantised.gains) == 16
