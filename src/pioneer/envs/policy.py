"""The one interface every controller implements: teacher, baselines and students.

A policy sees the observation (29-D, paper §III-A) and the environment's ``info`` dict, whose
``state`` and ``world`` entries give privileged controllers the full simulator state. Policies
hold their own RNG, seeded by ``reset``, and never touch the global numpy RNG. Policies are
constructed by name through :mod:`pioneer.control.registry`.

A privileged planner (the teacher, CVaR-BF, DWA, the social-force robot) is also a
:class:`Planner`: ``decide(world, state, prev)`` returns a :class:`Decision` (the command and,
in a subclass, why), which DAgger's labeller and the CrowdNav++ imitation call directly.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from pioneer.sim.world import State, World

__all__ = ["Decision", "Planner", "Policy"]


@runtime_checkable
class Policy(Protocol):
    """A controller: ``reset`` at the start of an episode, then one ``act`` per 0.1 s step."""

    name: str

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Start an episode; ``info`` is what ``env.reset`` returned."""
        ...

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """The command ``(v [m/s], ω [rad/s])`` for this step, shape ``(2,)``."""
        ...


@dataclasses.dataclass(frozen=True)
class Decision:
    """What a planner decided in one state; subclasses add why (scores, risk levels)."""

    command: NDArray[np.float64]  # (2,) the command sent, (v [m/s], ω [rad/s])


@runtime_checkable
class Planner(Protocol):
    """A privileged controller that decides from the simulator's world and state."""

    def decide(
        self, world: World, state: State, prev: NDArray[np.float64] | None = None
    ) -> Decision:
        """The decision in ``state`` (B = 1). ``prev``: the command applied on the last step
        when it was not this planner's own (a labeller's); planners that read the last command
        from ``state.command`` need not use it."""
        ...
