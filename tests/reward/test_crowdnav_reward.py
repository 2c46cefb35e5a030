"""The CrowdNav++ reward's compiled kernel against its formulas in NumPy (the oracle below is
the vectorised implementation the kernel replaced): every term of every copy bit for bit,
along random batched episodes with collisions, arrivals, near passes and intrusions, and for
configurations that make every branch count."""

from __future__ import annotations

import typing

import numpy as np
import pytest

from pioneer.reward.crowdnav import (
    NO_INTRUSION,
    REWARDS,
    TERMS,
    CrowdNavRewardConfig,
    RewardName,
    crowdnav_reward,
    crowdnav_reward_terms,
)
from pioneer.sim.events import Event, classify
from pioneer.sim.scenarios import get_scenario, sample_state
from pioneer.sim.world import State, World, step


def _oracle(world: World, prev: State, new: State, event, rc: CrowdNavRewardConfig):
    """The terms by the module docstring's formulas, vectorised over copies, humans and k."""
    dt = world.sim.dt
    per_step = dt / rc.reference_dt if rc.reference_dt else 1.0
    k = np.arange(1, rc.n_pred + 1)
    ks = (k * rc.pred_dt).astype(np.float64)
    pen = (rc.intrusion / 2.0 ** (k + 1) * per_step).astype(np.float64)
    collided, reached = event == int(Event.COLLISION), event == int(Event.SUCCESS)
    d0 = np.linalg.norm(prev.goal - prev.robot[:, :2], axis=-1)
    d1 = np.linalg.norm(new.goal - new.robot[:, :2], axis=-1)
    c = new.gap
    close = c < rc.discomfort_distance
    ongoing = ~(collided | reached)
    base = np.where(
        close, (c - rc.discomfort_distance) * rc.discomfort_scale * dt, rc.potential * (d0 - d1)
    )
    first = np.where(collided, rc.collision, np.where(reached, rc.success, base))
    intr = np.zeros(new.batch_size)
    if new.n_humans:
        pred = new.h_pos[:, :, None, :] + new.h_vel[:, :, None, :] * ks[None, None, :, None]
        dist = np.linalg.norm(pred - new.robot[:, None, None, :2], axis=-1)
        hit = (dist < world.sim.robot.radius + new.h_radius[:, :, None]) & new.humans_present[
            ..., None
        ]
        intr = np.where(ongoing, np.where(hit, pen[None, None, :], 0.0).min(axis=(1, 2)), 0.0)
    v, w = new.command[:, 0], new.command[:, 1]
    spin = rc.spin * (w * dt) ** 2 / per_step
    rev = np.where(v < 0.0, rc.reverse * per_step * np.abs(v), 0.0)
    terms = {
        "success": np.where(reached, rc.success, 0.0),
        "collision": np.where(collided, rc.collision, 0.0),
        "discomfort": np.where(ongoing & close, base, 0.0),
        "progress": np.where(ongoing & ~close, base, 0.0),
        "intrusion": intr,
        "spin": spin,
        "reverse": rev,
    }
    return terms, first + intr + spin + rev


CONFIGS = [
    CrowdNavRewardConfig(),
    CrowdNavRewardConfig(reference_dt=None),
    # a positive "penalty" and a wide discomfort zone: the least of hit and missed terms, and
    # the discomfort branch on most steps
    CrowdNavRewardConfig(intrusion=3.0, discomfort_distance=1.5, reverse=-1.0, n_pred=3),
]


@pytest.mark.parametrize("rc", CONFIGS)
def test_the_kernel_equals_the_formulas_bit_for_bit(rc):
    cfg = get_scenario("hr-rl")
    world = cfg.world()
    rng = np.random.default_rng(0)
    s = State.concat([sample_state(cfg, np.random.default_rng(i)) for i in range(12)])
    s.goal[::4] = s.robot[::4, :2] + [0.0, 0.3]  # a goal just ahead: some copies arrive
    seen: set[int] = set()
    intruded = 0
    for _ in range(60):
        prev = s
        s = step(world, prev, rng.uniform([0.0, -1.0], [0.8, 1.0], size=(12, 2)))
        event = classify(prev, s, world.sim.time_limit)
        seen |= set(event.tolist())
        new = s.copy()
        new.command[::3, 0] = -0.2  # reversing: the world never drives backwards (v_min = 0)
        got, total = crowdnav_reward_terms(world, prev, new, event, rc)
        want, want_total = _oracle(world, prev, new, event, rc)
        assert list(got) == list(TERMS)
        for name in TERMS:
            np.testing.assert_array_equal(got[name], want[name], err_msg=name)
        np.testing.assert_array_equal(total, want_total)
        np.testing.assert_array_equal(crowdnav_reward(world, prev, new, event, rc), want_total)
        intruded += int((got["intrusion"] != 0.0).sum())
    assert {int(Event.COLLISION), int(Event.SUCCESS)} <= seen
    # (a positive term is the least of hit and missed (0) terms: 0 unless every one hits)
    assert intruded > 0 or rc.intrusion > 0


def test_no_humans_and_a_single_copy():
    cfg = get_scenario("static")
    world = cfg.world()
    s0 = sample_state(cfg, np.random.default_rng(1))
    s1 = step(world, s0, np.array([[0.4, -0.3]]))
    event = classify(s0, s1, world.sim.time_limit)
    rc = CrowdNavRewardConfig()
    got, total = crowdnav_reward_terms(world, s0, s1, event, rc)
    want, want_total = _oracle(world, s0, s1, event, rc)
    for name in TERMS:
        np.testing.assert_array_equal(got[name], want[name], err_msg=name)
    np.testing.assert_array_equal(total, want_total)


def test_the_named_rewards_and_no_intrusion_against_hand_computed_values():
    """``pioneer train crowdnav++ --reward``'s choices: the original and the same without its
    intrusion term. A robot 0.1 m closer to its goal, 0.5 m from a person at rest (within
    r_r + r_h = 0.9 m of all 5 predicted positions): progress 3 × 0.1 = +0.3; intrusion the
    least of −20/2^(k+1) × Δt/T, k = 1: −5 × 0.1/0.25 = −2.0 — charged by the original only."""
    assert REWARDS["crowdnav"] == CrowdNavRewardConfig()
    assert REWARDS["no-intrusion"] is NO_INTRUSION
    assert set(REWARDS) == set(typing.get_args(RewardName))
    sc = get_scenario("hr-rl")
    world = sc.world()
    prev = sample_state(sc, np.random.default_rng(0))
    to_goal = prev.goal[0] - prev.robot[0, :2]
    new = prev.copy()
    new.robot[0, :2] += 0.1 * to_goal / np.linalg.norm(to_goal)
    new.command[0] = (0.5, 0.0)  # no turn: no spin
    new.gap[0] = np.inf  # no discomfort
    new.h_pos[0] += 50.0  # everybody far, but one person at rest 0.5 m from the robot
    new.h_pos[0, 0] = new.robot[0, :2] + [0.5, 0.0]
    new.h_vel[0] = 0.0
    new.humans_present[0, 0] = True
    event = np.array([Event.NONE], dtype=np.int8)
    for name, intrusion in (("crowdnav", -2.0), ("no-intrusion", 0.0)):
        terms, total = crowdnav_reward_terms(world, prev, new, event, REWARDS[name])
        assert terms["progress"][0] == pytest.approx(0.3)
        assert terms["intrusion"][0] == pytest.approx(intrusion)
        assert terms["discomfort"][0] == terms["spin"][0] == 0.0
        assert total[0] == pytest.approx(0.3 + intrusion)
