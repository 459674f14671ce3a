"""Progress bars for long work: a live bar on a terminal, plain lines in a captured log.

tqdm hides its bar when stderr is not a terminal, so a physics fit run from CI or a pipe said
nothing for minutes. Off a terminal a bar here prints nothing for its first ``LOG_INTERVAL_S``
(short work stays quiet), then one plain line at most every ``LOG_INTERVAL_S``.
"""

from __future__ import annotations

import sys
from typing import Any, TextIO

from tqdm import tqdm

LOG_INTERVAL_S = 10.0  # off a terminal: first line after this long, then at most one line per interval
_CURSOR_UP = "\x1b[A"


class _Lines:
    """A file for tqdm that turns its carriage-return redraws into one line per display."""

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream

    def write(self, text: str) -> None:
        line = text.replace(_CURSOR_UP, "").replace("\r", "").replace("\n", "").strip()
        if line:
            self.stream.write(line + "\n")

    def flush(self) -> None:
        self.stream.flush()


def progress_bar(iterable: Any = None, *, progress: bool, **kwargs: Any) -> tqdm:
    """``tqdm(iterable, **kwargs)`` shown when ``progress``: live on a terminal, as timed lines otherwise."""
    stream = kwargs.pop("file", None) or sys.stderr
    if not progress:
        return tqdm(iterable, disable=True, **kwargs)
    if stream.isatty():
        return tqdm(iterable, file=stream, **kwargs)
    kwargs.pop("leave", None)
    return tqdm(
        iterable,
        file=_Lines(stream),
        disable=False,
        leave=False,  # the last timed line stays; no closing redraw
        position=0,  # nested bars print lines, not cursor moves
        delay=LOG_INTERVAL_S,
        mininterval=LOG_INTERVAL_S,
        miniters=1,
        ascii=True,
        **kwargs,
    )
