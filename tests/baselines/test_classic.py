"""Classical baselines: dynamic window approach (``dwa``) and social-force robot (``sfm``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pioneer_testutils as tu
from pioneer.baselines.classic import DWAPolicy, SocialForceRobotPolicy
from pioneer.control.registry import build_policy, policy_names
from pioneer.errors import ConfigError
from pioneer.eval.episode import run_episode
from pioneer.sim.humans import ARRIVED
from pioneer.sim.robot import integrate_unicycle
from pioneer.sim.scenarios import Region, ScenarioConfig


def _empty_room() -> ScenarioConfig:
    w = 3.0
    return ScenarioConfig(
        name="empty-room",
        walls=((-w, -w, w, -w), (w, -w, w, w), (w, w, -w, w), (-w, w, -w, -w)),
        bounds=(-w, w, -w, w),
        robot_start=Region(x=(-1.5, 1.5), y=(-2.0, -1.5)),
        robot_goal=Region(x=(-1.5, 1.5), y=(1.5, 2.0)),
        robot_heading=(-math.pi, math.pi),
        humans=(),
    )


@pytest.mark.parametrize("name", ["dwa", "sfm", "cvar-bf"])
def test_reaches_the_goal_in_an_empty_room(name: str) -> None:
    pol = build_policy(name)
    for seed in range(3):
        rec, _ = run_episode(_empty_room(), pol, seed)
        assert rec.event == "success", (name, seed, rec)


@pytest.mark.parametrize("name", ["dwa", "sfm"])
def test_no_collision_with_the_static_human(name: str) -> None:
    """Static study: one person in the middle of the room, straight between start and goal.
    The social-force robot slides around them; DWA stops in front (its local minimum: every
    arc toward the goal is blocked and turning away scores worse) — neither touches them."""
    pol = build_policy(name, scenario="static")
    events = []
    for seed in range(5):
        rec, _ = run_episode("static", pol, seed)
        assert rec.event != "collision", (name, seed, rec)
        assert rec.min_gap_m > 0.0
        events.append(rec.event)
    if name == "sfm":
        assert events == ["success"] * 5


@pytest.mark.parametrize("name", ["dwa", "sfm", "cvar-bf"])
def test_runs_in_the_elevator(name: str) -> None:
    pol = build_policy(name, scenario="hr-rl")
    rec, _ = run_episode("hr-rl", pol, seed=0)
    assert rec.event in ("success", "collision", "timeout")
    assert rec.policy == name and rec.steps >= 1
    assert name in policy_names()


@pytest.mark.parametrize("name", ["dwa", "sfm"])
def test_deterministic(name: str) -> None:
    a, ta = run_episode("hl-rr", build_policy(name), seed=5, record=True)
    b, tb = run_episode("hl-rr", build_policy(name), seed=5, record=True)
    assert a == b and ta is not None and tb is not None
    assert np.array_equal(ta.robot, tb.robot)


# ------------------------------------------------------------------------------ DWA pieces
def test_dwa_window_respects_the_acceleration_limits() -> None:
    world = tu.open_world()
    state = tu.make_state(robot=(0.0, 0.0, 0.0), goal=(3.0, 0.0))
    state.command[0] = (0.4, 0.2)
    cmds = DWAPolicy(accel_v=0.5, accel_omega=1.5).window(world, state)
    assert cmds[:, 0].min() == pytest.approx(0.35) and cmds[:, 0].max() == pytest.approx(0.45)
    assert cmds[:, 1].min() == pytest.approx(0.05) and cmds[:, 1].max() == pytest.approx(0.35)
    state.command[0] = (0.0, -1.25)  # clipped to the robot's limits
    cmds = DWAPolicy().window(world, state)
    assert cmds[:, 0].min() == 0.0 and cmds[:, 1].min() == pytest.approx(-0.4 * math.pi)


def test_dwa_prediction_is_the_exact_unicycle() -> None:
    dwa = DWAPolicy(horizon=1.0, sim_dt=0.1)
    pose = np.array([0.5, -0.3, 1.1])
    cmds = np.array([[0.6, 0.0], [0.4, 1.2], [0.0, -0.8]])
    poses = dwa.predict(pose, cmds)
    assert poses.shape == (3, 10, 3)
    for c, (v, w) in enumerate(cmds):
        x, y, th = pose
        for k in range(10):
            x, y, th = integrate_unicycle(x, y, th, v, w, 0.1)
            assert poses[c, k, :2] == pytest.approx([x, y], abs=1e-12)
            assert tu.angle_diff(poses[c, k, 2], th) < 1e-12


def test_dwa_braking_distance_is_the_discrete_sum() -> None:
    dwa = DWAPolicy(accel_v=0.5)
    v = np.array([0.0, 0.05, 0.3, 0.8])
    brute = []
    for v0 in v:
        s, vv = 0.0, v0
        while vv > 1e-12:
            s += 0.1 * vv
            vv = max(0.0, vv - 0.05)
        brute.append(s)
    assert dwa.braking_distance(v, 0.1) == pytest.approx(brute)


def test_dwa_slows_down_for_a_person_ahead() -> None:
    world = tu.open_world()
    state = tu.make_state(
        robot=(0.0, 0.0, 0.0), goal=(5.0, 0.0), humans=[{"pos": (1.2, 0.0), "status": ARRIVED}]
    )
    state.command[0] = (0.8, 0.0)
    u = DWAPolicy().decide(world, state).command
    assert u[0] < 0.8  # cannot keep full speed toward a body 0.3 m away


def test_dwa_rejects_an_unknown_human_model() -> None:
    with pytest.raises(ConfigError) as err:
        DWAPolicy(human_model="oracle")
    tu.assert_house_message(str(err.value), "human_model")


# ------------------------------------------------------------------------------ SFM pieces
def test_sfm_force_pushes_away_from_people_and_walls() -> None:
    sfm = SocialForceRobotPolicy()
    world = tu.open_world()
    base = tu.make_state(robot=(0.0, 0.0, 0.0), goal=(5.0, 0.0))
    alone = sfm.force(world, base)
    assert alone[0] > 0 and alone[1] == pytest.approx(0.0)  # pure goal attraction
    left = tu.make_state(
        robot=(0.0, 0.0, 0.0), goal=(5.0, 0.0), humans=[{"pos": (0.3, 1.0), "status": ARRIVED}]
    )
    assert sfm.force(world, left)[1] < 0.0  # a person on the left pushes to the right
    room = tu.room_world(2.0, 0.5)
    assert sfm.force(room, tu.make_state(robot=(0.0, 0.1, 0.0), goal=(1.5, 0.1)))[1] < 0.0


def test_sfm_heads_around_a_person() -> None:
    world = tu.open_world()
    state = tu.make_state(
        robot=(0.0, 0.0, 0.0), goal=(5.0, 0.0), humans=[{"pos": (1.3, 0.2), "status": ARRIVED}]
    )
    state.command[0] = (0.6, 0.0)
    v, w = SocialForceRobotPolicy().decide(world, state).command
    assert w < 0.0  # turns right, away from the person slightly to the left
    assert 0.0 <= v <= 0.8
