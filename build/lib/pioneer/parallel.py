"""Process pools for episode collection (evaluation harness, DAgger): spawn workers with one
BLAS thread each, and a bounded submission queue so an interrupted run loses little work."""

from __future__ import annotations

import multiprocessing as mp
import os
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import TypeVar

__all__ = ["bounded_map", "spawn_pool"]

T = TypeVar("T")
R = TypeVar("R")


def spawn_pool(workers: int, initializer: Callable[[], None] | None = None) -> ProcessPoolExecutor:
    """A ``spawn`` pool of ``workers`` processes. One BLAS thread per worker: the workers
    already use every core (set in the environment, so the children inherit it)."""
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    ctx = mp.get_context("spawn")
    return ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=initializer)


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
