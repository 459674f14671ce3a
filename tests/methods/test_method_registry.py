"""trainer/methods.py is the one list of methods: a new method is one class plus one register() call."""

from __future__ import annotations

import argparse
import ast
import inspect
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Self

import numpy as np
import pytest

from codegen import family
from codegen.cli import main as codegen_main
from tests.repo import REPO_ROOT
from trainer import methods
from trainer.baselines.base import TemperatureCompensator
from trainer.checkpoint import load_model
from trainer.cli import build_parser
from trainer.cli import main as trainer_main
from trainer.compensator import Compensator
from trainer.errors import run_cli
from trainer.options.methods import OptionGroup
from trainer.scoring.compare import fit_all
from trainer.selection import AUTO, variant_labels

ROOT = REPO_ROOT
NAME = "linear-t"


class LinearInTemperature(TemperatureCompensator):
    """A throwaway memoryless method: one least-squares line of the drift in temperature."""

    def __init__(self, *, through_zero: bool = False) -> None:
        self.through_zero = through_zero
        self.coefficients = (0.0, 0.0)
        self.temp_range_c = (np.nan, np.nan)

    def fit_arrays(self, temp_c: np.ndarray, drift_mg: np.ndarray) -> Self:
        slope, offset = np.polyfit(temp_c, drift_mg, 1)
        self.coefficients = (float(slope), 0.0 if self.through_zero else float(offset))
        self.temp_range_c = (float(np.min(temp_c)), float(np.max(temp_c)))
        return self

    def drift_at(self, temp_c: np.ndarray) -> np.ndarray:
        return self.coefficients[0] * np.asarray(temp_c) + self.coefficients[1]

    def shift_drift(self, delta_mg: float) -> None:
        self.coefficients = (self.coefficients[0], self.coefficients[1] + delta_mg)

    def to_payload(self) -> dict[str, Any]:
        return {"coefficients": list(self.coefficients), "temp_range_c": list(self.temp_range_c)}

    @classmethod
    def from_payload(cls, payload: dict[str, Any]) -> Self:
        model = cls()
        model.coefficients = tuple(payload["coefficients"])  # type: ignore[assignment]
        model.temp_range_c = tuple(payload["temp_range_c"])  # type: ignore[assignment]
        return model


