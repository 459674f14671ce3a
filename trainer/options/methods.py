"""How a method's command-line options reach its constructor (``trainer fit`` and ``trainer compare``).

An :class:`OptionGroup` adds a method's options to a parser and turns the parsed arguments into
the keyword arguments of the method's class. Several methods may share one group (the four DLSTM
methods share :data:`DLSTM_OPTIONS`); ``trainer fit`` adds every distinct group once.
Nothing here imports torch: the DLSTM group builds its settings only when it is used.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from trainer.options.dlstm import add_dlstm_options, settings_from_args


def _no_arguments(parser: argparse.ArgumentParser) -> None:
    del parser


def _no_kwargs(*args: Any) -> dict[str, Any]:
    del args
    return {}


@dataclass(frozen=True, eq=False)
class OptionGroup:
    """A method's options: how they are added to a parser and turned into constructor kwargs.

    ``fit_kwargs(args)`` serves ``trainer fit``; ``compare_kwargs(settings, progress)`` serves
    ``trainer compare``, which builds every method from the shared ``FusionSettings``.
    """

    add_arguments: Callable[[argparse.ArgumentParser], None] = _no_arguments
    fit_kwargs: Callable[[argparse.Namespace], dict[str, Any]] = _no_kwargs
    compare_kwargs: Callable[[Any, bool], dict[str, Any]] = _no_kwargs


NO_OPTIONS = OptionGroup()

# options that act on the command rather than on a method's fit (progress lines: auto's log too)
COMMAND_WIDE = frozenset({"quiet"})


def option_defaults(group: OptionGroup) -> dict[str, Any]:
    """``{dest: default}`` of the options ``group`` adds (read off a parser it fills)."""
    parser = argparse.ArgumentParser(add_help=False)
    group.add_arguments(parser)
    return vars(parser.parse_args([]))


def options_not_applying(
    args: argparse.Namespace, own: OptionGroup, others: list[tuple[str, OptionGroup]]
) -> dict[str, list[str]]:
    """``{--option: [methods it belongs to]}`` for the options given on the command line (a value
    other than the default) that ``own`` does not have: a user who passes ``--effects`` to poly3
    expects it to act. ``others``: (method name, its group) of every method."""
    mine = option_defaults(own)
    given: dict[str, list[str]] = {}
    for name, group in others:
        for dest, default in option_defaults(group).items():
            if dest not in mine and dest not in COMMAND_WIDE and getattr(args, dest, default) != default:
                given.setdefault("--" + dest.replace("_", "-"), []).append(name)
    return given


def _add_intervals(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--intervals", type=int, default=10, help="pla: number of temperature intervals (10)")


def _add_remove_median(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--remove-median",
        action="store_true",
        help="poly3: subtract the axis median first, exactly as PX4 does (offset left to "
        "the six-position calibration)",
    )


def _dlstm_fit_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    settings, frontend = settings_from_args(args)
    return {"settings": settings, "frontend_seconds": frontend, "progress": not args.quiet}


def _pla_fit_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    from trainer.baselines.pla import check_intervals  # imports torch: only when used

    return {"n_intervals": check_intervals(args.intervals)}


PLA_OPTIONS = OptionGroup(_add_intervals, _pla_fit_kwargs)
POLY3_OPTIONS = OptionGroup(_add_remove_median, lambda args: {"remove_median": args.remove_median})
DLSTM_OPTIONS = OptionGroup(
    add_dlstm_options,
    _dlstm_fit_kwargs,
    lambda settings, progress: {"settings": settings, "progress": progress},
)


def _add_physics(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--effects",
        default="auto",
        help="physics: 'auto' (default: the effects the mismatch finder identifies on the training run) or a "
        "comma list of compensable catalogue effects (a wrong name lists them)",
    )
    parser.add_argument(
        "--from-sim",
        metavar="AUGMENTED_TOML",
        help="physics: take the structure and starting values from the augmented.toml of trainer diagnose --report",
    )
    parser.add_argument(
        "--warmup",
        action="store_true",
        help="physics: compensate the warm-up after power-on too (the firmware must count time since power-on)",
    )


def _physics_fit_kwargs(args: argparse.Namespace) -> dict[str, Any]:
    return {
        "effects": args.effects,
        "from_sim": args.from_sim,
        "with_warmup": args.warmup,
        "progress": not getattr(args, "quiet", False),
    }


PHYSICS_OPTIONS = OptionGroup(_add_physics, _physics_fit_kwargs)
