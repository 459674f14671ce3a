"""Option strings of a manifest, parsed by the parsers of ``trainer import`` and ``trainer fit``.

A manifest gives a unit's import options and each method's fit options as the command-line text
the user would type (``--preset tofupilot``, ``--intervals 12``), so they mean exactly what they
mean on the command line; the parsers are built from :mod:`trainer.options.importing` and the
method's :class:`~trainer.options.methods.OptionGroup` in :mod:`trainer.methods`, so a
method registered later (with its own options) works here unchanged.
"""

from __future__ import annotations

import argparse
import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from trainer import methods
from trainer.data.flightlog import log_kind
from trainer.data.plausibility import Plausibility
from trainer.data.recording import Recording
from trainer.errors import OneLineArgumentParser, UserError
from trainer.options.importing import add_import_arguments, import_options, log_import_options

if TYPE_CHECKING:
    from trainer.data.flightlog_import import LogImportOptions
    from trainer.data.importer import ImportOptions


RECORDING_OPTIONS = ("channel", "accept_implausible")  # the import options a recording (.csv/.npz) takes


def split(text: str, where: str) -> list[str]:
    """Shell-like words of ``text``; an unbalanced quote is a one-line error."""
    try:
        return shlex.split(text)
    except ValueError as exc:
        raise UserError(f"{where}: cannot split {text!r} ({exc})") from None


def canonical(text: str, where: str) -> str:
    """The option text re-joined word by word: spacing does not change a unit's cache key."""
    return shlex.join(split(text, where))


def _import_args(text: str, where: str) -> argparse.Namespace:
    """``trainer import`` options (``FOREIGN`` and ``-o`` are implied), parsed by its own parser."""
    parser = OneLineArgumentParser(prog=where)
    subparsers = parser.add_subparsers(dest="command", parser_class=OneLineArgumentParser)
    add_import_arguments(subparsers.add_parser("import", prog=where))  # errors name "<where>" once
    return parser.parse_args(["import", "FOREIGN", "-o", "unused.npz", *split(text, where)])


@dataclass(frozen=True)
class UnitImport:
    """A unit's ``import`` option text, parsed once by ``trainer import``'s parser and applied to a
    file of either kind, exactly as ``trainer import FILE OPTIONS`` would: a PX4 ULog or ArduPilot
    DataFlash log (recognised by its first bytes) with the flight-log options, any other file
    with the column options. Without options a file must be a recording (.csv/.npz) or a flight log.
    ``where`` names the manifest, the unit and the field in every error.
    """

    text: str
    where: str
    args: argparse.Namespace = field(compare=False, repr=False)

    @classmethod
    def parse(cls, text: str, where: str) -> UnitImport:
        return cls(text, where, _import_args(text, where))

    @property
    def accepts_implausible(self) -> bool:
        """``--accept-implausible`` among the unit's options: a warning instead of a refusal, as in
        ``trainer import`` and ``trainer fit``."""
        return bool(self.args.accept_implausible)

    def _only_recording_options(self) -> bool:
        """Whether the options are all a recording of the spec (.csv/.npz) takes: ``--channel NAME`` (one
        channel of a multi-channel recording) and ``--accept-implausible``; any column option makes the
        file a foreign one, imported as ``trainer import`` would."""
        defaults = vars(_import_args("", self.where))
        given = {name for name, value in vars(self.args).items() if value != defaults.get(name)}
        return given <= set(RECORDING_OPTIONS)

    def _recording(self, path: Path) -> Recording:
        """A recording of the spec, or the one channel ``--channel`` names of a multi-channel one."""
        from trainer.data.channels import channel_view, recording_channels, select_channels
        from trainer.data.recording_io import read_recording

        rec = read_recording(path)
        if self.args.channel is not None:
            (channel,) = select_channels(rec, (self.args.channel,))
            return channel_view(rec, channel)
        one_axis = rec.one_axis_or_none("accel_mg") is not None and rec.one_axis_or_none("temp_c") is not None
        if not one_axis and (named := recording_channels(rec)):
            raise UserError(
                f"{path}: a multi-channel recording without the one-axis columns accel_mg and temp_c: a unit "
                f'fits one channel; give the unit import = "--channel NAME" ({", ".join(named)})'
            )
        return rec

    def _fail(self, path: Path, exc: UserError) -> UserError:
        return UserError(f"{self.where} {self.text!r} for {path}: {exc}")

    def text_options(self) -> ImportOptions:
        """The options of a delimited file (a UserError naming the unit's field when incomplete)."""
        return import_options(self.args)

    def _log_options(self, path: Path, kind: str) -> LogImportOptions:
        args = argparse.Namespace(**{**vars(self.args), "foreign": str(path)})
        try:
            return log_import_options(args, kind)
        except UserError as exc:
            raise self._fail(path, exc) from None

    def check(self, path: Path) -> None:
        """Refuse, before any work, options that cannot apply to ``path`` (when it exists)."""
        if not path.is_file():
            return  # a missing file fails its unit when it is read
        kind = log_kind(path)
        if kind is not None:
            self._log_options(path, kind)
        elif self.text and not self._is_recording(path):
            try:
                self.text_options()
            except UserError as exc:
                raise self._fail(path, exc) from None

    def read(self, path: Path) -> tuple[Recording, list[str]]:
        """The recording of ``path`` and the import's notes (corrections undone, warnings accepted)."""
        from trainer.data.flightlog_import import import_flight_log
        from trainer.data.importer import import_foreign

        checks = Plausibility(accept=self.accepts_implausible)
        kind = log_kind(path)
        if kind is not None:
            imported = import_flight_log(path, self._log_options(path, kind), checks)
            if len(imported.recordings) != 1:
                raise UserError(
                    f"{self.where} {self.text!r} for {path}: makes {len(imported.recordings)} recordings "
                    f"({', '.join(imported.recordings)}: one per sensor instance) and a unit fits one channel; "
                    "give --channel NAME instead of --channels"
                )
            (rec,) = imported.recordings.values()
            return rec, [*imported.notices, *checks.warnings]
        if self.text and not self._is_recording(path):
            try:
                options = self.text_options()
            except UserError as exc:
                raise self._fail(path, exc) from None
            rec = import_foreign(path, options, checks)
            return self._one_channel(path, rec), list(checks.warnings)
        if path.suffix.lower() not in (".csv", ".npz"):
            raise UserError(
                f"{path}: not a recording (.csv/.npz) or a flight log; give the unit 'import' options for a "
                "foreign file"
            )
        return self._recording(path), []

    def _one_channel(self, path: Path, rec: Recording) -> Recording:
        """A delimited import with ``--channels``: the one channel it names (a unit fits one; the
        import's ``accel_mg`` column is the preset's own axis, not the channel asked for), else a
        one-line refusal, as for a flight log."""
        from trainer.data.channels import channel_view, recording_channels

        if self.text_options().channels is None:
            return rec
        named = recording_channels(rec)
        if len(named) != 1:
            raise UserError(
                f"{self.where} {self.text!r} for {path}: makes {len(named)} channels ({', '.join(named)}) and a "
                "unit fits one; give --channels NAME (one channel) or a unit per channel"
            )
        (channel,) = named.values()
        return channel_view(rec, channel)

    def _is_recording(self, path: Path) -> bool:
        """A .csv/.npz file with no column option: a recording of the spec."""
        return path.suffix.lower() in (".csv", ".npz") and self._only_recording_options()


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
