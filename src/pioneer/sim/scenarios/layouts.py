"""The scenario families: elevator co-boarding (HR-RL, HL-RR; paper world and the compact
world) and the static study, each built from a typed layout (docs/simulator.md)."""

from __future__ import annotations

import dataclasses
import math
from typing import Annotated, Literal

from annotated_types import Interval

from pioneer.bounds import Count, NonNegative, NonNegativeInt, Positive, Span
from pioneer.config import Config
from pioneer.errors import ConfigError, ScenarioError, expect
from pioneer.sim.scenarios.spec import HumanSpec, Point, Region, ScenarioConfig, Segment
from pioneer.sim.world import SimConfig

# --------------------------------------------------------------------------------------------
# Elevator co-boarding

HumanSide = Literal["right", "left"]  # the humans' side: "right" → HR-RL, "left" → HL-RR


@dataclasses.dataclass(frozen=True)
class ElevatorLayout(Config):
    """Geometry and population of the elevator co-boarding scenario (paper §V-B;
    docs/calibration.md).

    The defaults are the paper world: a 4 × 4 m lobby in front of the attached 2.5 × 2.7 m
    cabin. Positions are in HR-RL coordinates (humans board to the right half); ``human_side =
    "left"`` mirrors every x. A start-region field set to ``None`` is derived from the geometry
    by the rules of the earlier compact world (:meth:`compact`), which stays reproducible.
    The values of the free fields were chosen by world statistics (docs/calibration.md).
    """

    error_type = ScenarioError

    human_side: HumanSide = "right"  # "right" → HR-RL (robot goal left); "left" → HL-RR
    cabin_width: Positive = 2.5  # [m] Schindler 6000
    cabin_depth: Positive = 2.7  # [m]
    door_width: Positive = 1.8  # [m]
    lobby_width: Positive = 4.0  # [m] walled on its left and right
    lobby_depth: Positive = 4.0  # [m] the far side (y = −lobby_depth) is open
    n_boarding: NonNegativeInt = 2  # humans boarding from the lobby, on alternating sides
    n_exiting: NonNegativeInt = 1  # humans leaving the cabin through the door
    human_radius: Positive = 0.6  # [m] the paper's value
    v_pref_choices: tuple[float, ...] = (0.5, 0.6, 0.7)  # [m/s]
    robot_start_half_width: NonNegative = 0.25  # [m] robot start x ∈ ±this
    robot_start_y: Span | None = (-2.4, -2.0)  # [m] None: compact rule
    boarder_x: Span | None = (1.2, 1.3)  # [m] |x| of a boarder's start
    boarder_y: Span | None = (-3.8, -3.3)  # [m] beside, behind the robot
    boarding_delay: Span = (0.5, 1.5)  # [s] boarders' reaction time
    # The first boarder starts on the robot's goal side, the next on the humans' side, … (so
    # HL-RR is the mirror image of HR-RL); False: the first on the right in both (compact).
    first_boarder_on_goal_side: bool = True
    boarders_queue: bool = True  # let the exiting passengers out first, then board one by one
    # |x| of the last boarder's spot, beside the door's centre line on the humans' side (the
    # earlier boarders' spots lie between it and the cabin's deep outer corner).
    last_boarder_x: Span = (0.1, 0.35)  # [m]
    exit_start_x: Span = (-0.5, 0.5)  # [m] exiting passengers start in the cabin
    exit_start_y: Span | None = None  # [m] None: r_h + 0.3 … r_h + 0.9 (≤ depth)
    # After the door, the exiting passenger turns aside through these points (HR-RL: to the
    # humans' side, ahead of the robot), then leaves through the open far side below the last
    # one. None: straight out (compact rule).
    exit_waypoints: tuple[Point, ...] | None = ((1.2, -1.6),)  # [m]
    # Boarders go once the exiting passenger heads for this waypoint index (1 = the one in
    # front of the door, 2 = the first after it, …); None: once it has left the map.
    exit_release_waypoint: Count | None = 2
    # A later boarder goes once the one before it heads for this waypoint index (1 = in front
    # of the door, 2 = just inside the cabin, 3 = its spot); None: once it has arrived.
    boarder_release_waypoint: Annotated[int, Interval(ge=1, le=2)] | None = 1
    boarders_react_to_robot: bool = True  # False: the robot is invisible to the boarders
    exiting_react_to_robot: bool = True  # False: … to the exiting passengers
    margin: NonNegative = 0.05  # [m] extra clearance from walls for sampled positions
    min_start_gap: NonNegative = 0.1  # [m] clearance between all bodies and walls at t = 0

    @classmethod
    def compact(cls, human_side: HumanSide = "right") -> ElevatorLayout:
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
        n_route = 2 + len(self.exit_waypoints or ())  # the two at the door, then the exit
        k = self.exit_release_waypoint
        if k is not None and k > n_route:
            raise ScenarioError(
                expect(
                    "ElevatorLayout.exit_release_waypoint",
                    f"null or an integer in 1..{n_route} (waypoints of the route)",
                    k,
                    "fix it",
                )
            )


