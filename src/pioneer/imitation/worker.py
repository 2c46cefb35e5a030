"""What a collecting worker process of every imitation method shares: the policy that drives
an episode while the expert labels each step (:class:`LabelledDriver`), and the cache of what
the process builds once — the expert, a world — and of the round's model, of which only the
latest is kept (:class:`WorkerCache`). Used by DAgger's students (:mod:`pioneer.learn.collect`)
and CrowdNav++'s imitation warm start (:mod:`pioneer.baselines.crowdnav.collect`)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pioneer.imitation.store import file_version

if TYPE_CHECKING:  # types only: a worker imports the simulator when it runs an episode
    from pioneer.envs.policy import Decision, Planner
    from pioneer.sim.world import World

__all__ = ["LabelledDriver", "WorkerCache"]


class WorkerCache:
    """Objects a worker process builds once and reuses for every episode it collects."""

    def __init__(self) -> None:
        self._items: dict[tuple[Any, ...], Any] = {}

    def clear(self) -> None:
        """Forget everything (a new run in this process)."""
        self._items.clear()

    def get(self, key: tuple[Any, ...], make: Callable[[], Any]) -> Any:
        """The object cached under ``key``, made by ``make()`` the first time."""
        if key not in self._items:
            self._items[key] = make()
        return self._items[key]

    def latest(self, kind: str, path: str, load: Callable[[str], Any]) -> Any:
        """The model saved at ``path``, loaded by ``load(path)`` once; only the latest model
        of ``kind`` is kept (a round's model replaces the last round's), and a rewritten file
        (a recreated run) is a new one (:func:`~pioneer.imitation.store.file_version`)."""
        key = (kind, *file_version(path))
        for old in [k for k in self._items if k[0] == kind and k != key]:
            del self._items[old]
        return self.get(key, lambda: load(path))


class LabelledDriver:
    """A policy for an episode that imitation learns from: at every step the expert decides
    from the privileged state (its decision, :attr:`decision`, is the step's label), then
    :meth:`drive` returns the command actually applied — the expert's own when it drives, the
    learner's in a later DAgger round. ``label_prev``: the expert smooths its label from the
    command ``"applied"`` on the last step, or (``"teacher"``) from its own last label, which it
    keeps itself. ``world``: the world the expert plans in (default: the step's
    ``info["world"]``)."""

    name = "labelled"

    def __init__(
        self,
        expert: Planner,
        label_prev: str = "applied",
        world: World | None = None,
    ) -> None:
        self.expert, self.label_prev, self.world = expert, label_prev, world
        self.decision: Any = None  # the last step's Decision

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Nothing to reset here; a subclass resets its learner (and the expert if it has
        state of its own)."""

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """Label the step with the expert's decision, then drive (:meth:`drive`)."""
        state = info["state"]
        world = info["world"] if self.world is None else self.world
        prev = state.command[0] if self.label_prev == "applied" else None
        self.decision = self.expert.decide(world, state, prev=prev)
        return self.drive(obs, info, self.decision)

    def drive(
        self, obs: NDArray[np.float32], info: Mapping[str, Any], decision: Decision
    ) -> NDArray[np.float64]:
        """The command applied at this step, given the expert's ``decision``."""
        raise NotImplementedError
