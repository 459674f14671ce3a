"""The one writer of Markdown tables in the tool's reports (GitHub-flavoured Markdown)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

_RULES = {"l": "---", "r": "---:"}


def markdown_table(headers: Sequence[str], rows: Iterable[Sequence[str]], align: str | None = None) -> str:
    """A Markdown table: header line, alignment line, one line per row; no trailing newline.

    Cells are written as given, one space either side (an empty cell is two spaces). ``align``
    has one letter per column: ``l`` (the default alignment, ``---``) or ``r`` (right,
    ``---:``); ``None`` leaves every column at the default.
    """
    align = "l" * len(headers) if align is None else align
    if len(align) != len(headers) or set(align) - set(_RULES):
        raise ValueError(f"align needs one of {'/'.join(_RULES)} per column, got {align!r}")
    lines = [_line(headers), "|" + "|".join(_RULES[a] for a in align) + "|"]
    lines += [_line(row) for row in rows]
    return "\n".join(lines)


def _line(cells: Sequence[str]) -> str:
    return "| " + " | ".join(cells) + " |"
