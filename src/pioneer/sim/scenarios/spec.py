"""Scenario data: sampling regions, human specifications and the scenario config."""

from __future__ import annotations

import dataclasses
import math
from typing import Annotated

import numpy as np
from annotated_types import MinLen

from pioneer.bounds import Count, NonNegative, Positive, Span
from pioneer.config import Config
from pioneer.errors import ScenarioError, expect
from pioneer.sim.world import SimConfig, World

Segment = tuple[float, float, float, float]
Point = tuple[float, float]
MAX_TRIES = 2000


@dataclasses.dataclass(frozen=True)
class Region(Config):
    """Axis-aligned sampling box [m]; a degenerate box is a fixed point."""

    error_type = ScenarioError

    x: Span
    y: Span

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        """A uniform point in the box, shape ``(2,)``."""
        return np.array([rng.uniform(*self.x), rng.uniform(*self.y)])

    @property
    def center(self) -> np.ndarray:
        """Centre of the box, shape ``(2,)``."""
        return np.array([sum(self.x) / 2, sum(self.y) / 2])

    def mirrored(self) -> Region:
        """Mirror image across x = 0."""
        return Region(x=(-self.x[1], -self.x[0]), y=self.y)


@dataclasses.dataclass(frozen=True)
class HumanSpec(Config):
    """One human: where it starts, the waypoints it follows and where it ends."""

    error_type = ScenarioError

    role: str  # "boarding", "exiting", "static" or "walking" (free text for plots)
    start: Region
    goal: Region
    waypoints: tuple[Point, ...] = ()  # [m] visited in order before the goal
    radius: Positive = 0.6  # [m] r_h
    # [m/s] sampled uniformly
    v_pref_choices: Annotated[tuple[NonNegative, ...], MinLen(1)] = (0.5, 0.6, 0.7)
    static: bool = False  # True: never moves (an obstacle from t = 0)
    start_delay: Span = (0.0, 0.0)  # [s] sampled; stands still until then
    wait_for: tuple[int, ...] = ()  # indices of humans that must have left/arrived first
    # Those waiting for this human go once it heads for waypoint index >= this (None: only
    # once it has arrived or left the map); e.g. 2 = once past its second waypoint.
    release_waypoint: Count | None = None
    reacts_to_robot: bool = True  # False: the robot is invisible to this human

    def __post_init__(self) -> None:
        if self.release_waypoint is not None and self.release_waypoint > len(self.waypoints):
            raise ScenarioError(
                expect(
                    "HumanSpec.release_waypoint",
                    f"None or an integer in 1..{len(self.waypoints)} (its waypoints)",
                    self.release_waypoint,
                    "fix it or use null",
                )
            )


@dataclasses.dataclass(frozen=True)
class ScenarioConfig(Config):
    """Everything that defines a scenario; validated on construction."""

    error_type = ScenarioError

    name: str
    walls: tuple[Segment, ...]
    bounds: tuple[float, float, float, float]  # [m] xmin, xmax, ymin, ymax of the map
    robot_start: Region
    robot_goal: Region
    robot_heading: Span  # [rad] sampled uniformly
    humans: tuple[HumanSpec, ...]
    min_start_gap: NonNegative = 0.05  # [m] clearance between all bodies and walls at t = 0
    sim: SimConfig = SimConfig()

    def __post_init__(self) -> None:
        xmin, xmax, ymin, ymax = self.bounds
        if not (xmin < xmax and ymin < ymax):
            raise ScenarioError(
                expect(
                    "ScenarioConfig.bounds",
                    "xmin < xmax, ymin < ymax",
                    self.bounds,
                    "order the bounds (xmin, xmax, ymin, ymax)",
                )
            )
        for i, h in enumerate(self.humans):
            bad = [j for j in h.wait_for if not 0 <= j < len(self.humans) or j == i]
            if bad:
                raise ScenarioError(
                    expect(
                        f"{self.name}: humans[{i}].wait_for",
                        f"indices of other humans in 0..{len(self.humans) - 1}",
                        bad,
                        "remove the invalid indices",
                    )
                )
        # Every human must be placeable: some point of its start region clear of the walls.
        walls = np.asarray(self.walls, dtype=np.float64).reshape(-1, 4)
        rng = np.random.default_rng(0)
        for i, h in enumerate(self.humans):
            if not _fits(h.start, walls, h.radius + self.min_start_gap, rng):
                raise ScenarioError(
                    expect(
                        f"{self.name}: humans[{i}].start ({h.role})",
                        f"a region where a body of radius {h.radius} m fits clear of the walls",
                        {"x": h.start.x, "y": h.start.y},
                        "move the start region away from the walls or reduce the radius",
                    )
                )
        r_r = self.sim.robot.radius
        if not _fits(self.robot_start, walls, r_r + self.min_start_gap, rng):
            raise ScenarioError(
                expect(
                    f"{self.name}: robot_start",
                    f"a region where the robot (radius {r_r} m) fits clear of the walls",
                    {"x": self.robot_start.x, "y": self.robot_start.y},
                    "move the region away from the walls",
                )
            )

    def world(self) -> World:
        """The static :class:`World` of this scenario."""
        return World(
            walls=np.asarray(self.walls, dtype=np.float64),
            bounds=np.asarray(self.bounds),
            sim=self.sim,
        )


def _fits(region: Region, walls: np.ndarray, clearance: float, rng: np.random.Generator) -> bool:
    """Whether some point of ``region`` — its centre, else one of 256 drawn from ``rng`` — is
    ``clearance`` clear of every wall. The points are drawn only when needed: the centre
    usually fits, and a scenario is built for every episode."""
    if _wall_distance(np.asarray(region.center), walls) >= clearance:
        return True
    return any(_wall_distance(region.sample(rng), walls) >= clearance for _ in range(256))


def _wall_distance(p: np.ndarray, walls: np.ndarray) -> float:
    return float(_wall_distances(np.asarray(p, dtype=np.float64)[None], walls)[0])


def _wall_distances(points: np.ndarray, walls: np.ndarray) -> np.ndarray:
    """The distance from each of ``points (P, 2)`` to the nearest wall segment, ``(P,)``, in one
    pass over the walls (∞ without walls)."""
    if walls.shape[0] == 0:
        return np.full(points.shape[0], math.inf)
    a = walls[:, :2]
    e = walls[:, 2:] - a
    ll = np.maximum(np.einsum("ij,ij->i", e, e), 1e-18)
    s = np.clip(np.einsum("pij,ij->pi", points[:, None, :] - a, e) / ll, 0.0, 1.0)
    return np.min(np.linalg.norm(a + s[..., None] * e - points[:, None, :], axis=-1), axis=1)
