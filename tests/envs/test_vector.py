"""The native vector env: registered for make_vec, identical to Gymnasium's sync vector env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import pioneer  # noqa: F401  (registers the environment ids)
from pioneer.envs.env import NavEnv
from pioneer.envs.vector import NavVectorEnv
from pioneer.errors import ConfigError
from pioneer.reward.crowdnav import CrowdNavRewardConfig, crowdnav_reward_terms
from pioneer.sim.events import Event, classify
from pioneer.sim.scenarios import get_scenario, sample_state
from pioneer.sim.world import State, step


def test_make_vec_returns_the_native_vector_env() -> None:
    envs = gym.make_vec(
        "pioneer/ElevatorHRRL-v1", num_envs=4, vectorization_mode="vector_entry_point"
    )
    assert isinstance(envs.unwrapped, NavVectorEnv)
    assert envs.observation_space.shape == (4, 29)
    assert envs.action_space.shape == (4, 2)
    envs.close()


@pytest.mark.parametrize("scenario", ["hr-rl", "static"])
def test_native_equals_sync_step_for_step(scenario: str) -> None:
    """Same seeds, same actions → identical observations, rewards, flags, across autoresets."""
    env_id = {"hr-rl": "pioneer/ElevatorHRRL-v1", "static": "pioneer/StaticStudy-v1"}[scenario]
    n = 6
    native = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point")
    sync = gym.make_vec(env_id, num_envs=n, vectorization_mode="sync")
    o1, _ = native.reset(seed=11)
    o2, _ = sync.reset(seed=11)
    np.testing.assert_array_equal(o1, o2)
    native.action_space.seed(3)
    ends = 0
    for _ in range(160):
        a = native.action_space.sample()
        r1 = native.step(a)
        r2 = sync.step(a)
        for x, y in zip(r1[:4], r2[:4], strict=True):
            np.testing.assert_array_equal(x, y)
        ends += int(np.sum(r1[2] | r1[3]))
    assert ends > 0  # the comparison went through autoresets
    native.close()
    sync.close()


def test_event_codes_match_the_single_env_labels() -> None:
    envs = NavVectorEnv(num_envs=3, scenario="static")
    envs.reset(seed=0)
    seen: set[int] = set()
    for _ in range(400):
        _, _, term, trunc, info = envs.step(np.tile([0.8, 0.0], (3, 1)))
        ended = term | trunc
        seen |= set(info["event_code"][ended].tolist())
        labels = [Event(int(c)).label for c in info["event_code"]]
        assert info["event"].tolist() == labels
    assert seen <= {int(Event.SUCCESS), int(Event.COLLISION), int(Event.TIMEOUT)} and seen


def test_the_vector_env_reports_the_single_envs_info_copy_by_copy() -> None:
    """Same keys; every value of copy i equals what NavEnv seeded ``seed + i`` reports."""
    n = 3
    native = NavVectorEnv(num_envs=n, scenario="hr-rl")
    singles = [NavEnv("hr-rl") for _ in range(n)]
    _, vinfo = native.reset(seed=5)
    sinfo = [e.reset(seed=5 + i)[1] for i, e in enumerate(singles)]
    assert set(vinfo) == set(sinfo[0])
    rng = np.random.default_rng(0)
    for _ in range(40):
        a = rng.uniform([0.0, -1.0], [0.8, 1.0], size=(n, 2)).astype(np.float32)
        _, _, _, _, vinfo = native.step(a)
        sinfo = [e.step(a[i])[4] for i, e in enumerate(singles)]
        assert set(vinfo) == set(sinfo[0])
        for i, si in enumerate(sinfo):
            for key in ("event", "event_code", "min_gap", "episode_min_gap",
                        "wall_gap", "time", "path_length"):  # fmt: skip
                assert vinfo[key][i] == si[key], key
            np.testing.assert_array_equal(vinfo["robot_pose"][i], si["robot_pose"])
            np.testing.assert_array_equal(vinfo["goal"][i], si["goal"])
            assert {k: v[i] for k, v in vinfo["rewards"].items()} == si["rewards"]
            assert vinfo["state"].take(i) == si["state"]
        if any(si["event"] is not None for si in sinfo):
            break


def test_bad_arguments_are_refused() -> None:
    with pytest.raises(ConfigError, match="num_envs"):
        NavVectorEnv(num_envs=0)
    with pytest.raises(ConfigError, match="reset"):
        _ = NavVectorEnv(num_envs=2).state
    with pytest.raises(ConfigError, match="seed"):
        NavVectorEnv(num_envs=2).reset(seed=[1])


def test_one_reward_spin_term_charges_the_heading_change() -> None:
    """The spin term is spin · (ω Δt)² (the original's per-step rotation), rescaled by T/Δt so
    that a second of turning costs what it costs at the original's step T; the environment's
    total equals the reward function's."""
    cfg = get_scenario("hr-rl")
    world = cfg.world()
    s0 = sample_state(cfg, np.random.default_rng(0))
    s1 = step(world, s0, np.array([[0.3, 0.5]]))
    rc = CrowdNavRewardConfig()
    event = classify(s0, s1, world.sim.time_limit)
    terms, total = crowdnav_reward_terms(world, s0, s1, event, rc)
    w = float(s1.command[0, 1])
    dt, t_ref = cfg.sim.dt, rc.reference_dt
    assert terms["spin"][0] == pytest.approx(rc.spin * (w * dt) ** 2 * t_ref / dt)
    # a second of turning at ω: 1/Δt steps here, 1/T steps of (ω T)² there
    assert terms["spin"][0] / dt == pytest.approx(rc.spin * (w * t_ref) ** 2 / t_ref)
    per_step = crowdnav_reward_terms(world, s0, s1, event, CrowdNavRewardConfig(reference_dt=None))[
        0
    ]
    assert per_step["spin"][0] == pytest.approx(rc.spin * (w * dt) ** 2)
    env = NavEnv("hr-rl")
    env.reset(options={"state": s0})
    _, r, *_ = env.step([0.3, 0.5])
    assert r == float(total[0])


def test_classify_counts_only_this_step_and_collision_wins() -> None:
    cfg = get_scenario("static")
    s = State.concat([sample_state(cfg, np.random.default_rng(i)) for i in range(4)])
    new = s.copy()
    new.collided[:] = [True, True, False, False]
    new.reached[:] = [True, False, True, False]
    prev = s.copy()
    prev.collided[1] = True  # copy 1 had already collided
    codes = classify(prev, new, time_limit=1e9)
    assert codes.tolist() == [Event.COLLISION, Event.NONE, Event.SUCCESS, Event.NONE]
    new.t[:] = 1e9
    assert classify(prev, new, time_limit=1e9).tolist()[3] == Event.TIMEOUT


def test_classify_equals_its_rule_on_every_combination() -> None:
    """Against the rule written with array operators (the oracle): every combination of
    collided / arrived before and after the step, and times around the limit."""
    cfg = get_scenario("static")
    base = sample_state(cfg, np.random.default_rng(0))
    flags = np.array(np.meshgrid([0, 1], [0, 1], [0, 1], [0, 1], [0, 1, 2])).reshape(5, -1)
    n = flags.shape[1]
    prev, new = base.repeat(n), base.repeat(n)
    prev.collided[:], prev.reached[:] = flags[0] == 1, flags[1] == 1
    new.collided[:], new.reached[:] = flags[2] == 1, flags[3] == 1
    limit = 30.0
    new.t[:] = np.array([29.9, limit - 1e-10, 30.1])[flags[4]]
    collided = new.collided & ~prev.collided
    reached = new.reached & ~prev.reached & ~collided
    timeout = ~(collided | reached) & (new.t >= limit - 1e-9)
    want = np.where(
        collided, Event.COLLISION, np.where(reached, Event.SUCCESS, np.where(timeout, 3, 0))
    )
    got = classify(prev, new, limit)
    assert got.dtype == np.int8
    np.testing.assert_array_equal(got, want)
    assert set(got.tolist()) == {0, 1, 2, 3}
