"""Option strings of a manifest, parsed by the parsers of ``trainer import`` and ``trainer fit``.

A manifest gives a unit's import options and each method's fit options as the command-line text
the user would type (``--preset tofupilot``, ``--intervals 12``), so they mean exactly what they
mean on the command line; the parsers are built from :mod:`trainer.commands.import_cmd` and the
method's :class:`~trainer.commands.method_options.OptionGroup` in :mod:`trainer.methods`, so a
method registered later (with its own options) works here unchanged.
"""

from __future__ import annotations

import argparse
import shlex
from typing import Any

from trainer import methods
from trainer.data.importer import ImportOptions
from trainer.errors import OneLineArgumentParser, UserError


def split(text: str, where: str) -> list[str]:
    """Shell-like words of ``text``; an unbalanced quote is a one-line error."""
    try:
        return shlex.split(text)
    except ValueError as exc:
        raise UserError(f"{where}: cannot split {text!r} ({exc})") from None


def canonical(text: str, where: str) -> str:
    """The option text re-joined word by word: spacing does not change a unit's cache key."""
    return shlex.join(split(text, where))


def import_options(text: str, where: str) -> ImportOptions:
    """``trainer import`` options (``FOREIGN`` and ``-o`` are implied) as :class:`ImportOptions`."""
    from trainer.commands import import_cmd

    parser = OneLineArgumentParser(prog=where)
    import_cmd.add_parser(parser.add_subparsers(dest="command", parser_class=OneLineArgumentParser))
    args = parser.parse_args(["import", "FOREIGN", "-o", "unused.npz", *split(text, where)])
    return import_cmd.import_options(args)


def fit_methods() -> tuple[str, ...]:
    """The methods a manifest may name: those of ``trainer fit --method``, from the registry."""
    return methods.fit_cli_names()


def check_method(name: str, where: str) -> str:
    if name not in fit_methods():
        raise UserError(f"{where}: unknown method {name!r}; choose from {', '.join(fit_methods())}")
    return name


def fit_kwargs(method: str, text: str, where: str) -> dict[str, Any]:
    """Constructor keyword arguments of ``method`` from its ``trainer fit`` options ``text``.

    Progress bars are switched off: many units run at once and the fleet has its own bar.
    """
    group = methods.get(method).options
    parser = OneLineArgumentParser(prog=f"{where} ({method})", add_help=False)
    group.add_arguments(parser)
    args: argparse.Namespace = parser.parse_args(split(text, where))
    kwargs = group.fit_kwargs(args)
    if "progress" in kwargs:
        kwargs["progress"] = False
    return kwargs
