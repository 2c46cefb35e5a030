"""Rule terms and distance-adaptive weights of the teacher's score (paper §IV-A.2, eqs. 13–18)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pioneer.errors import ConfigError
from pioneer.reward.rules import RuleWeights, adaptive_weights, combine, goal_term, obstacle_term


def test_goal_term_hand_values():
    d_goal = np.array([0.0, 1.0, 2.0, 4.0, 8.0])
    got = goal_term(d_goal, 4.0)
    want = [1.0, 1 - math.tanh(0.25), 1 - math.tanh(0.5), 1 - math.tanh(1.0), 1 - math.tanh(2.0)]
    np.testing.assert_allclose(got, want, rtol=1e-15)
    assert got[0] == 1.0  # at the goal
    assert np.all(np.diff(got) < 0)  # farther → smaller
    # per-candidate d_total
    np.testing.assert_allclose(
        goal_term(np.array([1.0, 1.0]), np.array([1.0, 2.0])),
        [1 - math.tanh(1.0), 1 - math.tanh(0.5)],
    )


def test_goal_term_with_zero_total_distance_is_finite():
    assert np.isfinite(goal_term(np.array([0.0, 0.5]), 0.0)).all()


def test_obstacle_term_uses_the_two_nearest_descriptors():
    obs = np.full((2, 3, 29), 9.0, dtype=np.float32)  # ranges elsewhere must not matter
    # candidate 0: d_1/d_2 per step → min = 0.5, 1.0, 1.5 → mean 1.0
    obs[0, :, 24] = [0.5, 2.0, 1.5]
    obs[0, :, 25] = [0.7, 1.0, 3.0]
    # candidate 1: min = 0.2 every step
    obs[1, :, 24] = 0.2
    obs[1, :, 25] = 0.9
    got = obstacle_term(obs)
    np.testing.assert_allclose(got, [math.tanh(1.0), math.tanh(0.2)], rtol=1e-6)
    assert got.dtype == np.float64
    # with n_nearest = 1 only d_1 counts
    np.testing.assert_allclose(obstacle_term(obs, n_nearest=1)[0], math.tanh((0.5 + 2.0 + 1.5) / 3))


@pytest.mark.parametrize(
    ("d_goal", "d_total", "a_den", "a_goal"),
    [
        (4.0, 4.0, 2.0, 0.0),  # r = 1: far from the goal → density dominates
        (0.0, 4.0, 0.0, 2.0),  # r = 0: at the goal → goal dominates
        (2.0, 4.0, 1.0, 1.0),  # r = ½: cos(π/2) = 0
        (1.0, 4.0, 1.0 + math.cos(0.75 * math.pi), 1.5),
        (9.0, 4.0, 2.0, 0.0),  # beyond the start distance r is clipped to 1
    ],
)
def test_adaptive_weights_hand_values(d_goal, d_total, a_den, a_goal):
    w_den, w_goal, w_obs = adaptive_weights(np.array([d_goal]), d_total)
    assert w_den[0] == pytest.approx(a_den, abs=1e-15)
    assert w_goal[0] == pytest.approx(a_goal, abs=1e-15)
    assert w_obs[0] == 1.0


@settings(max_examples=50, deadline=None)
@given(st.floats(0.0, 20.0), st.floats(0.1, 10.0))
def test_adaptive_weights_formula(d_goal, d_total):
    w_den, w_goal, w_obs = adaptive_weights(np.array([d_goal]), d_total)
    r = min(max(d_goal / d_total, 0.0), 1.0)
    assert w_den[0] == pytest.approx(1 + math.cos(math.pi * (1 - r)), abs=1e-12)
    assert w_goal[0] == pytest.approx(2 * (1 - r), abs=1e-12)
    assert w_obs[0] == 1.0
    assert 0.0 <= w_den[0] <= 2.0 and 0.0 <= w_goal[0] <= 2.0


def _terms():
    r_den = np.array([0.5, -0.3, 0.8])
    r_goal = np.array([0.2, 0.9, 0.4])
    r_obs = np.array([0.7, 0.1, 0.6])
    d_goal = np.array([4.0, 0.0, 2.0])  # r = 1, 0, ½
    return r_den, r_goal, r_obs, d_goal, 4.0


def test_combine_default_is_the_adaptive_sum():
    r_den, r_goal, r_obs, d_goal, d_total = _terms()
    total, parts = combine(r_den, r_goal, r_obs, d_goal, d_total, RuleWeights())
    # α_den = (2, 0, 1), α_goal = (0, 2, 1), α_obs = 1
    np.testing.assert_allclose(parts["density"], [1.0, 0.0, 0.8], atol=1e-15)
    np.testing.assert_allclose(parts["goal"], [0.0, 1.8, 0.4], atol=1e-15)
    np.testing.assert_allclose(parts["obstacle"], r_obs)
    np.testing.assert_allclose(total, [1.7, 1.9, 1.8], atol=1e-15)
    np.testing.assert_allclose(total, parts["density"] + parts["goal"] + parts["obstacle"])


@pytest.mark.parametrize("off", ["density", "goal", "obstacle"])
def test_combine_switches_zero_one_term(off):
    r_den, r_goal, r_obs, d_goal, d_total = _terms()
    full, full_parts = combine(r_den, r_goal, r_obs, d_goal, d_total, RuleWeights())
    w = RuleWeights(**{f"use_{off}": False})
    total, parts = combine(r_den, r_goal, r_obs, d_goal, d_total, w)
    np.testing.assert_array_equal(parts[off], 0.0)
    for k in parts:
        if k != off:
            np.testing.assert_array_equal(parts[k], full_parts[k])
    np.testing.assert_allclose(total, full - full_parts[off], atol=1e-15)


def test_combine_density_switch_ignores_a_density_override():
    r_den, r_goal, r_obs, d_goal, d_total = _terms()
    w = RuleWeights(use_density=False, density_weight=5.0)
    total, parts = combine(r_den, r_goal, r_obs, d_goal, d_total, w)
    np.testing.assert_array_equal(parts["density"], 0.0)
    np.testing.assert_allclose(total, parts["goal"] + parts["obstacle"])


def test_combine_overrides_replace_the_adaptive_weights():
    r_den, r_goal, r_obs, d_goal, d_total = _terms()
    w = RuleWeights(density_weight=0.5, goal_weight=3.0, obstacle_weight=0.0)
    total, parts = combine(r_den, r_goal, r_obs, d_goal, d_total, w)
    np.testing.assert_allclose(parts["density"], 0.5 * r_den)
    np.testing.assert_allclose(parts["goal"], 3.0 * r_goal)
    np.testing.assert_array_equal(parts["obstacle"], 0.0)
    np.testing.assert_allclose(total, 0.5 * r_den + 3.0 * r_goal)
    # only one override: the others stay adaptive
    _, one = combine(r_den, r_goal, r_obs, d_goal, d_total, RuleWeights(goal_weight=1.0))
    np.testing.assert_allclose(one["goal"], r_goal)
    np.testing.assert_allclose(one["density"], [1.0, 0.0, 0.8], atol=1e-15)


def test_rule_weights_from_dict_round_trip_and_unknown_keys():
    w = RuleWeights(use_goal=False, obstacle_weight=2.0)
    assert RuleWeights.from_dict(w.to_dict()) == w
    with pytest.raises(ConfigError, match="use_dens"):
        RuleWeights.from_dict({"use_dens": False})
