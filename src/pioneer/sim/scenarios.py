"""Scenarios as data: elevator co-boarding (HR-RL, HL-RR) and the static study (SPEC 1.5).

Coordinate frame: origin at the centre of the elevator door on the wall line, +y into the
cabin. A :class:`ScenarioConfig` holds walls, map bounds, sampling regions and the human
specifications; :func:`elevator_scenario` builds one from an :class:`ElevatorLayout`, so door
width, cabin size, radii and the number of boarding/exiting humans are configuration.
:func:`sample_state` draws an initial state from a seeded generator, rejecting overlaps.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pioneer.config import Config, check_nonnegative, check_positive, check_range
from pioneer.errors import ConfigError, PioneerError, ScenarioError, expect
from pioneer.sim.humans import ARRIVED, WALKING, SocialForceConfig
from pioneer.sim.world import SimConfig, State, World

__all__ = [
    "SCENARIOS_ENV",
    "SCENARIO_FILE_FORMAT",
    "ElevatorLayout",
    "HumanSpec",
    "Region",
    "ScenarioConfig",
    "StaticStudyLayout",
    "elevator_scenario",
    "get_scenario",
    "load_env_scenarios",
    "load_scenario_file",
    "pin_scenario",
    "register_scenario",
    "sample_state",
    "scenario_base",
    "scenario_names",
    "static_study_scenario",
]

Segment = tuple[float, float, float, float]
Point = tuple[float, float]
MAX_TRIES = 2000


@dataclasses.dataclass(frozen=True)
class Region(Config):
    """Axis-aligned sampling box [m]; a degenerate box is a fixed point."""

    x: tuple[float, float]
    y: tuple[float, float]

    def __post_init__(self) -> None:
        check_range("Region", "x", *self.x)
        check_range("Region", "y", *self.y)

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

    role: str  # "boarding", "exiting", "static" or "walking" (free text for plots)
    start: Region
    goal: Region
    waypoints: tuple[Point, ...] = ()  # [m] visited in order before the goal
    radius: float = 0.6  # [m] r_h
    v_pref_choices: tuple[float, ...] = (0.5, 0.6, 0.7)  # [m/s] sampled uniformly
    static: bool = False  # True: never moves (an obstacle from t = 0)
    start_delay: tuple[float, float] = (0.0, 0.0)  # [s] sampled; stands still until then
    wait_for: tuple[int, ...] = ()  # indices of humans that must have left/arrived first
    # Those waiting for this human go once it heads for waypoint index >= this (None: only
    # once it has arrived or left the map); e.g. 2 = once past its second waypoint.
    release_waypoint: int | None = None
    reacts_to_robot: bool = True  # False: the robot is invisible to this human

    def __post_init__(self) -> None:
        check_positive("HumanSpec", "radius", self.radius)
        if self.release_waypoint is not None and not (
            isinstance(self.release_waypoint, int)
            and 1 <= self.release_waypoint <= len(self.waypoints)
        ):
            raise ScenarioError(
                expect(
                    "HumanSpec.release_waypoint",
                    f"None or an integer in 1..{len(self.waypoints)} (its waypoints)",
                    self.release_waypoint,
                    "fix it or use null",
                )
            )
        check_range("HumanSpec", "start_delay", *self.start_delay)
        if not self.v_pref_choices or any(
            not (math.isfinite(v) and v >= 0) for v in self.v_pref_choices
        ):
            raise ScenarioError(
                expect("HumanSpec.v_pref_choices", "non-empty, >= 0", self.v_pref_choices, "fix")
            )


@dataclasses.dataclass(frozen=True)
class ScenarioConfig(Config):
    """Everything that defines a scenario; validated on construction."""

    name: str
    walls: tuple[Segment, ...]
    bounds: tuple[float, float, float, float]  # [m] xmin, xmax, ymin, ymax of the map
    robot_start: Region
    robot_goal: Region
    robot_heading: tuple[float, float]  # [rad] sampled uniformly
    humans: tuple[HumanSpec, ...]
    min_start_gap: float = 0.05  # [m] clearance between all bodies and walls at t = 0
    sim: SimConfig = SimConfig()

    def __post_init__(self) -> None:
        check_nonnegative("ScenarioConfig", "min_start_gap", self.min_start_gap)
        check_range("ScenarioConfig", "robot_heading", *self.robot_heading)
        xmin, xmax, ymin, ymax = self.bounds
        if not (xmin < xmax and ymin < ymax):
            raise ScenarioError(
                expect("ScenarioConfig.bounds", "xmin < xmax, ymin < ymax", self.bounds, "fix")
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
            pts = [h.start.center] + [h.start.sample(rng) for _ in range(256)]
            if not any(_wall_distance(p, walls) >= h.radius + self.min_start_gap for p in pts):
                raise ScenarioError(
                    expect(
                        f"{self.name}: humans[{i}].start ({h.role})",
                        f"a region where a body of radius {h.radius} m fits clear of the walls",
                        {"x": h.start.x, "y": h.start.y},
                        "move the start region away from the walls or reduce the radius",
                    )
                )
        r_r = self.sim.robot.radius
        pts = [self.robot_start.center] + [self.robot_start.sample(rng) for _ in range(256)]
        if not any(_wall_distance(p, walls) >= r_r + self.min_start_gap for p in pts):
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


def _wall_distance(p: np.ndarray, walls: np.ndarray) -> float:
    if walls.shape[0] == 0:
        return math.inf
    a = walls[:, :2]
    e = walls[:, 2:] - a
    ll = np.maximum(np.einsum("ij,ij->i", e, e), 1e-18)
    s = np.clip(np.einsum("ij,ij->i", p - a, e) / ll, 0.0, 1.0)
    return float(np.min(np.linalg.norm(a + s[:, None] * e - p, axis=1)))


# --------------------------------------------------------------------------------------------
# Elevator co-boarding


@dataclasses.dataclass(frozen=True)
class ElevatorLayout(Config):
    """Geometry and population of the elevator co-boarding scenario (paper §V-B, SPEC 1.5).

    The defaults are the paper world: a 4 × 4 m lobby in front of the attached 2.5 × 2.7 m
    cabin. Positions are in HR-RL coordinates (humans board to the right half); ``human_side =
    "left"`` mirrors every x. A start-region field set to ``None`` is derived from the geometry
    by the rules of the earlier compact world (:meth:`compact`), which stays reproducible.
    The values of the free fields were chosen by world statistics (docs/calibration.md).
    """

    human_side: str = "right"  # "right" → HR-RL (robot goal left); "left" → HL-RR
    cabin_width: float = 2.5  # [m] Schindler 6000
    cabin_depth: float = 2.7  # [m]
    door_width: float = 1.8  # [m]
    lobby_width: float = 4.0  # [m] walled on its left and right
    lobby_depth: float = 4.0  # [m] the far side (y = −lobby_depth) is open
    n_boarding: int = 2  # humans boarding from the lobby (alternating sides of the robot)
    n_exiting: int = 1  # humans leaving the cabin through the door
    human_radius: float = 0.6  # [m] the paper's value
    v_pref_choices: tuple[float, ...] = (0.5, 0.6, 0.7)  # [m/s]
    robot_start_half_width: float = 0.25  # [m] robot start x ∈ ±this
    robot_start_y: tuple[float, float] | None = (-2.4, -2.0)  # [m] None: compact rule
    boarder_x: tuple[float, float] | None = (1.2, 1.3)  # [m] |x| of a boarder's start
    boarder_y: tuple[float, float] | None = (-3.8, -3.3)  # [m] beside, behind the robot
    boarding_delay: tuple[float, float] = (0.5, 1.5)  # [s] boarders' reaction time
    # The first boarder starts on the robot's goal side, the next on the humans' side, … (so
    # HL-RR is the mirror image of HR-RL); False: the first on the right in both (compact).
    first_boarder_on_goal_side: bool = True
    boarders_queue: bool = True  # let the exiting passengers out first, then board one by one
    exit_start_x: tuple[float, float] = (-0.5, 0.5)  # [m] exiting passengers start in the cabin
    exit_start_y: tuple[float, float] | None = None  # [m] None: r_h + 0.3 … r_h + 0.9 (≤ depth)
    # After the door, the exiting passenger turns aside through these points (HR-RL: to the
    # humans' side, ahead of the robot), then leaves through the open far side below the last
    # one. None: straight out (compact rule).
    exit_waypoints: tuple[Point, ...] | None = ((1.2, -1.6),)  # [m]
    # Boarders go once the exiting passenger heads for this waypoint index (1 = the one in
    # front of the door, 2 = the first after it, …); None: once it has left the map.
    exit_release_waypoint: int | None = 2
    # A later boarder goes once the one before it heads for this waypoint index (1 = in front
    # of the door, 2 = just inside the cabin, 3 = its spot); None: once it has arrived.
    boarder_release_waypoint: int | None = 1
    boarders_react_to_robot: bool = True  # False: the robot is invisible to the boarders
    exiting_react_to_robot: bool = True  # False: … to the exiting passengers
    margin: float = 0.05  # [m] extra clearance from walls for sampled positions
    min_start_gap: float = 0.1  # [m] clearance between all bodies and walls at t = 0

    @classmethod
    def compact(cls, human_side: str = "right") -> ElevatorLayout:
        """The earlier default world: the 4 × 4 m map contains the cabin (1.3 m lobby)."""
        return cls(
            human_side=human_side,
            lobby_depth=1.3,
            robot_start_y=None,
            boarder_x=None,
            boarder_y=None,
            exit_waypoints=None,
            exit_release_waypoint=None,
            boarder_release_waypoint=None,
            first_boarder_on_goal_side=False,
            min_start_gap=0.05,
        )

    def __post_init__(self) -> None:
        for name in ("cabin_width", "cabin_depth", "door_width", "lobby_width", "lobby_depth"):
            check_positive("ElevatorLayout", name, getattr(self, name))
        check_positive("ElevatorLayout", "human_radius", self.human_radius)
        check_nonnegative("ElevatorLayout", "margin", self.margin)
        check_nonnegative("ElevatorLayout", "min_start_gap", self.min_start_gap)
        check_nonnegative("ElevatorLayout", "robot_start_half_width", self.robot_start_half_width)
        check_range("ElevatorLayout", "boarding_delay", *self.boarding_delay)
        for name in ("robot_start_y", "boarder_x", "boarder_y", "exit_start_x", "exit_start_y"):
            value = getattr(self, name)
            if value is not None:
                check_range("ElevatorLayout", name, *value)
        if self.human_side not in ("right", "left"):
            raise ScenarioError(
                expect("ElevatorLayout.human_side", "'right' or 'left'", self.human_side, "fix")
            )
        if self.door_width > self.cabin_width:
            raise ScenarioError(
                expect(
                    "ElevatorLayout.door_width",
                    f"<= cabin_width ({self.cabin_width} m)",
                    self.door_width,
                    "narrow the door or widen the cabin",
                )
            )
        if self.cabin_width > self.lobby_width:
            raise ScenarioError(
                expect(
                    "ElevatorLayout.cabin_width",
                    f"<= lobby_width ({self.lobby_width} m)",
                    self.cabin_width,
                    "widen the lobby",
                )
            )
        for name in ("n_boarding", "n_exiting"):
            n = getattr(self, name)
            if not isinstance(n, int) or n < 0:
                raise ScenarioError(expect(f"ElevatorLayout.{name}", "an integer >= 0", n, "fix"))
        n_route = 2 + len(self.exit_waypoints or ())
        for name, n_max in (("exit_release_waypoint", n_route), ("boarder_release_waypoint", 2)):
            k = getattr(self, name)
            if k is not None and not (isinstance(k, int) and 1 <= k <= n_max):
                raise ScenarioError(
                    expect(
                        f"ElevatorLayout.{name}",
                        f"null or an integer in 1..{n_max} (waypoints of the route)",
                        k,
                        "fix it",
                    )
                )


def elevator_scenario(
    layout: ElevatorLayout | None = None, sim: SimConfig | None = None, name: str | None = None
) -> ScenarioConfig:
    """Build the elevator co-boarding scenario (HR-RL by default) from a layout.

    Placement (human side = right; "left" mirrors every x):
    - the robot starts in the lobby, between the boarders, facing the door; its goal is in the
      left cabin half;
    - boarding humans start in the lobby at alternating sides of the robot and walk through
      the door (waypoints in front of and behind the door centre) to stacked spots in the
      right cabin half, once the exiting passengers are out of the doorway;
    - exiting humans start in the cabin centre, leave through the door, turn aside through
      ``exit_waypoints`` and leave through the open far side of the lobby, where they are
      removed.
    """
    lay = layout or ElevatorLayout()
    sim = sim or SimConfig()
    r_h = lay.human_radius
    r_r = sim.robot.radius
    m = lay.margin
    hw_c = lay.cabin_width / 2
    hw_d = lay.door_width / 2
    hw_l = lay.lobby_width / 2
    depth = lay.cabin_depth
    ld = lay.lobby_depth
    if lay.door_width < 2 * r_r + 2 * m:
        raise ScenarioError(
            expect(
                "ElevatorLayout.door_width",
                f">= robot diameter + margins ({2 * r_r + 2 * m:.2f} m)",
                lay.door_width,
                "widen the door",
            )
        )
    walls: tuple[Segment, ...] = (
        (-hw_l, 0.0, -hw_d, 0.0),  # front wall, left of the door
        (hw_d, 0.0, hw_l, 0.0),  # front wall, right of the door
        (-hw_l, -ld, -hw_l, 0.0),  # lobby left wall
        (hw_l, -ld, hw_l, 0.0),  # lobby right wall
        (-hw_c, 0.0, -hw_c, depth),  # cabin left wall
        (hw_c, 0.0, hw_c, depth),  # cabin right wall
        (-hw_c, depth, hw_c, depth),  # cabin back wall
    )
    bounds = (-hw_l, hw_l, -ld, depth)
    front = (0.0, -(r_h + 0.1))  # waypoint in front of the door centre
    behind = (0.0, r_h + 0.1)  # waypoint just inside the cabin
    side = 1.0 if lay.human_side == "right" else -1.0
    sx = lay.robot_start_half_width
    # Compact rules: lobby start rows may reach a little beyond the open far side.
    lobby_y = lay.boarder_y or (-ld - 0.4, -(r_h + m + 0.45))
    humans: list[HumanSpec] = []
    # Boarders: alternating right/left of the robot; spots stacked front-to-back in one half.
    x_in, x_out = lay.boarder_x or (sx + r_r + r_h + 2 * m, hw_l - r_h - m)
    # Spots run from the deep outer corner (first boarder) to beside the door (last), so a
    # later boarder never has to pass an earlier one: with A = 2 m/s² at contact and a drive of
    # at most 1.4 m/s², two 0.6 m bodies cannot come closer than ≈ 1.4 m.
    deep = (hw_c - r_h - m - 0.15, hw_c - r_h - m, depth - r_h - m - 0.3, depth - r_h - m)
    near = (0.1, 0.35, r_h + 0.15, r_h + 0.35)
    n_b = lay.n_boarding
    exiting = tuple(range(n_b, n_b + lay.n_exiting))
    for k in range(n_b):
        lobby_side = (1.0 if k % 2 == 0 else -1.0) * (
            -side if lay.first_boarder_on_goal_side else 1
        )
        start = Region(
            x=(x_in, max(x_in, x_out)) if lobby_side > 0 else (-max(x_in, x_out), -x_in),
            y=lobby_y,
        )
        f = k / (n_b - 1) if n_b > 1 else 0.0
        box = [(1 - f) * d + f * e for d, e in zip(deep, near, strict=True)]
        spot = Region(x=(box[0], box[1]), y=(box[2], box[3]))
        wait = (*exiting, *((k - 1,) if k > 0 else ())) if lay.boarders_queue else ()
        spot_s = spot if side > 0 else spot.mirrored()
        humans.append(
            HumanSpec(
                role="boarding",
                start=start,
                goal=spot_s,
                waypoints=(front, behind),
                radius=r_h,
                v_pref_choices=lay.v_pref_choices,
                start_delay=lay.boarding_delay,
                wait_for=wait,
                release_waypoint=lay.boarder_release_waypoint,
                reacts_to_robot=lay.boarders_react_to_robot,
            )
        )
    aside = tuple((side * x, y) for x, y in lay.exit_waypoints or ())  # HR-RL coordinates
    exit_x = (aside[-1][0], aside[-1][0]) if aside else (-0.3, 0.3)
    exit_y = lay.exit_start_y or (r_h + 0.3, min(r_h + 0.9, depth - r_h - m))
    for _ in range(lay.n_exiting):
        humans.append(
            HumanSpec(
                role="exiting",
                start=Region(x=lay.exit_start_x, y=exit_y),
                goal=Region(x=exit_x, y=(-ld - 1.5, -ld - 1.5)),
                waypoints=(behind, front, *aside),
                radius=r_h,
                v_pref_choices=lay.v_pref_choices,
                release_waypoint=lay.exit_release_waypoint,
                reacts_to_robot=lay.exiting_react_to_robot,
            )
        )
    goal = Region(
        x=(-(hw_c - r_r - 0.15), -min(hw_c - r_r - 0.15, 0.45)), y=(1.0, depth - r_r - 0.2)
    )
    default_name = "hr-rl" if side > 0 else "hl-rr"
    robot_y = lay.robot_start_y or (-ld + 0.25, -(r_r + 0.35))
    return ScenarioConfig(
        name=name or default_name,
        walls=walls,
        bounds=bounds,
        robot_start=Region(x=(-sx, sx), y=robot_y),
        robot_goal=goal if side > 0 else goal.mirrored(),
        robot_heading=(math.pi / 2 - 0.15, math.pi / 2 + 0.15),
        humans=tuple(humans),
        min_start_gap=lay.min_start_gap,
        sim=sim,
    )


# --------------------------------------------------------------------------------------------
# Synthetic static study (paper Fig. 3)


@dataclasses.dataclass(frozen=True)
class StaticStudyLayout(Config):
    """A room with one static human in the middle and corridors to its left and right."""

    width: float = 4.0  # [m] room x ∈ [−width/2, width/2]
    length: float = 6.0  # [m] room y ∈ [−length/2, length/2]
    human_radius: float = 0.6  # [m]
    start_y: float = -2.4  # [m] robot start row (below the human)
    goal_y: float = 2.4  # [m] robot goal row (above the human)
    start_half_width: float = 0.3  # [m] start x ∈ ±this

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            if f.name not in ("start_y", "goal_y", "start_half_width"):
                check_positive("StaticStudyLayout", f.name, getattr(self, f.name))


def static_study_scenario(
    layout: StaticStudyLayout | None = None, sim: SimConfig | None = None
) -> ScenarioConfig:
    """The synthetic static study: start below the human, goal above, two corridors."""
    lay = layout or StaticStudyLayout()
    w, ln = lay.width / 2, lay.length / 2
    walls: tuple[Segment, ...] = (
        (-w, -ln, w, -ln),
        (w, -ln, w, ln),
        (w, ln, -w, ln),
        (-w, ln, -w, -ln),
    )
    human = HumanSpec(
        role="static",
        start=Region(x=(0.0, 0.0), y=(0.0, 0.0)),
        goal=Region(x=(0.0, 0.0), y=(0.0, 0.0)),
        radius=lay.human_radius,
        v_pref_choices=(0.0,),
        static=True,
    )
    return ScenarioConfig(
        name="static",
        walls=walls,
        bounds=(-w, w, -ln, ln),
        robot_start=Region(
            x=(-lay.start_half_width, lay.start_half_width), y=(lay.start_y, lay.start_y)
        ),
        robot_goal=Region(x=(0.0, 0.0), y=(lay.goal_y, lay.goal_y)),
        robot_heading=(math.pi / 2, math.pi / 2),
        humans=(human,),
        sim=sim or SimConfig(),
    )


# --------------------------------------------------------------------------------------------
# Registry and sampling


def _compact(side: str, name: str) -> ScenarioConfig:
    """The earlier default world (reproducible: the same states, bit for bit)."""
    sim = SimConfig(social_force=SocialForceConfig.preset("compact"))
    return elevator_scenario(ElevatorLayout.compact(side), sim=sim, name=name)


_REGISTRY: dict[str, Callable[[], ScenarioConfig]] = {
    "hr-rl": lambda: elevator_scenario(ElevatorLayout(human_side="right")),
    "hl-rr": lambda: elevator_scenario(ElevatorLayout(human_side="left")),
    "hr-rl-r03": lambda: elevator_scenario(
        ElevatorLayout(human_side="right", human_radius=0.3), name="hr-rl-r03"
    ),
    "hl-rr-r03": lambda: elevator_scenario(
        ElevatorLayout(human_side="left", human_radius=0.3), name="hl-rr-r03"
    ),
    "hr-rl-compact": lambda: _compact("right", "hr-rl-compact"),
    "hl-rr-compact": lambda: _compact("left", "hl-rr-compact"),
    "static": static_study_scenario,
}
_BUILTIN = frozenset(_REGISTRY)
_BASES: dict[str, str] = {}  # variant → built-in scenario whose learned parts it uses


def _key(name: str) -> str:
    """Registry key of a scenario name (case and surrounding blanks do not matter)."""
    return name.strip().lower()


def scenario_names() -> list[str]:
    """Names accepted by :func:`get_scenario`."""
    load_env_scenarios()
    return sorted(_REGISTRY)


def _check_new_name(where: str, name: str) -> None:
    if not _key(name) or _key(name) in _BUILTIN:
        raise ScenarioError(
            expect(where, f"a new non-empty name (not {sorted(_BUILTIN)})", name, "rename it")
        )


def _check_base(where: str, base: object) -> None:
    if base is not None and (not isinstance(base, str) or _key(base) not in _BUILTIN):
        raise ScenarioError(
            expect(f"{where}: base", f"one of {sorted(_BUILTIN)}", base, "fix the name")
        )


def register_scenario(
    name: str, factory: Callable[[], ScenarioConfig], base: str | None = None
) -> None:
    """Make a scenario variant available by ``name`` to :func:`get_scenario`, the Gymnasium
    env, the evaluation harness and DAgger (in-process; register it at import time of the
    script's top level, so spawned workers register it too).

    ``factory`` builds the config, e.g. ``lambda: elevator_scenario(ElevatorLayout(
    lobby_depth=2.8), name="hr-rl-deep")``; it is called once here to check it, and its start
    states for seeds 0–49 are drawn (a layout too tight to place every body is refused here,
    not halfway through an evaluation). Built-in names
    cannot be replaced. Learned parts keyed by scenario (the teacher's default reward, shipped
    students) exist only for the built-in ones: pass a reward file for a new name, or name a
    built-in ``base`` whose shipped demos and students the variant uses.
    """
    _check_new_name("scenario name", name)
    _check_base(f"scenario {name!r}", base)
    cfg = factory()
    if not isinstance(cfg, ScenarioConfig):
        raise ScenarioError(
            expect(
                f"scenario {name!r} factory", "a ScenarioConfig", type(cfg).__name__, "return one"
            )
        )
    _check_placement(f"scenario {name!r}", cfg)
    _register(name, factory, base)


def _check_placement(where: str, cfg: ScenarioConfig) -> None:
    """Draw the start states of seeds 0–49: a layout too tight for some of them would stop an
    evaluation in the middle (≈ 1 ms per seed when it fits)."""
    for seed in range(PLACEMENT_CHECK_SEEDS):
        try:
            sample_state(cfg, np.random.default_rng(seed))
        except ScenarioError as exc:
            raise ScenarioError(
                f"{where}: start state for seed {seed} (of {PLACEMENT_CHECK_SEEDS} checked): {exc}"
            ) from exc


def _register(name: str, factory: Callable[[], ScenarioConfig], base: str | None) -> None:
    key = _key(name)
    _REGISTRY[key] = factory
    if base is None:
        _BASES.pop(key, None)
    else:
        _BASES[key] = _key(base)


def scenario_base(name: str) -> str:
    """The built-in scenario whose learned parts (shipped demos → teacher reward, shipped
    students) serve ``name``: the ``base`` it was registered with, else ``name`` itself."""
    key = _key(name)
    if key not in _REGISTRY:
        load_env_scenarios()
    return _BASES.get(key, name)


SCENARIO_FILE_FORMAT = "pioneer.scenarios/1"
SCENARIOS_ENV = "PIONEER_SCENARIOS"  # scenario files (os.pathsep-separated) loaded on demand
_KINDS: dict[str, tuple[type[Config], Callable[..., ScenarioConfig]]] = {
    "elevator": (ElevatorLayout, elevator_scenario),
    "static": (StaticStudyLayout, static_study_scenario),
}
_ENV_LOADED: str | None = None  # the value of SCENARIOS_ENV whose files are registered
PLACEMENT_CHECK_SEEDS = 50  # start states drawn per variant when a scenario file is loaded


def _scenario_factory(
    name: str, kind: str, layout: dict[str, Any], sim: dict[str, Any] | None
) -> Callable[[], ScenarioConfig]:
    layout_cls, build = _KINDS[kind]
    lay = layout_cls.from_dict(layout)
    sim_cfg = SimConfig.from_dict(sim) if sim is not None else None

    def factory() -> ScenarioConfig:
        return build(lay, sim=sim_cfg).replace(name=name)

    return factory


def load_scenario_file(path: str | Path) -> list[str]:
    """Register the scenario variants of a JSON file; returns their names.

    The file (``format`` ``pioneer.scenarios/1``) maps names to a layout of a built-in family
    and, optionally, simulator settings::

        {"format": "pioneer.scenarios/1",
         "scenarios": {
           "hr-rl-deep": {"elevator": {"lobby_depth": 2.8}, "base": "hr-rl"},
           "static-wide": {"static": {"width": 5.0}, "sim": {"time_limit": 40.0}}}}

    ``elevator`` takes :class:`ElevatorLayout` fields, ``static`` :class:`StaticStudyLayout`
    fields, ``sim`` :class:`~pioneer.sim.world.SimConfig` fields; omitted fields keep their
    defaults. An optional ``"base": "hr-rl"`` lets the variant use that built-in scenario's
    shipped demos (the teacher's default reward) and shipped students. Episode seeds derive
    from the scenario *name*, so a variant evaluated twice under one name gets the same
    episodes. Each variant must place its bodies for the start-state seeds 0–49 (a layout
    that is too tight for some draws is refused here rather than halfway through a run).
    Put the file's path in the ``PIONEER_SCENARIOS`` environment variable (or pass
    ``pioneer --scenarios FILE``) so that worker processes register the variants too.
    """
    p = Path(path)
    fix = f"write a JSON object with 'format': {SCENARIO_FILE_FORMAT!r} and 'scenarios'"
    try:
        data = json.loads(p.read_text())
    except OSError as exc:
        raise ScenarioError(
            expect("scenario file", "a readable file", str(p), "check the path")
        ) from exc
    except json.JSONDecodeError as exc:
        raise ScenarioError(
            expect(f"scenario file {p}", "valid JSON", f"{exc.msg} at line {exc.lineno}", fix)
        ) from exc
    if not isinstance(data, dict) or data.get("format") != SCENARIO_FILE_FORMAT:
        got = data.get("format") if isinstance(data, dict) else type(data).__name__
        raise ScenarioError(expect(f"scenario file {p}: format", SCENARIO_FILE_FORMAT, got, fix))
    entries = data.get("scenarios")
    if not isinstance(entries, dict) or not entries:
        raise ScenarioError(
            expect(f"scenario file {p}: scenarios", "a non-empty object", entries, fix)
        )
    factories: dict[str, Callable[[], ScenarioConfig]] = {}
    bases: dict[str, str | None] = {}
    for name, entry in entries.items():
        where = f"scenario file {p}: {name!r}"
        _check_new_name(where, name)
        kinds = sorted(set(entry) & set(_KINDS)) if isinstance(entry, dict) else []
        extra = (
            sorted(set(entry) - set(_KINDS) - {"sim", "base"}) if isinstance(entry, dict) else []
        )
        if len(kinds) != 1 or extra:
            raise ScenarioError(
                expect(
                    where,
                    f"exactly one of {sorted(_KINDS)} (plus optional 'sim' and 'base')",
                    sorted(entry) if isinstance(entry, dict) else entry,
                    'e.g. {"elevator": {"lobby_depth": 2.8}}',
                )
            )
        try:
            factories[name] = _scenario_factory(name, kinds[0], entry[kinds[0]], entry.get("sim"))
            cfg = factories[name]()  # build it once: placement errors name the file and variant
        except PioneerError as exc:
            raise ScenarioError(f"{where}: {exc}") from exc
        _check_placement(where, cfg)
        _check_base(where, entry.get("base"))
        bases[name] = entry.get("base")
    for name, factory in factories.items():  # all or nothing: register only a valid file
        _register(name, factory, bases[name])
    return list(factories)


def load_env_scenarios() -> None:
    """Register the files named in ``PIONEER_SCENARIOS`` (once per value of the variable)."""
    global _ENV_LOADED
    value = os.environ.get(SCENARIOS_ENV, "")
    if value == _ENV_LOADED:
        return
    for item in value.split(os.pathsep):
        if item.strip():
            load_scenario_file(item.strip())
    _ENV_LOADED = value


def pin_scenario(name: str, recorded: dict[str, Any] | None, where: str) -> dict[str, Any]:
    """The full definition of ``name`` as plain JSON data; if ``recorded`` (the definition an
    output folder was made with) differs, raise :class:`ConfigError` naming the changed fields
    — a variant from a scenario file can change under an unchanged name."""
    mine: dict[str, Any] = json.loads(json.dumps(get_scenario(name).to_dict()))
    if recorded is not None and recorded != mine:
        diff = sorted(k for k in {*recorded, *mine} if recorded.get(k) != mine.get(k))
        raise ConfigError(
            expect(
                f"{where}: scenario {name!r}",
                f"the definition recorded there ({diff} differ)",
                "a changed definition",
                "restore the scenario file, or use a new --out directory",
            )
        )
    return mine


def get_scenario(name: str) -> ScenarioConfig:
    """A registered scenario by name (``hr-rl``, ``hl-rr``, ``static``, …, and the variants of
    the files in ``PIONEER_SCENARIOS``)."""
    key = _key(name)
    if key not in _REGISTRY:
        load_env_scenarios()
    if key not in _REGISTRY:
        raise ScenarioError(
            expect("scenario", f"one of {scenario_names()}", name, "pick a listed scenario name")
        )
    return _REGISTRY[key]()


def sample_state(cfg: ScenarioConfig, rng: np.random.Generator) -> State:
    """Draw an initial state (B = 1) from ``rng``, rejecting bodies that overlap at t = 0.

    Every draw comes from ``rng`` in a fixed order, so the same seed gives the same state.
    """
    walls = np.asarray(cfg.walls, dtype=np.float64).reshape(-1, 4)
    r_r = cfg.sim.robot.radius
    gap = cfg.min_start_gap
    n = len(cfg.humans)
    n_wp = [len(h.waypoints) + 1 for h in cfg.humans]
    w_max = max(n_wp, default=1)
    for _ in range(MAX_TRIES):
        p_r = cfg.robot_start.sample(rng)
        heading = rng.uniform(*cfg.robot_heading)
        goal = cfg.robot_goal.sample(rng)
        pos = np.zeros((n, 2))
        wps = np.zeros((n, w_max, 2))
        vpref = np.zeros(n)
        delay = np.zeros(n)
        for i, h in enumerate(cfg.humans):
            pos[i] = h.start.sample(rng)
            g = h.goal.sample(rng)
            pts = [*h.waypoints, tuple(g)]
            wps[i, : len(pts)] = pts
            wps[i, len(pts) :] = g
            vpref[i] = h.v_pref_choices[int(rng.integers(len(h.v_pref_choices)))]
            delay[i] = rng.uniform(*h.start_delay)
        if _initial_state_ok(cfg, walls, p_r, pos, gap, r_r):
            break
    else:
        raise ScenarioError(
            expect(
                f"{cfg.name}: initial state",
                f"a collision-free placement within {MAX_TRIES} draws",
                "every draw overlapped",
                "widen the start regions or reduce radii / min_start_gap",
            )
        )
    status = np.array([ARRIVED if h.static else WALKING for h in cfg.humans], dtype=np.int8)
    return State(
        robot=np.array([[p_r[0], p_r[1], heading]]),
        command=np.zeros((1, 2)),
        goal=goal.reshape(1, 2),
        start=p_r.reshape(1, 2).copy(),
        t=np.zeros(1),
        path_length=np.zeros(1),
        collided=np.zeros(1, dtype=np.bool_),
        reached=np.zeros(1, dtype=np.bool_),
        clearance=np.array([_min_clearance(p_r, pos, cfg, r_r)]),
        wall_clearance=np.array([_wall_distance(p_r, walls) - r_r]),
        h_pos=pos.reshape(1, n, 2),
        h_vel=np.zeros((1, n, 2)),
        h_radius=np.array([[h.radius for h in cfg.humans]]).reshape(1, n),
        h_vpref=vpref.reshape(1, n),
        h_waypoints=wps.reshape(1, n, w_max, 2),
        h_n_waypoints=np.array([n_wp], dtype=np.int64).reshape(1, n),
        h_wp_index=np.zeros((1, n), dtype=np.int64),
        h_status=status.reshape(1, n),
        h_delay=delay.reshape(1, n),
        h_home=pos.reshape(1, n, 2).copy(),
        h_wait_for=np.array(
            [[int(j in h.wait_for) for j in range(n)] for h in cfg.humans],
            dtype=np.int64,
        ).reshape(1, n, n),
        h_release=np.array(
            [
                k if (k := h.release_waypoint) is not None else n_wp[i]
                for i, h in enumerate(cfg.humans)
            ],
            dtype=np.int64,
        ).reshape(1, n),
        h_reacts=np.array([h.reacts_to_robot for h in cfg.humans], dtype=np.bool_).reshape(1, n),
    )


def _min_clearance(p_r: np.ndarray, pos: np.ndarray, cfg: ScenarioConfig, r_r: float) -> float:
    if len(cfg.humans) == 0:
        return math.inf
    radii = np.array([h.radius for h in cfg.humans])
    return float(np.min(np.linalg.norm(pos - p_r, axis=1) - radii - r_r))


def _initial_state_ok(
    cfg: ScenarioConfig, walls: np.ndarray, p_r: np.ndarray, pos: np.ndarray, gap: float, r_r: float
) -> bool:
    if _wall_distance(p_r, walls) < r_r + gap:
        return False
    for i, h in enumerate(cfg.humans):
        if _wall_distance(pos[i], walls) < h.radius + gap:
            return False
        if np.linalg.norm(pos[i] - p_r) < h.radius + r_r + gap:
            return False
        for j in range(i):
            if np.linalg.norm(pos[i] - pos[j]) < h.radius + cfg.humans[j].radius + gap:
                return False
    return True
