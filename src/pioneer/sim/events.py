"""How a step ends an episode: one event type and one classifier for every loop.

An episode ends at the first step that collides (humans or walls, swept over the step) or
reaches the goal — a collision wins when both happen in one step — or, failing both, when the
time limit is reached. The Gymnasium environments, the PPO trainer, the imitation collector
and the evaluation records all classify with :func:`classify`.
"""

from __future__ import annotations

import enum

import numpy as np
from numba import njit
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


# The codes as plain ints for the compiled classifier.
_COLLISION = int(Event.COLLISION)
_SUCCESS = int(Event.SUCCESS)
_TIMEOUT = int(Event.TIMEOUT)


@njit(cache=True)
def _classify(
    prev_collided: NDArray[np.bool_],
    prev_reached: NDArray[np.bool_],
    collided: NDArray[np.bool_],
    reached: NDArray[np.bool_],
    t: NDArray[np.float64],
    t_end: float,
) -> NDArray[np.int8]:  # pragma: no cover - compiled
    out = np.zeros(collided.shape[0], dtype=np.int8)
    for b in range(collided.shape[0]):
        if collided[b] and not prev_collided[b]:
            out[b] = _COLLISION
        elif reached[b] and not prev_reached[b]:
            out[b] = _SUCCESS
        elif t[b] >= t_end:
            out[b] = _TIMEOUT
    return out


def classify(prev: State, new: State, time_limit: float) -> NDArray[np.int8]:
    """Event code of the step ``prev → new`` per copy, ``(B,)`` int8 (values of :class:`Event`).

    Only what happened in this step counts (a copy that had already collided or arrived is not
    counted again); a collision wins over an arrival in the same step, and either over the
    time limit. (One compiled loop: the single environment classifies every step.)"""
    return _classify(
        prev.collided, prev.reached, new.collided, new.reached, new.t, time_limit - TIME_EPS
    )
