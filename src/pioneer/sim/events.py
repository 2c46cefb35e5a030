"""How a step ends an episode: one event type and one classifier for every loop.

An episode ends at the first step that collides (humans or walls, swept over the step) or
reaches the goal — a collision wins when both happen in one step — or, failing both, when the
time limit is reached. The Gymnasium environments, the PPO trainer, the imitation collector
and the evaluation records all classify with :func:`classify`.
"""

from __future__ import annotations

import enum

import numpy as np
from numpy.typing import NDArray

from pioneer.sim.world import State

__all__ = ["TIME_EPS", "Event", "classify"]

TIME_EPS = 1e-9  # [s] tolerance of the time-limit comparison (t accumulates Δt)


class Event(enum.IntEnum):
    """Outcome of a step; ``NONE`` while the episode goes on. Stored as int8 codes."""

    NONE = 0
    SUCCESS = 1
    COLLISION = 2
    TIMEOUT = 3

    @property
    def label(self) -> str | None:
        """The record's text: ``"success"``, ``"collision"``, ``"timeout"`` or ``None``."""
        return None if self is Event.NONE else self.name.lower()


# The codes as plain int8 scalars: an IntEnum member lookup costs ≈ 1 µs, and the single
# environment classifies every step.
_COLLISION = np.int8(Event.COLLISION)
_SUCCESS = np.int8(Event.SUCCESS)
_TIMEOUT = np.int8(Event.TIMEOUT)


def classify(prev: State, new: State, time_limit: float) -> NDArray[np.int8]:
    """Event code of the step ``prev → new`` per copy, ``(B,)`` int8 (values of :class:`Event`).

    Only what happened in this step counts (a copy that had already collided or arrived is not
    counted again)."""
    collided = new.collided & ~prev.collided
    reached = new.reached & ~prev.reached & ~collided
    timeout = ~(collided | reached) & (new.t >= time_limit - TIME_EPS)
    return np.where(
        collided, _COLLISION, np.where(reached, _SUCCESS, np.where(timeout, _TIMEOUT, 0))
    ).astype(np.int8)