def _elevator_walls(lay: ElevatorLayout) -> tuple[Segment, ...]:
    """Front wall with the door, the lobby's side walls and the cabin (door centre at origin,
    cabin at y > 0, lobby at y < 0, the lobby's far side open)."""
    hw_c, hw_d, hw_l = lay.cabin_width / 2, lay.door_width / 2, lay.lobby_width / 2
    depth, ld = lay.cabin_depth, lay.lobby_depth
    return (
        (-hw_l, 0.0, -hw_d, 0.0),  # front wall, left of the door
        (hw_d, 0.0, hw_l, 0.0),  # front wall, right of the door
        (-hw_l, -ld, -hw_l, 0.0),  # lobby left wall
        (hw_l, -ld, hw_l, 0.0),  # lobby right wall
        (-hw_c, 0.0, -hw_c, depth),  # cabin left wall
        (hw_c, 0.0, hw_c, depth),  # cabin right wall
        (-hw_c, depth, hw_c, depth),  # cabin back wall
    )


def _door_waypoints(lay: ElevatorLayout) -> tuple[Point, Point]:
    # In front of the door centre, and just inside the cabin.
    return (0.0, -(lay.human_radius + 0.1)), (0.0, lay.human_radius + 0.1)


def _boarders(lay: ElevatorLayout, r_r: float, side: float) -> list[HumanSpec]:
    """Boarders: alternating right/left of the robot; spots stacked front-to-back in the
    cabin half of the humans' side."""
    r_h, m = lay.human_radius, lay.margin
    hw_c, hw_l = lay.cabin_width / 2, lay.lobby_width / 2
    depth, ld = lay.cabin_depth, lay.lobby_depth
    sx = lay.robot_start_half_width
    # Compact rules: lobby start rows may reach a little beyond the open far side.
    lobby_y = lay.boarder_y or (-ld - 0.4, -(r_h + m + 0.45))
    x_in, x_out = lay.boarder_x or (sx + r_r + r_h + 2 * m, hw_l - r_h - m)
    # Spots run from the deep outer corner (first boarder) to beside the door (last), so a
    # later boarder never has to pass an earlier one: with A = 2 m/s² at contact and a drive of
    # at most 1.4 m/s², two 0.6 m bodies cannot come closer than ≈ 1.4 m.
    deep = (hw_c - r_h - m - 0.15, hw_c - r_h - m, depth - r_h - m - 0.3, depth - r_h - m)
    near = (*lay.last_boarder_x, r_h + 0.15, r_h + 0.35)
    n_b = lay.n_boarding
    exiting = tuple(range(n_b, n_b + lay.n_exiting))
    humans: list[HumanSpec] = []
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
        humans.append(
            HumanSpec(
                role="boarding",
                start=start,
                goal=spot if side > 0 else spot.mirrored(),
                waypoints=_door_waypoints(lay),
                radius=r_h,
                v_pref_choices=lay.v_pref_choices,
                start_delay=lay.boarding_delay,
                wait_for=wait,
                release_waypoint=lay.boarder_release_waypoint,
                reacts_to_robot=lay.boarders_react_to_robot,
            )
        )
    return humans


