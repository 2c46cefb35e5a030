"""Stopping a long run on SIGINT or SIGTERM: at once, keeping everything that is finished.

The ``pioneer`` command runs inside :func:`handle_signals`: either signal raises
:class:`Interrupted` in the main thread, which unwinds the run — process pools kill and reap
their workers (:func:`pioneer.parallel.spawn_pool`), a file being written atomically is
dropped — and the CLI prints one line with what was kept and the command that resumes, exit
code 128 + the signal number (130 for SIGINT, 143 for SIGTERM).

A run names what it keeps with :func:`kept` and marks the steps that must not be cut in two
with :func:`deferred` (an evaluation record with its fsync, a training update with its
checkpoint): a signal during one takes effect at its end. Once a run is stopping, further
signals are ignored (the stop takes well under 2 s; SIGKILL still ends the process, and every
run resumes from that too).
"""

from __future__ import annotations

import contextlib
import shlex
import signal
import threading
from collections.abc import Callable, Iterator, Sequence
from types import FrameType

__all__ = ["SIGNALS", "Interrupted", "deferred", "handle_signals", "kept"]

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Interrupted(BaseException):
    """SIGINT or SIGTERM stopped the run. A ``BaseException`` like ``KeyboardInterrupt``, so no
    ``except Exception`` swallows it."""

    def __init__(self, signum: int) -> None:
        self.signum = signum
        self.kept: str | None = None  # what the run keeps, for the CLI's line (see kept())
        self.resumes = True  # whether running the command again resumes it (see kept())
        super().__init__(self.name)

    @property
    def name(self) -> str:
        """``SIGINT`` or ``SIGTERM``."""
        return signal.Signals(self.signum).name

    @property
    def exit_code(self) -> int:
        """128 + the signal number, as a shell reports a process ended by it."""
        return 128 + self.signum

    def message(self, command: Sequence[str]) -> str:
        """One line: the signal, and for a run that keeps its work what it kept and
        ``command`` (the argument vector that resumes it)."""
        if self.kept is None:
            return f"interrupted ({self.name})"
        if not self.resumes:
            return f"interrupted ({self.name}); {self.kept}"
        return f"interrupted ({self.name}); {self.kept}; resume with: {shlex.join(command)}"


_depth = 0  # open deferred() blocks
_pending: int | None = None  # a signal received inside one
_stopping = False  # Interrupted was raised: ignore further signals
_active = False  # inside handle_signals(): our handlers are installed


def _handler(signum: int, frame: FrameType | None) -> None:
    global _pending, _stopping
    if _stopping or _pending is not None:
        return
    if _depth:
        _pending = signum
        return
    _stopping = True
    raise Interrupted(signum)


@contextlib.contextmanager
def handle_signals() -> Iterator[None]:
    """SIGINT and SIGTERM raise :class:`Interrupted` inside the block; the previous handlers
    are restored after it. Outside the main thread (where Python cannot set handlers) the
    block runs unchanged."""
    global _pending, _stopping, _active
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in SIGNALS}
    _pending, _stopping, _active = None, False, True
    for s in SIGNALS:
        signal.signal(s, _handler)
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, signal.SIG_DFL if h is None else h)
        # A signal held by a deferred() block whose own exception won dies with the block
        # that handled it; it must not surface in a later, unrelated deferred() block.
        _pending, _stopping, _active = None, False, False


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Hold a signal received inside the block until its end, then raise :class:`Interrupted`
    (blocks nest; the outermost one raises). If the block itself raises, its exception wins.
    Main thread only, like the handlers."""
    global _depth, _pending, _stopping
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
    if not _depth and _pending is not None and _active:
        signum, _pending, _stopping = _pending, None, True
        raise Interrupted(signum)


@contextlib.contextmanager
def kept(describe: Callable[[], str], resumes: bool = True) -> Iterator[None]:
    """Name what a run keeps when it is interrupted inside the block: ``describe()``, e.g.
    ``"37 of 120 episodes kept in runs/e/episodes.jsonl"``. The innermost block names it;
    ``resumes=False``: the command run again does not resume (the line gives no command)."""
    try:
        yield
    except Interrupted as exc:
        if exc.kept is None:
            exc.kept = describe()
            exc.resumes = resumes
        raise