def _add_through_zero(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--through-zero", action="store_true", help="linear-t: no offset")


@pytest.fixture
def linear_t() -> Iterator[methods.Method]:
    entry = methods.register(
        methods.Method(
            NAME,
            LinearInTemperature,
            methods.MEMORYLESS,
            OptionGroup(_add_through_zero, lambda args: {"through_zero": args.through_zero}),
        )
    )
    yield entry
    methods.unregister(NAME)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Two 10-minute paper runs at 20 Hz (12,000 samples each)."""
    work = tmp_path_factory.mktemp("registry")
    paths = []
    for name, seed in (("train", 1), ("valid", 2)):
        path = work / f"{name}.npz"
        args = ["simulate", "--protocol", "paper-oven", "--seed", str(seed), "--duration", "600"]
        assert trainer_main([*args, "--rate", "20", "-o", str(path)]) == 0
        paths.append(path)
    return paths[0], paths[1]


def _choices(command: str, option: str) -> tuple[str, ...]:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    action = next(a for a in sub.choices[command]._actions if option in a.option_strings)
    return tuple(action.choices) if action.choices else tuple(action.default.split(","))


def test_fit_compare_and_export_see_a_method_registered_once(
    linear_t: methods.Method,
    recordings: tuple[Path, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    train, valid = recordings
    model_path = tmp_path / "lin.pt"
    argv = [
        "fit",
        "--method",
        NAME,
        str(train),
        "-o",
        str(model_path),
        "--through-zero",
        "--offset",
        "absolute",
    ]
    assert trainer_main(argv) == 0
    model, checkpoint = load_model(model_path)
    assert isinstance(model, LinearInTemperature) and checkpoint["method"] == NAME
    assert model.coefficients[1] == 0.0  # its own option reached its constructor

    out_dir = tmp_path / "cmp"
    args = ["compare", str(train), str(valid), "--out-dir", str(out_dir), "--methods", f"{NAME},poly3"]
    capsys.readouterr()
    assert trainer_main([*args, "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert f"| {NAME} |" in printed and "| poly3 |" in printed
    assert (out_dir / "models" / f"{NAME}.pt").is_file()

    code = run_cli(codegen_main, ["export", str(model_path), "-o", str(tmp_path / "c")])
    err = capsys.readouterr().err
    assert code == 2
    assert (
        err.count("\n") == 1 and err.startswith("error: ") and f"method '{NAME}' has no code generator" in err
    )
    assert not (tmp_path / "c").exists()


def test_registered_method_is_range_checked_and_ordered_last(
    linear_t: methods.Method, recordings: tuple[Path, Path]
) -> None:
    from trainer.data.recording_io import read_recording
    from trainer.dlstm.fusion import FusionSettings

    assert linear_t.range_checked and methods.names()[-1] == NAME
    models, _ = fit_all(
        read_recording(recordings[0]),
        FusionSettings(),
        methods=(NAME, "pla"),
        progress=False,
        log=lambda _: None,
    )
    assert list(models) == ["pla", NAME]  # registry order, whatever order was asked for


def test_duplicate_registration_is_refused(linear_t: methods.Method) -> None:
    with pytest.raises(ValueError, match="already registered"):
        methods.register(methods.Method(NAME, LinearInTemperature, methods.MEMORYLESS))
    with pytest.raises(ValueError, match="already registered"):
        methods.register(methods.Method("pla", LinearInTemperature, methods.MEMORYLESS))


def test_a_subclass_does_not_inherit_its_parents_name() -> None:
    pla = methods.get("pla").cls

    class Tweaked(pla):  # type: ignore[misc, valid-type]
        pass

    assert methods.name_of(pla()) == "pla"
    with pytest.raises(ValueError, match="not a registered method"):
        methods.name_of(Tweaked())
    assert methods.get("pla").cls is pla


def test_the_registry_order_is_the_comparison_order() -> None:
    assert methods.names() == (
        "dlstm",
        "dlstm-ssa",
        "dlstm-issa",
        "pla",
        "poly3",
        "dlstm-temp",
        "physics",
        "persistence",
    )
    assert methods.paper_names() == ("dlstm", "dlstm-ssa", "dlstm-issa", "pla")
    assert [m.name for m in methods.entries() if m.shares_population] == ["dlstm", "dlstm-ssa", "dlstm-issa"]
    assert [m.name for m in methods.entries() if m.range_checked] == ["pla", "poly3", "dlstm-temp", "physics"]
    assert inspect.signature(fit_all).parameters["methods"].default is None  # None = every method


def test_argparse_choices_equal_the_registry(linear_t: methods.Method) -> None:
    # auto: a selector, not a method; the variants: auto's candidates that fix a method's options
    assert _choices("fit", "--method") == (*methods.fit_cli_names(), *variant_labels(), AUTO)
    assert set(methods.fit_cli_names()) == {m.name for m in methods.entries() if not m.reference}
    assert NAME in _choices("fit", "--method")
    assert _choices("compare", "--methods") == methods.names()


def test_every_entry_resolves_to_a_compensator_class() -> None:
    """The entries name their classes by import path (no torch at start-up); each one resolves."""
    seen = set()
    for method in methods.entries():
        cls = method.cls
        assert inspect.isclass(cls) and issubclass(cls, Compensator) and not inspect.isabstract(cls)
        assert cls not in seen, f"{method.name}: class used by two methods"
        seen.add(cls)
        assert methods.name_of(cls) == method.name


def test_codegen_has_a_family_for_every_renderer() -> None:
    assert family.names() == methods.RENDERERS
    assert {m.renderer for m in methods.entries()} <= {*family.names(), None}
    assert all(family.get(name).name == name for name in family.names())


def test_method_names_are_written_only_in_the_registry() -> None:
    """No string literal outside trainer/methods.py names a method (tests and docs aside)."""
    names = set(methods.names())
    offenders = []
    for folder in ("trainer", "codegen", "bench"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            if path == ROOT / "trainer" / "methods.py":
                continue
            tree = ast.parse(path.read_text(encoding="utf-8"))
            docstrings = {
                id(node.body[0].value)
                for node in ast.walk(tree)
                if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
                and node.body
                and isinstance(node.body[0], ast.Expr)
            }
            for node in ast.walk(tree):
                if isinstance(node, ast.Constant) and node.value in names and id(node) not in docstrings:
                    offenders.append((str(path.relative_to(ROOT)), node.value))
    # the persistence predictor's front-end kind (PERSISTENCE_KIND) is a payload value that matches
    assert offenders == [("trainer/dlstm/realtime.py", "persistence")], offenders
