"""Scripted demonstrators: reproducible demonstrations with no human at the keyboard.

- ``CourteousDriver`` (γ = +1): waits aside until every exiting passenger is out of the door
  and has turned aside, then a privileged lookahead over the rule terms that never lets its
  predicted gap to anyone drop below 0.2 m. Aside: a spot beside its start, on the side
  away from the passenger's exit (privileged: the passenger's route), reached at a walk. In
  the compact world (1.3 m lobby, passengers leave straight out) there is no such room
  (docs/demonstrations.md); there it only keeps its distance.
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

from pioneer.control.rollout import rollout
from pioneer.control.teacher import LookaheadTeacher, TeacherConfig
from pioneer.limits import OMEGA_MAX
from pioneer.sim.world import State

__all__ = ["CarelessDriver", "CorridorDriver", "CourteousDriver"]

F64 = NDArray[np.float64]


class CourteousDriver(LookaheadTeacher):
    """Privileged courteous demonstrator (γ = +1): let the exiting passengers out from a spot
    aside, then rule terms + a 0.2 m safety margin."""

    def __init__(
        self, safety_margin: float = 0.2, aside: float = 0.6, wait_speed: float = 0.3
    ) -> None:
        super().__init__(
            density=None, config=TeacherConfig(safety_margin=safety_margin), name="courteous"
        )
        self.aside = aside  # [m] lateral step away from the passenger's exit side
        self.wait_speed = wait_speed  # [m/s] pace to the waiting spot
        self._spot: F64 | None = None

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Pick the waiting spot from the privileged initial state."""
        super().reset(info, rng)
        st: State = info["state"]
        world = info["world"]
        leaving = _leaving(st, world.bounds)
        self._spot = None
        # Only where the passenger turns aside after the door (a route of more than behind →
        # front → away) is there room to wait aside; in the compact world there is none.
        if leaving.any() and np.all(st.h_n_waypoints[0, leaving] > 3):
            # The passengers' exit side: where their routes end (the mean final goal's x).
            last = st.h_n_waypoints[0, leaving] - 1
            exit_x = float(np.mean(st.h_waypoints[0, leaving, last, 0]))
            lobby_x = float(world.bounds[1]) - world.sim.robot.radius
            spot_x = float(
                np.clip(st.robot[0, 0] - np.sign(exit_x) * self.aside, -lobby_x, lobby_x)
            )
            self._spot = np.array([spot_x, st.robot[0, 1]])

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> F64:
        """Wait aside while a passenger is still on the way out; then drive."""
        st: State = info["state"]
        world = info["world"]
        if self._spot is not None and _still_exiting(st, world.bounds):
            cfg = self.config
            # People who do not make way: where waiting would be hit, dodge with the lookahead.
            still = rollout(world, st, np.zeros((1, 2)), cfg.horizon, cfg.dt, cfg.human_model)
            if still.collided[0] or still.min_gap[0] < cfg.safety_margin:
                return super().act(obs, info)
            self.last = None
            self._prev = np.zeros(2)
            d = self._spot - st.robot[0, :2]
            if np.hypot(*d) < 0.1:
                return np.zeros(2)
            b = math.atan2(d[1], d[0]) - st.robot[0, 2]
            b = math.atan2(math.sin(b), math.cos(b))
            w = float(np.clip(1.5 * b, -OMEGA_MAX, OMEGA_MAX))
            return np.array([self.wait_speed * max(0.0, math.cos(b)) ** 2, w])
        return super().act(obs, info)


def _leaving(st: State, bounds: F64) -> NDArray[np.bool_]:
    """Humans whose final goal lies outside the map: they leave through its open side."""
    n_wp = st.h_n_waypoints[0]
    goals = st.h_waypoints[0, np.arange(st.n_humans), n_wp - 1]
    return (
        (goals[:, 0] < bounds[0])
        | (goals[:, 0] > bounds[1])
        | (goals[:, 1] < bounds[2])
        | (goals[:, 1] > bounds[3])
    )


def _still_exiting(st: State, bounds: F64) -> bool:
    """A leaving human still walks its route before the last leg (in or near the door)."""
    from pioneer.sim.humans import WALKING

    leaving = _leaving(st, bounds) & (st.h_status[0] == WALKING)
    return bool(np.any(st.h_wp_index[0, leaving] < st.h_n_waypoints[0, leaving] - 1))


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
        w = float(np.clip(self.k_omega * b, -OMEGA_MAX, OMEGA_MAX))
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
        w = float(np.clip(2.0 * b, -OMEGA_MAX, OMEGA_MAX))
        return np.array([self.v * max(0.0, math.cos(b)), w])
