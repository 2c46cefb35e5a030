"""Scripted demonstrators: reproducible demonstrations with no human at the keyboard (SPEC 2).

- ``CourteousDriver`` (γ = +1): a privileged lookahead over the rule terms that never lets its
  predicted clearance to anyone drop below 0.2 m. With the paper's 0.6 m bodies the lobby has
  no place where the robot is clear of the exit lane (docs/demonstrations.md), so it cannot
  literally wait aside: it lets the passenger out by keeping its distance, entering along the
  far side of the door and letting them pass inside the 2.5 m cabin.
- ``CarelessDriver`` (γ = −1 near collisions): drives straight at the goal, ignoring people;
  speed and steering gain vary with the seed. Only the frames in the last 1.0 s before a
  collision are kept, labelled γ = −1.
- ``CorridorDriver`` (static study): follows one of the two corridors around the central
  human (a waypoint beside it, then the goal); with ``through_middle`` it heads straight at the
  human and its pre-collision frames are the negatives.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.control.teacher import LookaheadTeacher, TeacherConfig
from pioneer.sim.world import State

__all__ = ["CarelessDriver", "CorridorDriver", "CourteousDriver"]

F64 = NDArray[np.float64]


class CourteousDriver(LookaheadTeacher):
    """Privileged courteous demonstrator (γ = +1): rule terms + a 0.2 m safety margin."""

    def __init__(self, safety_margin: float = 0.2) -> None:
        super().__init__(
            density=None, config=TeacherConfig(safety_margin=safety_margin), name="courteous"
        )


class CarelessDriver:
    """Straight to the goal, ignoring people (negatives come from its collisions)."""

    name = "careless"

    def __init__(self, v: float = 0.7, k_omega: float = 1.5) -> None:
        self.v = v  # [m/s]
        self.k_omega = k_omega  # [1/s]

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Draw this episode's speed and steering gain."""
        self.v = float(rng.uniform(0.5, 0.8))
        self.k_omega = float(rng.uniform(1.0, 2.5))

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> F64:
        """Turn toward the goal; drive whenever roughly facing it."""
        b = float(obs[-1])
        w = float(np.clip(self.k_omega * b, -0.4 * math.pi, 0.4 * math.pi))
        return np.array([self.v * max(0.0, math.cos(b)), w])


class CorridorDriver:
    """Static study: pass the central human on the ``side`` (+1 right, −1 left) or hit it."""

    name = "corridor"

    def __init__(self, side: float = 1.0, through_middle: bool = False) -> None:
        self.side = side
        self.through_middle = through_middle
        self._wp: list[F64] = []

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Pick waypoints with some seed-dependent variety."""
        goal = np.asarray(info["goal"], dtype=np.float64)
        st: State = info["state"]
        h = st.h_pos[0, 0]
        r = st.h_radius[0, 0]
        if self.through_middle:
            self._wp = [h + rng.normal(0.0, 0.15, 2), goal]
        else:
            off = r + 0.3 + rng.uniform(0.25, 0.55)
            self._wp = [
                h + np.array([self.side * off, -0.6 + rng.normal(0, 0.1)]),
                h + np.array([self.side * off, 0.6 + rng.normal(0, 0.1)]),
                goal,
            ]
        self.v = float(rng.uniform(0.45, 0.75))

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> F64:
        """Pure pursuit of the current waypoint."""
        pose = np.asarray(info["robot_pose"])
        while len(self._wp) > 1 and np.linalg.norm(self._wp[0] - pose[:2]) < 0.35:
            self._wp.pop(0)
        d = self._wp[0] - pose[:2]
        b = math.atan2(d[1], d[0]) - pose[2]
        b = math.atan2(math.sin(b), math.cos(b))
        w = float(np.clip(2.0 * b, -0.4 * math.pi, 0.4 * math.pi))
        return np.array([self.v * max(0.0, math.cos(b)), w])
