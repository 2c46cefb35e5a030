"""Social-navigation measures of one episode, beside the paper's success, time and path length.

Pure functions on arrays (each with its formula and public source; docs/metrics.md defines
every measure with its units) and :func:`measure_episode`, which computes all of them once an
episode has ended from the states it went through — the episode runner only keeps a reference
to every state, so the accumulation costs nothing per step.

Conventions: an episode of T steps of Δt has T + 1 states (after the reset, then after every
step); step k's command is held over [kΔt, (k+1)Δt); the robot stood still before t = 0
(speed and acceleration 0). Distances to people are those of the records: the **gap** is
surface to surface, the **clearance** from the robot's centre to the person's surface
(gap + r_r; docs/simulator.md, "Collisions"), both the least over each step (swept).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.eval.blocked import way_open
from pioneer.eval.freepath import FreePath, free_space, shortest_free_path
from pioneer.sim.humans import GONE
from pioneer.sim.scenarios import ScenarioConfig
from pioneer.sim.world import State

__all__ = [
    "HALL_ZONES",
    "PERSON_HITS",
    "SPACE_GAP_M",
    "STALL_PROGRESS_M",
    "STALL_WINDOW_S",
    "STILL_SPEED",
    "EpisodeMeasures",
    "accelerations",
    "closest_approach",
    "heading_change",
    "measure_episode",
    "measures_of",
    "path_irregularity",
    "person_hit_kind",
    "series_of",
    "spl",
    "stall_count",
    "time_shares",
    "time_still",
    "time_to_collision",
]

F64 = NDArray[np.float64]

STILL_SPEED = 0.05  # [m/s] below this linear speed the robot is standing
STALL_WINDOW_S = 5.0  # [s] no progress toward the goal for this long: a failure to progress
STALL_PROGRESS_M = 0.1  # [m] progress: the goal distance drops this far below its last mark
# Hall's proxemic zones [m] (Hall 1966, "The Hidden Dimension"), on the clearance.
HALL_ZONES: tuple[tuple[str, float, float], ...] = (
    ("intimate", 0.0, 0.45),
    ("personal", 0.45, 1.2),
    ("social", 1.2, 3.6),
)
SPACE_GAP_M = 0.5  # [m] space compliance: the share of time with the nearest gap >= this
PERSON_HITS = ("robot-into-person", "person-into-robot")


# ------------------------------------------------------------------------------ pure functions
def accelerations(speed: F64, dt: float, initial: float = 0.0) -> F64:
    """Linear accelerations [m/s²] of piecewise-constant speeds ``speed (T,)`` [m/s] held for
    ``dt`` each: a_k = (v_k − v_{k−1}) / Δt with v_{−1} = ``initial`` (backward differences,
    as smoothness is measured from commanded velocities in SocNavBench, Biswas et al. 2022,
    and robot_sf's jerk metric)."""
    v = np.asarray(speed, dtype=np.float64)
    return np.diff(v, prepend=initial) / dt


def heading_change(theta: F64) -> float:
    """Cumulative heading change [rad] of headings ``theta (T+1,)`` [rad]:
    Σ |wrap(θ_k − θ_{k−1})| with wrap into (−π, π] (navmet's cumulative heading changes, Okal
    & Arras)."""
    th = np.asarray(theta, dtype=np.float64)
    if th.size < 2:
        return 0.0
    return float(np.abs(np.angle(np.exp(1j * np.diff(th)))).sum())


def path_irregularity(turned: float, needed: float, path_length: float) -> float:
    """Unnecessary turning per metre [rad/m] (Guzzi et al. 2013, "Human-friendly robot
    navigation in dynamic environments", ICRA; SocNavBench's definition): (total rotation −
    the least rotation that reaches the goal along the shortest free path) / path length,
    the excess floored at 0; NaN for a robot that did not move."""
    if not path_length > 0.0:
        return math.nan
    return max(turned - needed, 0.0) / path_length


def time_still(speed: F64, dt: float, threshold: float = STILL_SPEED) -> float:
    """Time not moving [s]: Δt · #{k : |v_k| < threshold} (SEAN 2.0's "time not moving")."""
    return float(dt * np.count_nonzero(np.abs(np.asarray(speed)) < threshold))


def stall_count(
    distance: F64,
    dt: float,
    window_s: float = STALL_WINDOW_S,
    progress_m: float = STALL_PROGRESS_M,
) -> int:
    """Failures to progress in goal distances ``distance (T+1,)`` [m] sampled every ``dt``:
    the distance makes *progress* when it drops ``progress_m`` below its mark (the distance at
    t = 0, then at the last progress); every stretch of ``window_s`` without progress counts
    once, however long it lasts (Francis et al. 2023, "Principles and Guidelines for
    Evaluating Social Robot Navigation Algorithms", THRI: failure to progress)."""
    d = np.asarray(distance, dtype=np.float64)
    if d.size == 0:
        return 0
    mark, waited, count, counted = float(d[0]), 0.0, 0, False
    limit = window_s - 1e-9 * max(window_s, 1.0)
    for x in d[1:]:
        if x <= mark - progress_m + 1e-9:  # (a rounding error is no lack of progress)
            mark, waited, counted = float(x), 0.0, False
            continue
        waited += dt
        if waited >= limit and not counted:
            count, counted = count + 1, True
    return count


def time_shares(distance: F64, bands: Sequence[tuple[float, float]]) -> list[float]:
    """The share of steps (each lasting Δt: the share of time) whose ``distance`` lies in each
    half-open band ``[lo, hi)``; an empty episode gives NaN."""
    d = np.asarray(distance, dtype=np.float64)
    if d.size == 0:
        return [math.nan] * len(bands)
    return [float(np.count_nonzero((d >= lo) & (d < hi)) / d.size) for lo, hi in bands]


def time_to_collision(position: F64, velocity: F64, radius: F64 | float) -> F64:
    """Time [s] until two discs touch if both keep their velocities: the least t ≥ 0 with
    ‖p + u t‖ = R, for the relative position ``position (…, 2)`` [m] and velocity
    ``velocity (…, 2)`` [m/s] of the other disc and the sum of radii ``radius`` [m]:

        t = (−p·u − √((p·u)² − ‖u‖² (‖p‖² − R²))) / ‖u‖²

    when the discs approach (p·u < 0) on a course that meets (discriminant ≥ 0); 0 when they
    already overlap; ``inf`` otherwise (van den Berg et al. 2011, "Reciprocal n-body collision
    avoidance", the time to collision of two discs)."""
    p = np.asarray(position, dtype=np.float64)
    u = np.asarray(velocity, dtype=np.float64)
    r = np.asarray(radius, dtype=np.float64)
    c = np.einsum("...i,...i->...", p, p) - r * r
    b = np.einsum("...i,...i->...", p, u)
    a = np.einsum("...i,...i->...", u, u)
    disc = b * b - a * c
    meets = (b < 0.0) & (disc >= 0.0) & (a > 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (-b - np.sqrt(np.where(meets, disc, 0.0))) / np.where(meets, a, 1.0)
    return np.where(c < 0.0, 0.0, np.where(meets, np.maximum(t, 0.0), np.inf))


def closest_approach(rel0: F64, rel1: F64) -> F64:
    """Least distance [m] over a step of a relative position moving linearly from ``rel0`` to
    ``rel1`` (each ``(…, 2)``): min over τ ∈ [0, 1] of ‖rel0 + τ (rel1 − rel0)‖."""
    a = np.asarray(rel0, dtype=np.float64)
    e = np.asarray(rel1, dtype=np.float64) - a
    ee = np.einsum("...i,...i->...", e, e)
    tau = np.clip(-np.einsum("...i,...i->...", a, e) / np.where(ee > 0.0, ee, 1.0), 0.0, 1.0)
    q = a + tau[..., None] * e
    return np.sqrt(np.einsum("...i,...i->...", q, q))


def person_hit_kind(speed: float, heading: float, to_person: F64) -> str:
    """Who ran into whom: ``"robot-into-person"`` when the robot moved (speed ≥
    :data:`STILL_SPEED`) toward the person (a positive component of its velocity along the
    direction ``to_person`` from its centre to the person's, at the step's start), else
    ``"person-into-robot"`` — the robot standing or moving away (the split of SEAN 2.0's
    robot-on-person and person-on-robot collisions)."""
    toward = math.cos(heading) * float(to_person[0]) + math.sin(heading) * float(to_person[1])
    return PERSON_HITS[0] if speed >= STILL_SPEED and toward > 0.0 else PERSON_HITS[1]


def spl(success: bool, shortest: float, path: float) -> float:
    """Success weighted by path length of one episode: S · ℓ / max(p, ℓ) (Anderson et al.
    2018, "On Evaluation of Embodied Navigation Agents"), ℓ the shortest free path and p the
    path driven [m]; NaN when ℓ is unknown (no free path)."""
    if not math.isfinite(shortest):
        return math.nan
    if not success:
        return 0.0
    return shortest / max(path, shortest) if max(path, shortest) > 0.0 else 1.0


# ------------------------------------------------------------------------------ one episode
@dataclasses.dataclass(frozen=True)
class EpisodeMeasures:
    """The social-navigation measures of one episode (docs/metrics.md); NaN: undefined."""

    # efficiency
    shortest_path_m: float  # [m] shortest free path start → goal region (a disc of radius r_r)
    spl: float  # [0, 1] success weighted by path length
    path_efficiency: float  # [0, 1] shortest / max(path driven, shortest); successes only
    time_still_s: float  # [s] time with linear speed < STILL_SPEED
    stalls: int  # failures to progress (STALL_WINDOW_S without STALL_PROGRESS_M of progress)
    # smoothness
    accel_mean_m_s2: float  # [m/s²] mean |linear acceleration| over the steps
    accel_max_m_s2: float  # [m/s²]
    jerk_mean_m_s3: float  # [m/s³] mean |linear jerk|
    jerk_max_m_s3: float  # [m/s³]
    heading_change_rad: float  # [rad] Σ |Δθ|
    path_irregularity_rad_m: float  # [rad/m] unnecessary turning per metre
    # social (NaN / inf: no person in the episode)
    min_clearance_m: float  # [m] least clearance (centre → nearest person's surface)
    intimate_share: float  # [0, 1] share of time with the clearance in [0, 0.45) m
    personal_share: float  # [0, 1] … in [0.45, 1.2) m
    social_share: float  # [0, 1] … in [1.2, 3.6) m
    space_compliance: float  # [0, 1] share of time with the nearest gap >= 0.5 m
    min_ttc_s: float  # [s] least time to collision with a person at constant velocities
    # collisions by kind (a collision may touch a wall and a person at once)
    wall_hit: bool = False
    person_hit: str | None = None  # "robot-into-person" or "person-into-robot"
    person_role: str | None = None  # the role of the person hit ("boarding", "exiting", …)
    person_index: int | None = None  # the person's slot in the scenario
    # a timeout: no way to the goal was left at its end, people standing where they were
    # (pioneer.eval.blocked); None: the episode did not time out
    blocked: bool | None = None

    def to_dict(self) -> dict[str, Any]:
        """Plain dict, floats to 6 significant digits, NaN and inf as ``None``."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            out[f.name] = _compact(v) if isinstance(v, float) else v
        return out


def _compact(x: float, digits: int = 6) -> float | None:
    return float(f"{x:.{digits}g}") if math.isfinite(x) else None


def series_of(states: Sequence[State], robot_radius: float) -> dict[str, list[float | None]]:
    """The compact per-step series a record keeps for the pictures: robot ``x``, ``y`` [m] of
    every state (T + 1, to the millimetre) and the nearest person's swept ``clearance`` [m] of
    every step (T, to the millimetre; ``None``: no person)."""
    pose = np.array([s.robot[0, :2] for s in states])
    clear = np.array([s.gap[0] for s in states[1:]]) + robot_radius
    return {
        "x": [round(float(v), 3) for v in pose[:, 0]],
        "y": [round(float(v), 3) for v in pose[:, 1]],
        "clearance": [round(float(c), 3) if math.isfinite(c) else None for c in clear],
    }


def _shortest(scenario: ScenarioConfig, start: F64, goal: F64) -> FreePath:
    space = free_space(scenario.walls, scenario.sim.robot.radius)
    return shortest_free_path(space, start, goal)


def _blocked(scenario: ScenarioConfig, last: State) -> bool:
    here = last.h_status[0] != GONE
    return not way_open(
        scenario.walls,
        scenario.sim.robot.radius,
        last.robot[0, :2],
        last.goal[0],
        scenario.sim.goal_tolerance,
        last.h_pos[0][here],
        last.h_radius[0][here],
    )


def measure_episode(
    scenario: ScenarioConfig,
    states: Sequence[State],
    event: str,
    collided_with: str | None = None,
) -> EpisodeMeasures:
    """Every measure of the episode whose states (after the reset, then after each step) are
    ``states`` and whose end is ``event`` (``collided_with``: ``"human"``, ``"wall"`` or
    ``"human and wall"`` for a collision)."""
    sim = scenario.sim
    dt, r_r = sim.dt, sim.robot.radius
    first, last = states[0], states[-1]
    pose = np.array([s.robot[0] for s in states])  # (T+1, 3)
    speed = np.array([s.command[0, 0] for s in states[1:]])  # (T,) applied v of each step
    gap = np.array([s.gap[0] for s in states[1:]])  # (T,) swept, surface to surface
    path = float(last.path_length[0])
    goal = first.goal[0]

    free = _shortest(scenario, first.start[0], goal)
    # to the success region (within the goal tolerance of the goal), not to the goal point
    shortest = max(free.length - sim.goal_tolerance, 0.0)
    efficiency = spl(True, shortest, path) if event == "success" else math.nan
    acc = accelerations(speed, dt, float(first.command[0, 0]))
    jerk = np.diff(acc, prepend=0.0) / dt
    turned = heading_change(pose[:, 2])
    needed = free.turning(float(pose[0, 2])) if math.isfinite(free.length) else math.nan

    clear = gap + r_r
    shares = time_shares(clear, [(lo, hi) for _, lo, hi in HALL_ZONES])
    (compliant,) = time_shares(gap, [(SPACE_GAP_M, math.inf)])
    if not np.isfinite(gap).any():  # nobody in the episode: no social measure
        shares, compliant = [math.nan] * len(HALL_ZONES), math.nan

    hit: dict[str, Any] = {}
    if event == "collision" and collided_with is not None:
        hit["wall_hit"] = "wall" in collided_with
        if "human" in collided_with and len(states) >= 2:
            hit.update(_person_hit(scenario, states[-2], last, r_r))
    if event == "timeout":
        hit["blocked"] = _blocked(scenario, last)
    return EpisodeMeasures(
        shortest_path_m=shortest,
        spl=spl(event == "success", shortest, path),
        path_efficiency=efficiency,
        time_still_s=time_still(speed, dt),
        stalls=stall_count(np.hypot(*(pose[:, :2] - goal).T), dt),
        accel_mean_m_s2=_mean_abs(acc),
        accel_max_m_s2=_max_abs(acc),
        jerk_mean_m_s3=_mean_abs(jerk),
        jerk_max_m_s3=_max_abs(jerk),
        heading_change_rad=turned,
        path_irregularity_rad_m=path_irregularity(turned, needed, path),
        min_clearance_m=float(np.min(clear, initial=first.gap[0] + r_r)),
        intimate_share=shares[0],
        personal_share=shares[1],
        social_share=shares[2],
        space_compliance=compliant,
        min_ttc_s=_min_ttc(states[1:], r_r),
        **hit,
    )


def _mean_abs(x: F64) -> float:
    return float(np.abs(x).mean()) if x.size else math.nan


def _max_abs(x: F64) -> float:
    return float(np.abs(x).max()) if x.size else math.nan


def _min_ttc(states: Sequence[State], r_r: float) -> float:
    """The least time to collision [s] over the states after every step, between the robot
    (velocity v (cos θ, sin θ) of the step's command) and every person present."""
    if not states or states[0].n_humans == 0:
        return math.inf
    robot = np.array([s.robot[0] for s in states])  # (T, 3)
    v = np.array([s.command[0, 0] for s in states])
    h_pos = np.array([s.h_pos[0] for s in states])  # (T, N, 2)
    h_vel = np.array([s.h_vel[0] for s in states])
    present = np.array([s.h_status[0] != GONE for s in states])  # (T, N)
    r_sum = r_r + states[0].h_radius[0]  # (N,)
    vel = v[:, None] * np.stack([np.cos(robot[:, 2]), np.sin(robot[:, 2])], axis=-1)
    ttc = time_to_collision(h_pos - robot[:, None, :2], h_vel - vel[:, None, :], r_sum[None, :])
    ttc = np.where(present, ttc, np.inf)
    return float(ttc.min()) if ttc.size else math.inf


def _person_hit(
    scenario: ScenarioConfig, before: State, after: State, r_r: float
) -> dict[str, Any]:
    """Which person the collision step touched (the least closest approach over the step, both
    moving linearly) and who ran into whom (:func:`person_hit_kind`)."""
    present = before.h_status[0] != GONE
    if not present.any():
        return {}
    rel0 = before.h_pos[0] - before.robot[0, :2]
    rel1 = after.h_pos[0] - after.robot[0, :2]
    gap = closest_approach(rel0, rel1) - r_r - before.h_radius[0]
    i = int(np.argmin(np.where(present, gap, np.inf)))
    role = scenario.humans[i].role if i < len(scenario.humans) else None
    kind = person_hit_kind(float(after.command[0, 0]), float(before.robot[0, 2]), rel0[i])
    return {"person_hit": kind, "person_role": role, "person_index": i}


def measures_of(record: Mapping[str, Any]) -> Mapping[str, Any] | None:
    """The ``measures`` of a record (``None`` for a record written before them)."""
    m = record.get("measures")
    return m if isinstance(m, Mapping) else None
