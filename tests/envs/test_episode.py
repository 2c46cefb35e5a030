"""The one episode driver: reset with the seed, one command per step, the world's ending."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from pioneer.baselines.classic import GoalPolicy
from pioneer.envs.env import NavEnv
from pioneer.envs.episode import Episode, Step


class _Recorder:
    """Go-to-goal that also remembers what it was reset with and how often it acted."""

    name = "recorder"

    def __init__(self) -> None:
        self.inner = GoalPolicy()
        self.draws: list[float] = []
        self.acts = 0

    def reset(self, info, rng):
        self.inner.reset(info, rng)
        self.draws.append(float(rng.random()))

    def act(self, obs, info):
        self.acts += 1
        return self.inner.act(obs, info)


def test_an_episode_runs_to_the_worlds_ending_and_hands_over_every_step():
    pol = _Recorder()
    ep = Episode(NavEnv("hr-rl"), pol, seed=3)
    steps: list[Step] = []
    info = ep.run(steps.append)
    assert ep.done and ep.event == info["event"] in ("success", "collision", "timeout")
    assert [s.index for s in steps] == list(range(ep.steps)) and ep.steps == pol.acts
    assert all(s.next_info["event"] is None for s in steps[:-1])
    assert steps[-1].next_info["event"] == ep.event
    for a, b in itertools.pairwise(steps):  # each step starts where the last ended
        assert b.info is a.next_info and b.obs is a.next_obs
    assert all(s.command.dtype == np.float64 and s.command.shape == (2,) for s in steps)
    with pytest.raises(RuntimeError, match="ended"):
        ep.step()


def test_the_policy_is_reset_with_a_generator_seeded_by_the_episode_seed():
    pol = _Recorder()
    Episode(NavEnv("hr-rl"), pol, seed=7)
    Episode(NavEnv("hr-rl"), pol, seed=7)
    Episode(NavEnv("hr-rl"), pol, seed=8)
    assert pol.draws[0] == pol.draws[1] == np.random.default_rng(7).random()
    assert pol.draws[2] != pol.draws[0]


def test_stepping_by_hand_and_running_give_the_same_episode():
    a = Episode(NavEnv("hl-rr"), GoalPolicy(), seed=5)
    poses = []
    while not a.done:
        poses.append(a.step().next_info["robot_pose"])
    b = Episode(NavEnv("hl-rr"), GoalPolicy(), seed=5)
    other: list[np.ndarray] = []
    b.run(lambda s: other.append(s.next_info["robot_pose"]))
    np.testing.assert_array_equal(np.stack(poses), np.stack(other))
    assert a.event == b.event and a.steps == b.steps
