"""The DAgger round loop (Ross, Gordon and Bagnell, AISTATS 2011) over a :class:`RunFolder`.

Round 0 is driven by the expert; round r ≥ 1 by the model fitted after round r − 1, that is
on the aggregate of rounds 0..r − 1 (the paper's β = 0 after round 0). The expert labels every
step of every round. After each round the method fits a model on the aggregate of rounds
0..r, saved as that round's model; the last round's model is the run's result.

Resume: an episode whose file exists is not collected again and a round whose model file
exists is not fitted again (its model is loaded), so a rerun of an interrupted run ends with
the files of an uninterrupted one as long as collecting and fitting are deterministic.

The per-method parts are a :class:`Method` — the arguments that collect one episode, what the
aggregate of episodes is, the loss, the fit and the model files — and a :class:`Collector`:
the top-level function that collects one episode from those arguments and writes it
(:func:`~pioneer.imitation.store.save_episode`), run in this process or in a pool of spawned
worker processes (:func:`pioneer.parallel.spawn_pool`). The driver reaches it as the path of
the model file it drives with, so a worker loads (and may cache) the model itself.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from collections.abc import Callable, Generator, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, Generic, Protocol, TypeVar

from pioneer.imitation.store import RunFolder
from pioneer.parallel import bounded_map, spawn_pool

__all__ = ["Collector", "Fitted", "Method", "Step", "one_thread", "run_rounds"]

D = TypeVar("D")  # the aggregate of episodes a model is fitted on
M = TypeVar("M")  # a model

EpisodeArrays = Mapping[str, Any]  # one episode's arrays, as stored


@dataclasses.dataclass(frozen=True)
class Step(Generic[D, M]):
    """A collected round, before its model is fitted."""

    round: int
    episodes: list[dict[str, Any]]  # this round's, in index order
    data: D  # the aggregate of rounds 0..round, in (round, index) order
    previous: M | None  # the model fitted after the round before: this round's driver
    # ``previous``'s loss on this round's episodes (NaN in round 0): the loss of the online
    # learner on the states it led to, the quantity DAgger's guarantee is about
    loss_new: float


@dataclasses.dataclass(frozen=True)
class Fitted(Generic[D, M]):
    """A finished round: its step, its model and the information saved with it."""

    step: Step[D, M]
    model: M
    info: dict[str, Any]
    fitted: bool  # False: loaded from the round's model file (a resumed run)


class Method(Protocol[D, M]):
    """The parts of one imitation method that the round loop calls."""

    def task(self, rnd: int, index: int, path: Path, driver: Path | None) -> Any:
        """The arguments of the :class:`Collector` function for episode ``index`` of round
        ``rnd``, to be written to ``path``; ``driver`` is the model file to drive with
        (``None``: the expert drives). Picklable when collected in worker processes."""
        ...

    def aggregate(self, episodes: Sequence[EpisodeArrays]) -> D:
        """What a model is fitted on: the ``episodes`` together, in their order."""
        ...

    def loss(self, model: M, data: D) -> float:
        """``model``'s imitation loss on ``data``."""
        ...

    def fit(self, step: Step[D, M]) -> tuple[M, dict[str, Any]]:
        """The model of ``step`` (fitted on ``step.data``; it may go on training
        ``step.previous``) and the information to save with it."""
        ...

    def save(self, model: M, path: Path, info: dict[str, Any]) -> None:
        """Write ``model`` and ``info`` to ``path`` (atomically)."""
        ...

    def load(self, path: Path) -> tuple[M, dict[str, Any]]:
        """The model and information :meth:`save` wrote to ``path``."""
        ...


def one_thread() -> None:
    """Initialise a collecting process: one BLAS thread and one torch thread (the workers
    already use every core, and float sums depend on the thread count). Imports torch."""
    import torch
    from threadpoolctl import threadpool_limits

    threadpool_limits(1, user_api="blas")
    torch.set_num_threads(1)


@dataclasses.dataclass(frozen=True)
class Collector:
    """How episodes are collected: ``collect`` — a top-level function — collects and writes
    one episode from the arguments of :meth:`Method.task`, in this process (``workers`` 1)
    or in ``workers`` spawned processes, each initialised by ``init`` (this process too when
    it collects). One pool serves the whole run, so workers keep what they cache."""

    collect: Callable[[Any], object]
    init: Callable[[], None] | None = None
    workers: int = 1

    @contextlib.contextmanager
    def open(self) -> Iterator[Callable[[list[Any]], Iterator[object]]]:
        """For the block: a function that collects a list of tasks, yielding as each ends."""
        if self.workers <= 1:
            if self.init is not None:
                self.init()
            yield lambda tasks: (self.collect(t) for t in tasks)
            return
        with spawn_pool(self.workers, self.init) as pool:
            yield lambda tasks: bounded_map(pool, self.collect, tasks, 2 * self.workers)


def run_rounds(
    folder: RunFolder,
    sizes: Sequence[int],
    method: Method[D, M],
    collector: Collector,
    on_round_start: Callable[[int, int], None] | None = None,
    on_episode: Callable[[], None] | None = None,
) -> Generator[Fitted[D, M], None, None]:
    """Run (or resume) the rounds of ``sizes[r]`` episodes each in ``folder`` (prepared by
    :meth:`RunFolder.prepare`), yielding each finished round. ``on_round_start(r, k)``: round
    r starts with k episodes to collect; ``on_episode()``: one was written. Close the
    generator when stopping early (``contextlib.closing``): that ends a pool at once; name
    what an interrupted run keeps with :meth:`RunFolder.kept` (:func:`pioneer.interrupt.kept`)."""
    with collector.open() as collect:
        episodes: list[dict[str, Any]] = []
        previous: M | None = None
        for rnd, n in enumerate(sizes):
            driver = folder.model_path(rnd - 1) if rnd > 0 else None
            todo = folder.missing(rnd, n)
            if on_round_start is not None:
                on_round_start(rnd, len(todo))
            tasks = [method.task(rnd, i, folder.episode_path(rnd, i), driver) for i in todo]
            for _ in collect(tasks):
                if on_episode is not None:
                    on_episode()
            new = folder.load_round(rnd, n)
            episodes.extend(new)
            loss_new = math.nan
            if previous is not None:
                loss_new = method.loss(previous, method.aggregate(new))
            step = Step(rnd, new, method.aggregate(episodes), previous, loss_new)
            path = folder.model_path(rnd)
            fitted = not path.exists()
            if fitted:
                model, info = method.fit(step)
                method.save(model, path, info)
            else:
                model, info = method.load(path)
            yield Fitted(step, model, info, fitted)
            previous = model
