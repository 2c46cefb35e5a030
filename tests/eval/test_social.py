"""The social-navigation measures on hand-built trajectories whose values are known in closed
form: a straight line at constant speed, a circle, a stop-and-go profile, a head-on approach
with a known time to collision, collisions of each kind."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pioneer.eval.social import (
    HALL_ZONES,
    STILL_SPEED,
    EpisodeMeasures,
    accelerations,
    closest_approach,
    heading_change,
    measure_episode,
    path_irregularity,
    person_hit_kind,
    series_of,
    spl,
    stall_count,
    time_shares,
    time_still,
    time_to_collision,
)
from pioneer.sim.scenarios import HumanSpec, Region, ScenarioConfig
from pioneer.sim.world import SimConfig
from pioneer_testutils import make_state

DT = 0.1  # [s]
R_R = 0.3  # [m] the robot's radius (SimConfig's default)
R_H = 0.6  # [m]


def _scenario(roles: tuple[str, ...] = (), walls=((-20.0, -20.0, -20.0, 20.0),)) -> ScenarioConfig:
    """An open floor (one far wall) with a person of each role."""
    spot = Region(x=(10.0, 10.0), y=(10.0, 10.0))
    return ScenarioConfig(
        name="flat",
        walls=walls,
        bounds=(-30.0, 30.0, -30.0, 30.0),
        robot_start=Region(x=(0.0, 0.0), y=(0.0, 0.0)),
        robot_goal=Region(x=(1.0, 1.0), y=(0.0, 0.0)),
        robot_heading=(0.0, 0.0),
        humans=tuple(HumanSpec(role=r, start=spot, goal=spot) for r in roles),
        sim=SimConfig(dt=DT),
    )


def _episode(poses, speeds, goal, humans=None):
    """States of a hand-built episode: ``poses (T+1, 3)``, the speed of each of the T steps,
    and per state a list of human dicts (``pos``, ``vel``) or none; the gap of each state is
    its instantaneous gap."""
    poses = np.asarray(poses, dtype=float)
    path = np.concatenate([[0.0], np.cumsum(speeds) * DT])
    states = []
    for k, pose in enumerate(poses):
        hs = humans[k] if humans is not None else []
        s = make_state(pose, goal, hs)
        gaps = [math.dist(h["pos"], pose[:2]) - R_R - h.get("radius", R_H) for h in hs]
        s = dataclasses.replace(
            s,
            start=poses[:1, :2].copy(),
            command=np.array([[speeds[k - 1] if k else 0.0, 0.0]]),
            path_length=np.array([path[k]]),
            t=np.array([k * DT]),
            gap=np.array([min(gaps, default=math.inf)]),
        )
        states.append(s)
    return states


def _line(v: float, steps: int, y: float = 0.0) -> np.ndarray:
    """Poses of a straight drive along +x at ``v`` [m/s]."""
    x = v * DT * np.arange(steps + 1)
    return np.stack([x, np.full_like(x, y), np.zeros_like(x)], axis=-1)


# ------------------------------------------------------------------------------ straight line
def test_a_straight_line_at_constant_speed():
    """0.5 m/s for 20 steps from rest: 1 m; goal 1.3 m ahead (1 m to its 0.3 m region)."""
    states = _episode(_line(0.5, 20), [0.5] * 20, (1.3, 0.0))
    m = measure_episode(_scenario(), states, "success")
    assert m.shortest_path_m == pytest.approx(1.0)  # 1.3 m − the goal tolerance
    assert m.spl == pytest.approx(1.0) and m.path_efficiency == pytest.approx(1.0)
    assert m.time_still_s == 0.0 and m.stalls == 0
    # a = 5 m/s² on the first step (from rest), then 0; jerk +50, −50 m/s³, then 0
    assert m.accel_max_m_s2 == pytest.approx(5.0)
    assert m.accel_mean_m_s2 == pytest.approx(5.0 / 20)
    assert m.jerk_max_m_s3 == pytest.approx(50.0)
    assert m.jerk_mean_m_s3 == pytest.approx(100.0 / 20)
    assert m.heading_change_rad == 0.0 and m.path_irregularity_rad_m == 0.0
    assert math.isnan(m.intimate_share) and math.isinf(m.min_ttc_s)  # nobody there
    assert m.person_hit is None and not m.wall_hit


def test_a_longer_path_scales_spl_and_a_failure_scores_zero():
    states = _episode(_line(0.5, 40), [0.5] * 40, (1.3, 0.0))  # drives 2 m where 1 m would do
    assert measure_episode(_scenario(), states, "success").spl == pytest.approx(0.5)
    failed = measure_episode(_scenario(), states, "timeout")
    assert failed.spl == 0.0 and math.isnan(failed.path_efficiency)
    assert spl(True, 4.0, 3.0) == 1.0  # inside the goal region early: capped at 1
    assert math.isnan(spl(True, math.inf, 3.0))


# ------------------------------------------------------------------------------ circle
def test_a_circle_turns_by_omega_times_t():
    """v = 0.5 m/s, ω = 0.5 rad/s (radius 1 m) for 60 steps: 3 rad of heading, 3 m of path."""
    omega, v, n = 0.5, 0.5, 60
    th = omega * DT * np.arange(n + 1)
    poses = np.stack([np.sin(th) / omega * v, (1 - np.cos(th)) / omega * v, th], axis=-1)
    assert heading_change(th) == pytest.approx(omega * n * DT)
    assert heading_change(np.array([3.0, -3.0])) == pytest.approx(2 * math.pi - 6.0)  # wrapped
    states = _episode(poses, [v] * n, (5.0, 0.0))
    m = measure_episode(_scenario(), states, "timeout")
    assert m.heading_change_rad == pytest.approx(3.0)
    # the goal lies straight ahead of the start heading: no rotation is needed
    assert m.path_irregularity_rad_m == pytest.approx(3.0 / 3.0)
    assert path_irregularity(1.0, 2.0, 4.0) == 0.0  # never below 0
    assert math.isnan(path_irregularity(1.0, 0.0, 0.0))


# ------------------------------------------------------------------------------ stop and go
def test_stop_and_go():
    """0.5 m/s for 2 s, standing 6 s, 0.5 m/s for 2 s (dt = 0.1 s), 10 m from the goal."""
    speeds = [0.5] * 20 + [0.0] * 60 + [0.5] * 20
    x = np.concatenate([[0.0], np.cumsum(speeds) * DT])
    poses = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=-1)
    states = _episode(poses, speeds, (10.0, 0.0))
    m = measure_episode(_scenario(), states, "timeout")
    assert m.time_still_s == pytest.approx(6.0)
    assert m.stalls == 1  # 6 s without progress: one failure to progress
    # accelerations +5, −5, +5 m/s² at the three changes; jerks ±50 m/s³ twice at each
    assert m.accel_max_m_s2 == pytest.approx(5.0)
    assert m.accel_mean_m_s2 == pytest.approx(15.0 / 100)
    assert m.jerk_mean_m_s3 == pytest.approx(300.0 / 100)
    np.testing.assert_allclose(accelerations(np.array([1.0, 1.0, 0.0]), 0.5), [2.0, 0.0, -2.0])
    assert time_still(np.array([0.0, 0.04, -0.04, 0.05, 0.6]), DT) == pytest.approx(0.3)
    assert STILL_SPEED == 0.05


def test_failure_to_progress_counts_each_long_stretch_once():
    go = np.linspace(3.9, 3.0, 10)  # 0.1 m per step
    d = np.concatenate([np.linspace(5, 4, 11), np.full(49, 4.0), go])
    assert stall_count(d, DT) == 0  # 4.9 s of standing: not yet 5 s
    d = np.concatenate([np.linspace(5, 4, 11), np.full(50, 4.0), go])
    assert stall_count(d, DT) == 1  # 5 s
    d = np.concatenate([np.full(200, 5.0), np.linspace(5, 3, 21), np.full(60, 3.0)])
    assert stall_count(d, DT) == 2  # 20 s is still one stall; then another 6 s
    creep = 5.0 - 0.01 * np.arange(100)  # 0.1 m/s … but 1 cm per step
    assert stall_count(creep, DT) == 0  # 0.1 m in 1 s: progress
    slow = 5.0 - 0.001 * np.arange(100)  # 1 cm/s: 0.1 m takes 10 s
    assert stall_count(slow, DT) == 1


# ------------------------------------------------------------------------------ people
def test_time_to_collision_of_a_head_on_approach():
    """Robot at 0 moving +x at 1 m/s, person at 5 m moving −x at 1 m/s, radii 0.3 + 0.6:
    contact when the 5 m closed to 0.9 m at 2 m/s, after 2.05 s."""
    ttc = time_to_collision(np.array([5.0, 0.0]), np.array([-2.0, 0.0]), 0.9)
    assert ttc == pytest.approx(2.05)
    # offset by 0.5 m sideways: contact at x-distance √(0.9² − 0.5²)
    ttc = time_to_collision(np.array([5.0, 0.5]), np.array([-2.0, 0.0]), 0.9)
    assert ttc == pytest.approx((5.0 - math.sqrt(0.81 - 0.25)) / 2.0)
    assert time_to_collision(np.array([5.0, 1.0]), np.array([-2.0, 0.0]), 0.9) == math.inf
    assert time_to_collision(np.array([5.0, 0.0]), np.array([2.0, 0.0]), 0.9) == math.inf
    assert time_to_collision(np.array([0.5, 0.0]), np.array([2.0, 0.0]), 0.9) == 0.0  # overlap


def test_head_on_episode_min_ttc_and_clearances():
    """The robot drives +x at 0.5 m/s for 10 steps, the person comes at 0.5 m/s from 6 m."""
    n, v = 10, 0.5
    poses = _line(v, n)
    humans = [[{"pos": (6.0 - v * DT * k, 0.0), "vel": (-v, 0.0)}] for k in range(n + 1)]
    states = _episode(poses, [v] * n, (20.0, 0.0), humans)
    m = measure_episode(_scenario(("walking",)), states, "timeout")
    gap_end = 6.0 - 2 * v * DT * n - R_R - R_H  # 4.1 m after the last step
    assert m.min_ttc_s == pytest.approx(gap_end / (2 * v))
    assert m.min_clearance_m == pytest.approx(gap_end + R_R)
    assert m.social_share == 0.0 and m.space_compliance == 1.0  # clearance ≥ 3.6 m … 5 m
    # a standing person whose surface stays 2 m ahead of the robot's centre: clearance 2 m
    # (the social zone) at every step, a gap of 1.7 m closed at 0.5 m/s
    ahead = [[{"pos": (x + 2.0 + R_H, 0.0)}] for x in poses[:, 0]]
    states = _episode(poses, [v] * n, (20.0, 0.0), ahead)
    m = measure_episode(_scenario(("static",)), states, "timeout")
    assert (m.intimate_share, m.personal_share, m.social_share) == (0.0, 0.0, 1.0)
    assert m.min_ttc_s == pytest.approx((2.0 - R_R) / v)
    assert m.space_compliance == 1.0


def test_hall_zones_and_space_compliance_on_a_known_series():
    clear = np.array([0.2, 0.44, 0.45, 1.0, 1.19, 1.2, 3.59, 3.6, 10.0, np.inf])
    shares = time_shares(clear, [(lo, hi) for _, lo, hi in HALL_ZONES])
    assert shares == [pytest.approx(0.2), pytest.approx(0.3), pytest.approx(0.2)]
    gap = clear - R_R
    (compliant,) = time_shares(gap, [(0.5, math.inf)])
    assert compliant == pytest.approx(0.6)  # clearance ≥ 0.8 m: 6 of 10
    assert [z[0] for z in HALL_ZONES] == ["intimate", "personal", "social"]


# ------------------------------------------------------------------------------ collisions
def test_who_ran_into_whom():
    ahead = np.array([1.0, 0.0])
    assert person_hit_kind(0.5, 0.0, ahead) == "robot-into-person"
    assert person_hit_kind(0.01, 0.0, ahead) == "person-into-robot"  # standing
    assert person_hit_kind(0.5, math.pi, ahead) == "person-into-robot"  # moving away
    assert person_hit_kind(0.5, math.pi / 2, np.array([1.0, 0.1])) == "robot-into-person"
    np.testing.assert_allclose(
        closest_approach(np.array([[-2.0, 1.0]]), np.array([[2.0, 1.0]])), [1.0]
    )
    np.testing.assert_allclose(closest_approach(np.array([3.0, 4.0]), np.array([3.0, 4.0])), 5.0)


def _collision(robot_speed, robot_heading, exiting_vel):
    """Two steps: the exiting person (slot 1) meets the robot; the boarding one (slot 0) is
    far. Returns the measures of the collision."""
    poses = [
        (0.0, 0.0, robot_heading),
        (robot_speed * DT * math.cos(robot_heading), 0.0, robot_heading),
    ]
    ex0 = np.array([0.95, 0.0])
    ex1 = ex0 + DT * np.asarray(exiting_vel)
    humans = [
        [{"pos": (5.0, 5.0)}, {"pos": tuple(ex0), "vel": exiting_vel}],
        [{"pos": (5.0, 5.0)}, {"pos": tuple(ex1), "vel": exiting_vel}],
    ]
    states = _episode(poses, [robot_speed], (9.0, 0.0), humans)
    return measure_episode(_scenario(("boarding", "exiting")), states, "collision", "human")


def test_collisions_by_kind_and_by_person():
    m = _collision(0.5, 0.0, (0.0, 0.0))  # the robot drives into a standing person
    assert (m.person_hit, m.person_role, m.person_index) == ("robot-into-person", "exiting", 1)
    assert not m.wall_hit and m.min_ttc_s == 0.0
    m = _collision(0.0, 0.0, (-1.0, 0.0))  # the robot stands, the person walks into it
    assert (m.person_hit, m.person_role) == ("person-into-robot", "exiting")
    m = _collision(0.5, math.pi, (-1.0, 0.0))  # the robot backs away… forward, heading away
    assert m.person_hit == "person-into-robot"
    poses = _line(0.5, 1)
    wall = measure_episode(_scenario(), _episode(poses, [0.5], (9.0, 0.0)), "collision", "wall")
    assert wall.wall_hit and wall.person_hit is None


def test_the_record_form_is_compact_and_strict_json():
    states = _episode(_line(0.5, 3), [0.5] * 3, (9.0, 0.0))
    d = measure_episode(_scenario(), states, "timeout").to_dict()
    assert d["min_ttc_s"] is None and d["intimate_share"] is None  # inf, NaN → None
    assert d["accel_mean_m_s2"] == float(f"{5.0 / 3:.6g}")
    s = series_of(states, R_R)
    assert s["x"] == [0.0, 0.05, 0.1, 0.15] and s["y"] == [0.0] * 4
    assert s["clearance"] == [None] * 3  # nobody: no clearance


def test_an_episode_record_carries_its_measures_and_series():
    from pioneer.control.registry import build_policy
    from pioneer.eval.episode import RECORD_FORMAT, run_episode

    rec, _ = run_episode("static", build_policy("goal", "static"), seed=3)
    d = rec.to_dict()
    assert d["format"] == RECORD_FORMAT == 3
    m, s = d["measures"], d["series"]
    assert set(m) == {f.name for f in dataclasses.fields(EpisodeMeasures)}
    assert len(s["x"]) == len(s["y"]) == rec.steps + 1 and len(s["clearance"]) == rec.steps
    assert m["min_clearance_m"] == pytest.approx(rec.min_gap_m + R_R, abs=1e-5)
    assert min(c for c in s["clearance"] if c is not None) == pytest.approx(
        m["min_clearance_m"], abs=1e-3
    )
    assert rec.event == "collision" and m["person_hit"] == "robot-into-person"
    assert m["person_role"] == "static" and m["min_ttc_s"] == 0.0
    assert all(round(x, 3) == x for x in s["x"])  # to the millimetre
