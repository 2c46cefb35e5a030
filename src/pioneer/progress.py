"""Progress bars that suit where they are shown: redrawn on a terminal, a few lines in a log.

On a terminal a bar redraws in place as usual (tqdm). Anywhere else — CI, a file
(``make demo > log``), ``nohup`` — redraws would pile up as one long line of ``\\r``
updates, so the bar prints a whole line at the start, then at most one every
:data:`LOG_EVERY_FRACTION` of its total *and* :data:`LOG_EVERY_S` seconds (whichever comes
later), and one at the end: a run of any length stays a short, readable log.

tqdm is imported when a bar is made, so modules of the light robot runtime can use this one
without it until a bar is asked for.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Iterable, Sized
from typing import Any, TextIO

__all__ = ["LOG_EVERY_FRACTION", "LOG_EVERY_S", "LineWriter", "progress_bar"]

LOG_EVERY_FRACTION = 0.1  # a log line every 10 % of the total …
LOG_EVERY_S = 30.0  # [s] … and at least this long after the previous one


class LineWriter:
    """A text stream for tqdm that turns its carriage-return redraws into whole lines.

    tqdm writes ``"\\r" + status + padding`` for each redraw and ``"\\n"`` when it closes;
    each non-empty status becomes one line, padding stripped, and nothing else is written.
    """

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream

    def write(self, text: str) -> int:
        for piece in text.replace("\n", "\r").split("\r"):
            line = piece.rstrip()
            if line:
                self.stream.write(line + "\n")
        return len(text)

    def flush(self) -> None:
        self.stream.flush()


def _is_terminal(stream: TextIO) -> bool:
    isatty = getattr(stream, "isatty", None)
    try:
        return bool(isatty()) if isatty is not None else False
    except ValueError:  # a closed stream
        return False


def progress_bar(
    iterable: Iterable[Any] | None = None,
    *,
    total: int | None = None,
    desc: str,
    unit: str,
    enabled: bool = True,
    initial: int = 0,
    file: TextIO | None = None,
    **kwargs: Any,
) -> Any:
    """A tqdm bar over ``iterable`` (or counted by ``update``) on ``file`` (default stderr):
    redrawn on a terminal, a line every ~10 % or ~30 s (whichever later) elsewhere;
    ``enabled=False`` gives a silent bar (tqdm's ``disable=True``)."""
    from tqdm import tqdm

    if total is None and isinstance(iterable, Sized):
        total = len(iterable)
    stream = file if file is not None else sys.stderr
    common = {"total": total, "desc": desc, "unit": unit, "initial": initial}
    if not enabled:
        return tqdm(iterable, **common, disable=True, **kwargs)
    if _is_terminal(stream):
        return tqdm(iterable, **common, file=stream, **kwargs)
    kwargs.pop("mininterval", None)  # a terminal's redraw rate; the log's is LOG_EVERY_S
    every = max(1, math.ceil(LOG_EVERY_FRACTION * total)) if total else 1
    return tqdm(
        iterable,
        **common,
        file=LineWriter(stream),
        mininterval=LOG_EVERY_S,
        maxinterval=math.inf,  # tqdm's monitor would otherwise force a redraw every 10 s
        miniters=every,
        ncols=100,
        dynamic_ncols=False,
        **kwargs,
    )
