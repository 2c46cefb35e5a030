"""Process pools for episode collection (evaluation harness, DAgger, calibration): spawned
workers with one BLAS thread each, a bounded submission queue so an interrupted run loses
little work, and a stop that never waits for an episode to finish.

The parent alone decides when the work stops. Workers ignore SIGINT and SIGTERM — a Ctrl-C in
a terminal reaches the whole process group, and a worker would print its own traceback — and
they are started with both signals blocked, so not even a half-started worker reacts. Each
worker exits as soon as its parent process ends, however it ends (even by SIGKILL), so none is
ever left behind. When the body of :func:`spawn_pool` raises — an interrupted run
(:class:`~pioneer.interrupt.Interrupted`), a failed task, an abandoned generator — the
pool's pending tasks are cancelled and its workers killed and reaped at once.
"""

from __future__ import annotations

import contextlib
import functools
import multiprocessing as mp
import os
import signal
import threading
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, InvalidStateError, ProcessPoolExecutor, wait
from multiprocessing.connection import wait as wait_ready
from multiprocessing.context import SpawnContext, SpawnProcess
from typing import Any, TypeVar

from pioneer.interrupt import SIGNALS, deferred

__all__ = ["bounded_map", "spawn_pool", "worker_count"]

T = TypeVar("T")
R = TypeVar("R")


class _Worker(SpawnProcess):
    """A pool worker process: started with SIGINT and SIGTERM blocked (the child inherits the
    mask; :func:`_start_worker` then ignores both and unblocks them)."""

    def start(self) -> None:
        """Start the process; a signal meanwhile takes effect once it is started (and so
        known to the pool's stop)."""
        with deferred():
            mask = signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS)
            try:
                super().start()
            finally:
                signal.pthread_sigmask(signal.SIG_SETMASK, mask)


class _Context(SpawnContext):
    """The ``spawn`` context, keeping every process it makes (the pool's workers: a
    ``ProcessPoolExecutor`` starts them through its context's ``Process``)."""

    def __init__(self) -> None:
        super().__init__()
        self.workers: list[_Worker] = []

    # typeshed declares ``Process`` a class attribute; a method is what lets it remember
    def Process(self, *args: Any, **kwargs: Any) -> _Worker:  # type: ignore[override]
        """A new worker, remembered."""
        worker = _Worker(*args, **kwargs)
        self.workers.append(worker)
        return worker


def _start_worker(initializer: Callable[[], None] | None) -> None:
    """Worker side, before any task: ignore SIGINT and SIGTERM, exit with the parent, then
    run the pool's own initializer."""
    for s in SIGNALS:
        signal.signal(s, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, SIGNALS)
    parent = mp.parent_process()
    if parent is not None:
        watch = threading.Thread(target=_exit_with, args=(parent.sentinel,), daemon=True)
        watch.start()
    if initializer is not None:
        initializer()


def _exit_with(parent_sentinel: int) -> None:
    """Block until the parent process ends (its sentinel becomes ready), then end this one."""
    wait_ready([parent_sentinel])
    os._exit(1)


def _kill(workers: list[_Worker]) -> None:
    """Kill every started worker (SIGKILL: an episode holds nothing to clean up) and wait
    until it has ended."""
    started = [w for w in workers if w.pid is not None]
    for w in started:
        if w.is_alive():
            w.kill()
    for w in started:
        w.join(timeout=1.0)


@contextlib.contextmanager
def spawn_pool(
    workers: int, initializer: Callable[[], None] | None = None
) -> Iterator[ProcessPoolExecutor]:
    """A ``spawn`` pool of ``workers`` processes for the block. One BLAS thread per worker:
    the workers already use every core (set in the environment, so the children inherit it).
    If the block raises, pending tasks are cancelled and the workers killed at once (their
    running episodes are lost: a resumed run repeats them); otherwise the pool shuts down
    after its last task."""
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    ctx = _Context()
    pool = ProcessPoolExecutor(
        max_workers=workers,
        mp_context=ctx,
        initializer=functools.partial(_start_worker, initializer),
    )
    try:
        yield pool
    except BaseException:
        with _quiet_broken_pool():
            _kill(ctx.workers)  # the pool finds them dead, fails the pending tasks and stops
            pool.shutdown(wait=True, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


@contextlib.contextmanager
def _quiet_broken_pool() -> Iterator[None]:
    """Keep the pool's manager thread from printing a traceback while a failed pool stops.

    Python 3.11's ``ProcessPoolExecutor``, finding its workers dead, fails every pending task,
    including one that ``shutdown(cancel_futures=True)`` has just cancelled: setting the
    exception of a cancelled future raises ``InvalidStateError`` in its manager thread, whose
    traceback would precede the one error line the run ends with (about one stop in four, a
    race). That exception, and only that one, is dropped; the thread has failed every other
    task by then."""
    previous = threading.excepthook

    def hook(args: threading.ExceptHookArgs) -> None:
        if not isinstance(args.exc_value, InvalidStateError):
            previous(args)

    threading.excepthook = hook
    try:
        yield
    finally:
        threading.excepthook = previous


def bounded_map(
    pool: ProcessPoolExecutor, fn: Callable[[T], R], tasks: Iterable[T], in_flight: int
) -> Iterator[R]:
    """``fn`` over ``tasks`` in ``pool``, yielding results as they finish (any order), with at
    most ``in_flight`` tasks submitted at a time."""
    it = iter(tasks)
    pending: set[Future[R]] = set()
    for t in it:
        pending.add(pool.submit(fn, t))
        if len(pending) >= in_flight:
            break
    while pending:
        done, pending = wait(pending, return_when=FIRST_COMPLETED)
        for f in done:
            yield f.result()
            nxt = next(it, None)
            if nxt is not None:
                pending.add(pool.submit(fn, nxt))


def worker_count(workers: int | None) -> int:
    """The number of worker processes: ``workers``, or one per CPU when it is None (or 0)."""
    return workers or os.cpu_count() or 1