def _exiting(lay: ElevatorLayout, side: float) -> list[HumanSpec]:
    """Exiting passengers: from the cabin centre through the door, aside through
    ``exit_waypoints`` and out through the lobby's open far side."""
    r_h, m = lay.human_radius, lay.margin
    depth, ld = lay.cabin_depth, lay.lobby_depth
    front, behind = _door_waypoints(lay)
    aside = tuple((side * x, y) for x, y in lay.exit_waypoints or ())  # HR-RL coordinates
    exit_x = (aside[-1][0], aside[-1][0]) if aside else (-0.3, 0.3)
    exit_y = lay.exit_start_y or (r_h + 0.3, min(r_h + 0.9, depth - r_h - m))
    return [
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
        for _ in range(lay.n_exiting)
    ]


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
    r_r = sim.robot.radius
    m = lay.margin
    hw_c, hw_l = lay.cabin_width / 2, lay.lobby_width / 2
    depth, ld = lay.cabin_depth, lay.lobby_depth
    if lay.door_width < 2 * r_r + 2 * m:
        raise ScenarioError(
            expect(
                "ElevatorLayout.door_width",
                f">= robot diameter + margins ({2 * r_r + 2 * m:.2f} m)",
                lay.door_width,
                "widen the door",
            )
        )
    side = 1.0 if lay.human_side == "right" else -1.0
    sx = lay.robot_start_half_width
    goal = Region(
        x=(-(hw_c - r_r - 0.15), -min(hw_c - r_r - 0.15, 0.45)), y=(1.0, depth - r_r - 0.2)
    )
    robot_y = lay.robot_start_y or (-ld + 0.25, -(r_r + 0.35))
    try:  # the humans' regions derive from their size: name it, not a derived region
        humans = (*_boarders(lay, r_r, side), *_exiting(lay, side))
    except ConfigError as exc:
        raise ScenarioError(
            expect(
                "ElevatorLayout.human_radius",
                f"people who fit the cabin ({lay.cabin_width:g} × {depth:g} m) and the lobby "
                f"({lay.lobby_width:g} × {ld:g} m) with margin {m:g} m (their start and goal "
                "regions come out empty)",
                lay.human_radius,
                "shrink human_radius or margin, or enlarge the cabin or the lobby",
            )
        ) from exc
    return ScenarioConfig(
        name=name or ("hr-rl" if side > 0 else "hl-rr"),
        walls=_elevator_walls(lay),
        bounds=(-hw_l, hw_l, -ld, depth),
        robot_start=Region(x=(-sx, sx), y=robot_y),
        robot_goal=goal if side > 0 else goal.mirrored(),
        robot_heading=(math.pi / 2 - 0.15, math.pi / 2 + 0.15),
        humans=humans,
        min_start_gap=lay.min_start_gap,
        sim=sim,
    )


# --------------------------------------------------------------------------------------------
# Synthetic static study (paper Fig. 3)


@dataclasses.dataclass(frozen=True)
class StaticStudyLayout(Config):
    """A room with one static human in the middle and corridors to its left and right."""

    error_type = ScenarioError

    width: Positive = 4.0  # [m] room x ∈ [−width/2, width/2]
    length: Positive = 6.0  # [m] room y ∈ [−length/2, length/2]
    human_radius: Positive = 0.6  # [m]
    start_y: float = -2.4  # [m] robot start row (below the human)
    goal_y: float = 2.4  # [m] robot goal row (above the human)
    start_half_width: float = 0.3  # [m] start x ∈ ±this
    human_x: float = 0.0  # [m] the static human's position
    human_y: float = 0.0  # [m]


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
        start=Region(x=(lay.human_x, lay.human_x), y=(lay.human_y, lay.human_y)),
        goal=Region(x=(lay.human_x, lay.human_x), y=(lay.human_y, lay.human_y)),
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
