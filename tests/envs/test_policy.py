"""The one policy interface: every privileged planner decides with one signature."""

from __future__ import annotations

import numpy as np
import pytest

from pioneer.control.registry import build_policy
from pioneer.envs.env import NavEnv
from pioneer.envs.policy import Decision, Planner, Policy

PLANNERS = ("teacher", "cvar-bf", "dwa", "sfm")


@pytest.mark.parametrize("name", PLANNERS)
def test_every_planner_decides_with_one_signature_and_acts_by_it(name):
    """``decide(world, state, prev)`` returns a Decision whose command is what ``act`` sends
    from the same state (a fresh policy each time: the teacher smooths from its own past)."""
    env = NavEnv("hr-rl")
    obs, info = env.reset(seed=5)
    for _ in range(3):  # a state with a last command that is not zero
        obs, _, _, _, info = env.step(np.array([0.3, 0.1]))
    acting, deciding = build_policy(name, "hr-rl"), build_policy(name, "hr-rl")
    assert isinstance(acting, Policy) and isinstance(deciding, Planner)
    for pol in (acting, deciding):
        pol.reset(info, np.random.default_rng(0))
    sent = acting.act(obs, info)
    d = deciding.decide(info["world"], info["state"])
    assert isinstance(d, Decision) and d.command.shape == (2,)
    np.testing.assert_array_equal(d.command, sent)
    # ``prev``, the command applied on the last step, is what a labeller passes: planners
    # that read it from the state give the same; the teacher smooths from it instead
    again = build_policy(name, "hr-rl")
    again.reset(info, np.random.default_rng(0))
    labelled = again.decide(info["world"], info["state"], prev=info["state"].command[0])
    assert np.array_equal(labelled.command, sent) == (name != "teacher")
