"""Batched lookahead rollouts (paper §IV-A.2): candidate set, horizon, exact robot motion,
human models."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from pioneer.control.rollout import rollout
from pioneer.control.teacher import TeacherConfig
from pioneer.errors import ConfigError
from pioneer.sim.humans import ARRIVED, WALKING
from pioneer_testutils import concat_states, make_state, open_world

R_ROBOT = 0.3


def _unicycle_reference(pose, v, w, t):
    """Closed-form unicycle pose after holding (v, ω) for t seconds (independent of the code)."""
    x0, y0, th0 = pose
    if abs(w) < 1e-12:
        return x0 + v * t * math.cos(th0), y0 + v * t * math.sin(th0), th0
    th = th0 + w * t
    return (
        x0 + v / w * (math.sin(th) - math.sin(th0)),
        y0 - v / w * (math.cos(th) - math.cos(th0)),
        th,
    )


def _wrapped(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


# --------------------------------------------------------------------------------------------
# candidate set


def test_candidate_set_is_8_speeds_by_15_turn_rates():
    c = TeacherConfig().candidates()
    assert c.shape == (120, 2)
    assert c.dtype == np.float64
    v = np.unique(c[:, 0])
    np.testing.assert_allclose(v, np.arange(1, 9) / 10, rtol=0, atol=1e-12)
    w = np.unique(c[:, 1])
    assert w.size == 15
    np.testing.assert_allclose(w[[0, -1]], [-0.4 * math.pi, 0.4 * math.pi], rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.diff(w), 0.8 * math.pi / 14, rtol=0, atol=1e-12)
    assert abs(w[7]) < 1e-12  # the straight-ahead command is a candidate
    # the full Cartesian product, each pair exactly once
    pairs = {(round(a, 9), round(b, 9)) for a, b in c}
    assert len(pairs) == 120
    assert pairs == {(round(a, 9), round(b, 9)) for a, b in itertools.product(v, w)}


def test_candidate_set_is_configurable():
    c = TeacherConfig(v_values=(0.2, 0.4), n_omega=3, omega_max=1.0).candidates()
    expected = [[0.2, -1.0], [0.2, 0.0], [0.2, 1.0], [0.4, -1.0], [0.4, 0.0], [0.4, 1.0]]
    np.testing.assert_array_equal(c, expected)


# --------------------------------------------------------------------------------------------
# shapes and exact motion


def test_rollout_has_ten_states_of_every_candidate():
    world = open_world()
    state = make_state((0.0, 0.0, 0.3), goal=(5.0, 1.0))
    cands = TeacherConfig().candidates()
    ro = rollout(world, state, cands)
    assert ro.robot.shape == (120, 10, 3)
    assert ro.obs.shape == (120, 10, world.sim.lidar.obs_dim) == (120, 10, 29)
    assert ro.obs.dtype == np.float32
    assert ro.collided.shape == ro.min_gap.shape == ro.min_wall_gap.shape == (120,)
    assert ro.final.batch_size == 120
    np.testing.assert_allclose(ro.final.t, 3.0, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(ro.commands, cands)
    # the horizon over the step decides L
    assert rollout(world, state, cands[:3], horizon=0.9, dt=0.3).robot.shape == (3, 3, 3)
    assert rollout(world, state, cands[:3], horizon=3.0, dt=0.1).robot.shape == (3, 30, 3)


def test_rollout_poses_are_exact_unicycle_arcs_in_an_empty_world():
    world = open_world()
    pose = (0.7, -1.2, 2.9)  # heading near π: the wrap to (−π, π] is exercised
    state = make_state(pose, goal=(4.0, 4.0))
    cands = TeacherConfig().candidates()
    ro = rollout(world, state, cands)
    assert not ro.collided.any()
    assert np.all(np.isinf(ro.min_gap))  # no humans at all
    assert np.all(np.isinf(ro.min_wall_gap))  # no walls at all
    for c, (v, w) in enumerate(cands):
        for k in range(10):
            x, y, th = _unicycle_reference(pose, v, w, 0.3 * (k + 1))
            np.testing.assert_allclose(ro.robot[c, k, :2], [x, y], rtol=0, atol=1e-9)
            assert abs(_wrapped(ro.robot[c, k, 2] - th)) < 1e-9
            assert -math.pi < ro.robot[c, k, 2] <= math.pi
    # the final goal distance is measured from x_L
    np.testing.assert_allclose(
        ro.final_goal_distance, np.linalg.norm(ro.robot[:, -1, :2] - [4.0, 4.0], axis=1)
    )


def test_rollout_observations_match_the_world_observation_of_each_state():
    from pioneer.sim.world import observe

    world = open_world()
    state = make_state((0.0, 0.0, 0.0), goal=(3.0, 0.0), humans=[{"pos": (2.0, 1.5)}])
    cands = TeacherConfig().candidates()[::17]
    ro = rollout(world, state, cands, precision="float64")  # the world observes in float64
    np.testing.assert_array_equal(ro.obs[:, -1], observe(world, ro.final))
    np.testing.assert_array_equal(ro.robot[:, -1], ro.final.robot)
    fast = rollout(world, state, cands)  # the default: float32 rays, last bits only
    np.testing.assert_allclose(fast.obs, ro.obs, rtol=0.0, atol=1e-4)


def test_rollout_is_deterministic_and_does_not_touch_its_input():
    world = open_world()
    state = make_state(
        (0.0, 0.0, 0.0),
        goal=(4.0, 0.0),
        humans=[{"pos": (2.0, 0.4), "goal": (-3.0, 0.4), "vel": (-0.5, 0.0)}],
    )
    before = state.copy()
    cands = TeacherConfig().candidates()
    a = rollout(world, state, cands)
    b = rollout(world, state, cands)
    assert state == before
    np.testing.assert_array_equal(a.robot, b.robot)
    np.testing.assert_array_equal(a.obs, b.obs)
    np.testing.assert_array_equal(a.collided, b.collided)
    np.testing.assert_array_equal(a.min_gap, b.min_gap)


def test_rollout_refuses_a_batch_and_an_unknown_human_model():
    world = open_world()
    s = make_state((0.0, 0.0, 0.0))
    with pytest.raises(ConfigError, match="B = 1"):
        rollout(world, concat_states([s, s]), TeacherConfig().candidates())
    with pytest.raises(ConfigError, match="human_model"):
        rollout(world, s, TeacherConfig().candidates(), human_model="oracle")


# --------------------------------------------------------------------------------------------
# human models


def _walkers():
    return [
        {"pos": (3.0, 4.0), "goal": (-20.0, 4.0), "vel": (-0.6, 0.0)},
        {"pos": (-4.0, -3.0), "goal": (-4.0, 20.0), "vel": (0.1, 0.5)},
        {"pos": (6.0, -6.0), "status": ARRIVED},  # standing still: stays put
    ]


@pytest.mark.parametrize("horizon", [0.9, 3.0])
def test_constant_velocity_humans_move_in_straight_lines(horizon):
    world = open_world()
    state = make_state((0.0, 0.0, 0.0), goal=(2.0, 0.0), humans=_walkers())
    cands = TeacherConfig().candidates()[::10]
    ro = rollout(world, state, cands, horizon=horizon, human_model="constant_velocity")
    expected = state.h_pos[0] + state.h_vel[0] * horizon
    for c in range(cands.shape[0]):
        np.testing.assert_allclose(ro.final.h_pos[c], expected, rtol=0, atol=1e-12)


def test_privileged_humans_follow_the_social_force_model():
    world = open_world()
    state = make_state((0.0, 0.0, 0.0), goal=(2.0, 0.0), humans=_walkers())
    ro = rollout(world, state, TeacherConfig().candidates()[:2], human_model="privileged")
    linear = state.h_pos[0] + state.h_vel[0] * 3.0
    # walkers accelerate toward v_pref along their goal direction, unlike the linear prediction
    assert not np.allclose(ro.final.h_pos[0, :2], linear[:2], atol=1e-3)
    assert ro.final.h_status[0, 0] == WALKING
    assert ro.final.h_pos[0, 0, 0] < state.h_pos[0, 0, 0]  # walking toward its goal (−x)
    np.testing.assert_array_equal(ro.final.h_pos[:, 2], np.tile(state.h_pos[0, 2], (2, 1)))


def test_constant_velocity_rollout_flags_an_overlap_at_the_horizon():
    world = open_world()
    # The robot creeps along +x at 0.1 m/s; a person walks at it at 0.9 m/s: the bodies overlap
    # (clearance 3.75 − 1.0·t − 0.9) from t ≈ 2.85 s on, so at t = 3 s they overlap by 0.15 m.
    state = make_state(
        (0.0, 0.0, 0.0),
        goal=(5.0, 0.0),
        humans=[{"pos": (3.75, 0.0), "goal": (-10.0, 0.0), "vel": (-0.9, 0.0)}],
    )
    ro = rollout(world, state, np.array([[0.1, 0.0]]), human_model="constant_velocity")
    gap = np.linalg.norm(ro.final.h_pos[0, 0] - ro.robot[0, -1, :2]) - R_ROBOT - 0.6
    assert gap < -0.1  # the predicted bodies overlap at the horizon ...
    assert ro.min_gap[0] <= gap + 1e-9  # ... so the clearance must say so
    assert ro.collided[0]  # ... and the candidate must be infeasible


@pytest.mark.parametrize("human_model", ["privileged", "constant_velocity"])
def test_rollout_observes_a_subset_of_candidates_with_the_same_values(human_model):
    """``observations(which)`` (what the teacher asks for: its feasible candidates) equals the
    rows of ``obs``, whether or not ``obs`` was cast first."""
    world = open_world()
    state = make_state(
        (0.0, 0.0, 0.0), goal=(4.0, 0.0), humans=[{"pos": (1.2, 0.1), "vel": (-0.4, 0.0)}]
    )
    cands = TeacherConfig().candidates()
    which = np.arange(len(cands)) % 3 == 1
    assert rollout(world, state, cands, human_model=human_model).collided[which].any()
    subset = rollout(world, state, cands, human_model=human_model).observations(which)
    ro = rollout(world, state, cands, human_model=human_model)
    np.testing.assert_array_equal(subset, ro.obs[which])
    np.testing.assert_array_equal(ro.observations(which), ro.obs[which])
