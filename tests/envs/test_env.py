"""Gymnasium environment: registration, API compliance, determinism and episode events."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env, data_equivalence

import pioneer  # noqa: F401  (registers the environment ids)
from pioneer.baselines.classic import GoalPolicy
from pioneer.control import make_policy, policy_names
from pioneer.envs.env import ENV_IDS, NavEnv
from pioneer.errors import CommandError, ConfigError
from pioneer.eval import run_episode
from pioneer.reward.crowdnav import CrowdNavRewardConfig as RewardConfig
from pioneer.sim import GONE, get_scenario, sample_state
from pioneer_testutils import assert_house_message

IDS = ["pioneer/ElevatorHRRL-v1", "pioneer/ElevatorHLRR-v1", "pioneer/StaticStudy-v1"]


def test_ids_registered_on_import():
    assert set(ENV_IDS) == set(IDS)
    for env_id in IDS:
        assert env_id in gym.registry


@pytest.mark.filterwarnings("ignore:.*out of date:DeprecationWarning")
@pytest.mark.parametrize("old", ["pioneer/ElevatorHRRL-v0", "pioneer/StaticStudy-v0"])
def test_the_old_version_is_refused_naming_the_new_one(old):
    """v1 changed the observation (sector 0 centred on the heading): v0 no longer exists."""
    with pytest.raises(gym.error.DeprecatedEnv, match=old.replace("-v0", "-v1")):
        gym.make(old)


@pytest.mark.filterwarnings("ignore:.*symmetric and normalized:UserWarning")
@pytest.mark.parametrize("env_id", IDS)
def test_check_env_passes(env_id):
    check_env(gym.make(env_id).unwrapped)


def test_step_returns_python_bools():
    env = NavEnv("static")
    env.reset(seed=0)
    _, reward, terminated, truncated, _ = env.step(np.zeros(2, dtype=np.float32))
    assert type(reward) is float
    assert type(terminated) is bool
    assert type(truncated) is bool


def test_step_info_equal_for_same_seed_and_action():
    env = NavEnv("hr-rl")
    infos = []
    for _ in range(2):
        env.reset(seed=3)
        infos.append(env.step(np.array([0.3, 0.1], dtype=np.float32))[4])
    assert data_equivalence(infos[0], infos[1])


@pytest.mark.parametrize("env_id", IDS)
def test_gym_make_spaces_and_render(env_id):
    env = gym.make(env_id, render_mode="rgb_array")
    obs, _ = env.reset(seed=0)
    assert env.observation_space.shape == (29,)
    assert env.observation_space.dtype == np.float32
    assert obs.shape == (29,)
    assert obs.dtype == np.float32
    assert env.observation_space.contains(obs)
    np.testing.assert_allclose(env.action_space.low, [0.0, -0.4 * math.pi], rtol=1e-6)
    np.testing.assert_allclose(env.action_space.high, [0.8, 0.4 * math.pi], rtol=1e-6)
    frame = env.render()
    assert frame.ndim == 3
    assert frame.shape[2] == 3
    assert frame.dtype == np.uint8
    assert frame.std() > 0  # something was drawn
    for _ in range(5):
        obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs)
        assert math.isfinite(reward)
        if terminated or truncated:
            break
    assert env.render().shape == frame.shape
    env.close()


def test_render_modes():
    env = NavEnv("static")
    env.reset(seed=0)
    assert env.render() is None
    with pytest.raises(ConfigError) as exc:
        NavEnv("static", render_mode="human")
    assert_house_message(str(exc.value), "render_mode")


def test_state_before_reset_raises():
    env = NavEnv("hr-rl")
    with pytest.raises(ConfigError) as exc:
        _ = env.state
    assert_house_message(str(exc.value), "reset")


def _rollout(env_id, seed, actions):
    env = gym.make(env_id)
    obs, _ = env.reset(seed=seed)
    out = [obs]
    resets = 0
    for a in actions:
        obs, reward, terminated, truncated, _ = env.step(a)
        out.append(obs)
        out.append(np.array([reward, terminated, truncated], dtype=np.float32))
        if terminated or truncated:
            resets += 1
            obs, _ = env.reset(seed=seed + 1000 * resets)
            out.append(obs)
    env.close()
    return out


@pytest.mark.parametrize("env_id", ["pioneer/ElevatorHRRL-v1", "pioneer/ElevatorHLRR-v1"])
def test_same_seed_same_trajectory(env_id):
    rng = np.random.default_rng(2024)
    space = gym.make(env_id).action_space
    actions = rng.uniform(space.low, space.high, (200, 2)).astype(np.float32)
    a = _rollout(env_id, 17, actions)
    b = _rollout(env_id, 17, actions)
    assert len(a) == len(b) >= 401
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x, y)


@pytest.mark.parametrize("env_id", IDS)
def test_different_seed_different_initial_state(env_id):
    env = gym.make(env_id)
    obs0, info0 = env.reset(seed=0)
    obs1, info1 = env.reset(seed=1)
    assert not np.array_equal(info0["robot_pose"], info1["robot_pose"])
    assert not np.array_equal(obs0, obs1)
    obs0b, info0b = env.reset(seed=0)
    assert np.array_equal(obs0, obs0b)
    assert np.array_equal(info0["robot_pose"], info0b["robot_pose"])


def test_reset_with_given_state_and_bad_state():
    env = NavEnv("hr-rl")
    state = sample_state(get_scenario("hr-rl"), np.random.default_rng(5))
    _, info = env.reset(options={"state": state})
    np.testing.assert_array_equal(info["robot_pose"], state.robot[0])
    assert info["state"] is not state  # the env works on a copy
    env.step([0.5, 0.0])
    assert state.t[0] == 0.0
    with pytest.raises(ConfigError) as exc:
        env.reset(options={"state": state.repeat(2)})
    assert_house_message(str(exc.value), "options['state']")


def test_nan_action_raises_command_error():
    env = NavEnv("hr-rl")
    env.reset(seed=0)
    with pytest.raises(CommandError) as exc:
        env.step(np.array([np.nan, 0.0]))
    assert_house_message(str(exc.value), "command")
    with pytest.raises(CommandError):
        env.step([0.1, np.inf])


@pytest.mark.parametrize("action", [[0.1, 0.2, 0.3], [0.1]])
def test_wrong_size_action_raises_command_error(action):
    env = NavEnv("hr-rl")
    env.reset(seed=0)
    with pytest.raises(CommandError) as exc:
        env.step(action)
    assert_house_message(str(exc.value), "command")


def test_info_contents():
    env = NavEnv("hr-rl")
    _, info = env.reset(seed=0)
    for key in (
        "event",
        "robot_pose",
        "goal",
        "min_gap",
        "episode_min_gap",
        "wall_gap",
        "time",
        "path_length",
        "rewards",
        "state",
        "world",
    ):
        assert key in info
    assert info["event"] is None
    assert info["time"] == 0.0
    _, reward, _, _, info = env.step([0.4, 0.0])
    assert set(info["rewards"]) == {
        "success",
        "collision",
        "discomfort",
        "progress",
        "intrusion",
        "spin",
        "reverse",
    }
    assert reward == pytest.approx(sum(info["rewards"].values()))
    assert info["time"] == pytest.approx(0.1)
    assert info["path_length"] == pytest.approx(0.04)
    assert info["episode_min_gap"] <= info["min_gap"]


def _static_without_human(env):
    state = sample_state(env.scenario, np.random.default_rng(0))
    state.h_status[0, :] = GONE
    return env.reset(options={"state": state})


def test_goal_policy_succeeds_in_empty_static_room():
    env = NavEnv("static")
    obs, info = _static_without_human(env)
    policy = GoalPolicy()
    policy.reset(info, np.random.default_rng(0))
    for _ in range(300):
        obs, _, terminated, truncated, info = env.step(policy.act(obs, info))
        if terminated or truncated:
            break
    assert terminated is True
    assert not truncated
    assert info["event"] == "success"
    assert info["rewards"]["success"] == RewardConfig().success
    assert np.linalg.norm(info["robot_pose"][:2] - info["goal"]) < 0.3
    assert info["time"] < 30.0


def test_time_limit_truncates_with_timeout_event():
    env = NavEnv("static")
    _static_without_human(env)
    n = round(env.scenario.sim.time_limit / env.scenario.sim.dt)
    assert n == 300
    for k in range(1, n + 1):
        _, _, terminated, truncated, info = env.step([0.0, 0.0])
        assert not terminated
        if k < n:
            assert not truncated
            assert info["event"] is None
    assert truncated
    assert info["event"] == "timeout"
    assert info["time"] == pytest.approx(30.0)


def test_collision_terminates():
    env = NavEnv("static")
    state = sample_state(env.scenario, np.random.default_rng(0))
    state.robot[0] = [1.0, -1.0, 0.0]  # facing the wall x = 2, 0.7 m of clearance
    env.reset(options={"state": state})
    steps = 0
    terminated = False
    while not terminated and steps < 30:
        _, _, terminated, _, info = env.step([0.8, 0.0])
        steps += 1
    # 0.7 m of clearance at 0.08 m per step: contact during step 9.
    assert steps == 9
    assert terminated is True
    assert info["event"] == "collision"
    assert info["rewards"]["collision"] == RewardConfig().collision
    assert info["wall_gap"] < 0


def test_policy_registry():
    assert "goal" in policy_names()
    assert isinstance(make_policy("goal"), GoalPolicy)
    with pytest.raises(ConfigError) as exc:
        make_policy("telepathy")
    assert_house_message(str(exc.value), "policy", "goal")


def test_run_episode_records_trajectory():
    rec, traj = run_episode("hr-rl", GoalPolicy(), seed=0, record=True)
    assert rec.event in {"success", "collision", "timeout"}
    assert rec.steps == len(traj.states) - 1
    assert traj.robot.shape == (rec.steps + 1, 3)
    assert traj.humans.shape == (rec.steps + 1, 3, 2)
    assert rec.time_s == pytest.approx(0.1 * rec.steps)
    d = rec.to_dict()
    assert d["scenario"] == "hr-rl" and d["policy"] == "goal" and d["seed"] == 0
    rec2, traj2 = run_episode("hr-rl", GoalPolicy(), seed=0)
    assert traj2 is None
    assert rec2 == rec  # deterministic


def test_run_episode_without_humans_reports_no_clearance():
    cfg = get_scenario("static")
    empty = cfg.replace(humans=())
    rec, _ = run_episode(empty, GoalPolicy(), seed=1)
    assert rec.event == "success"
    assert rec.min_gap_m == math.inf
    assert rec.to_dict()["min_gap_m"] is None


def test_the_environment_takes_its_reward_and_the_world_ends_the_episode():
    """A custom step reward replaces the CrowdNav++ reward; the endings stay the world's."""
    calls = []

    def flat(world, prev, new, event):
        calls.append(event.copy())
        return np.full(new.batch_size, 1.0), {"alive": np.full(new.batch_size, 1.0)}

    own, default = NavEnv("hr-rl", reward=flat), NavEnv("hr-rl")
    own.reset(seed=2)
    default.reset(seed=2)
    while True:
        _, r, term, trunc, info = own.step([0.8, 0.0])
        _, _, term_d, trunc_d, info_d = default.step([0.8, 0.0])
        assert r == 1.0 and info["rewards"] == {"alive": 1.0}
        assert (term, trunc, info["event"]) == (term_d, trunc_d, info_d["event"])
        assert int(calls[-1][0]) == info["event_code"]
        if term or trunc:
            break
    assert info["event"] is not None
