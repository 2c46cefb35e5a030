"""The one interface every controller implements: teacher, baselines and students.

A policy sees the observation (29-D, paper §III-A) and the environment's ``info`` dict, whose
``state`` and ``world`` entries give privileged controllers the full simulator state. Policies
hold their own RNG, seeded by ``reset``, and never touch the global numpy RNG. Policies are
constructed by name through :mod:`pioneer.control.registry`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

__all__ = ["Policy"]


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
