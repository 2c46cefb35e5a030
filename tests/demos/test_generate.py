"""Scripted demonstration generation: counts, the 1.0 s negative window, determinism."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from pioneer.demos.generate import NEGATIVE_WINDOW, generate, negative_frames, record_episode
from pioneer.demos.scripted import CarelessDriver, CorridorDriver
from pioneer.envs.env import NavEnv
from pioneer.errors import ConfigError
from pioneer.reward.dataset import Dataset
from pioneer.seeds import TRAINING_BASE
from pioneer.sim.scenarios import get_scenario

COLUMNS = ("episode", "step", "time", "obs", "action", "gamma", "pose", "scenario", "seed")


@pytest.fixture(scope="module")
def static_demos() -> Dataset:
    return generate("static", 30, 20, progress=False)


@pytest.fixture(scope="module")
def elevator_demos() -> Dataset:
    return generate("hr-rl", 40, 20, progress=False)


def _negative_policy(scenario: str) -> Any:
    return CorridorDriver(through_middle=True) if scenario == "static" else CarelessDriver()


def _replay(scenario: str, seed: int) -> tuple[list[dict[str, Any]], str, float]:
    """Run the negative demonstrator's episode again; return frames, event, end time [s]."""
    env = NavEnv(get_scenario(scenario))
    policy = _negative_policy(scenario)
    obs, info = env.reset(seed=seed)
    policy.reset(info, np.random.default_rng(seed))
    frames = []
    while True:
        u = np.asarray(policy.act(obs, info), dtype=np.float64)
        frames.append({"time": info["time"], "obs": obs, "action": u})
        obs, _, _, _, info = env.step(u)
        if info["event"] is not None:
            return frames, str(info["event"]), float(info["time"])


@pytest.mark.parametrize(
    ("fixture", "scenario", "n_pos", "n_neg"),
    [("static_demos", "static", 30, 20), ("elevator_demos", "hr-rl", 40, 20)],
)
def test_generate_returns_exact_counts(request, fixture, scenario, n_pos, n_neg):
    d: Dataset = request.getfixturevalue(fixture)
    assert (d.n_positive, d.n_negative, len(d)) == (n_pos, n_neg, n_pos + n_neg)
    assert set(np.unique(d.gamma).tolist()) == {-1.0, 1.0}
    assert d.scenarios == (scenario,)
    np.testing.assert_array_equal(d.scenario, 0)
    assert d.meta["source"] == ("scripted" if scenario == "static" else "rules-only teacher")
    assert d.meta["negative_window_s"] == NEGATIVE_WINDOW
    # positives come first, from training seeds 0, 1, …; negatives from 100000, …
    k = d.seed - TRAINING_BASE
    assert np.all(k >= 0)
    assert np.all(k[d.gamma > 0] < 100_000) and np.all(k[d.gamma < 0] >= 100_000)
    for e in np.unique(d.episode):
        m = d.episode == e
        assert np.unique(d.gamma[m]).size == 1 and np.unique(d.seed[m]).size == 1
        np.testing.assert_array_equal(np.diff(d.step[m]), 1)
        np.testing.assert_allclose(np.diff(d.time[m]), get_scenario(scenario).sim.dt, atol=1e-9)


@pytest.mark.parametrize(
    ("fixture", "scenario"), [("static_demos", "static"), ("elevator_demos", "hr-rl")]
)
def test_negatives_are_the_last_second_before_a_collision(request, fixture, scenario):
    d: Dataset = request.getfixturevalue(fixture)
    dt = get_scenario(scenario).sim.dt
    neg_eps = np.unique(d.episode[d.gamma < 0])
    assert neg_eps.size >= 1
    for e in neg_eps:
        m = d.episode == e
        seed = int(d.seed[m][0])
        frames, event, t_collision = _replay(scenario, seed)
        assert event == "collision"
        times = d.time[m]
        # ends at the collision: the last kept frame is the last action before it
        assert times.max() == pytest.approx(t_collision - dt, abs=1e-9)
        # spans no more than the window
        assert t_collision - times.min() <= NEGATIVE_WINDOW + 1e-9
        # and holds *every* frame of the window (nothing dropped)
        window = [f for f in frames if f["time"] >= t_collision - NEGATIVE_WINDOW - 1e-9]
        assert len(window) == int(m.sum())
        np.testing.assert_array_equal(d.obs[m], np.stack([f["obs"] for f in window]))
        np.testing.assert_array_equal(d.action[m], np.stack([f["action"] for f in window]))


def test_truncated_last_negative_episode_stays_inside_the_window():
    d = generate("static", 5, 15, progress=False)
    assert (d.n_positive, d.n_negative) == (5, 15)
    dt = get_scenario("static").sim.dt
    for e in np.unique(d.episode[d.gamma < 0]):
        m = d.episode == e
        _, event, t_collision = _replay("static", int(d.seed[m][0]))
        assert event == "collision"
        assert np.all(d.time[m] >= t_collision - NEGATIVE_WINDOW - 1e-9)
        assert np.all(d.time[m] <= t_collision - dt + 1e-9)


def test_positive_episodes_were_successes(static_demos):
    env = NavEnv(get_scenario("static"))
    d = static_demos
    for e in np.unique(d.episode[d.gamma > 0]):
        m = d.episode == e
        seed = int(d.seed[m][0])
        k = seed - TRAINING_BASE  # the episode index: 2 of 3 on the right
        frames, event, _ = record_episode(env, CorridorDriver(side=1.0 if k % 3 else -1.0), seed)
        assert event == "success"
        k = int(m.sum())
        assert k <= len(frames)
        np.testing.assert_array_equal(d.pose[m], np.stack([f["pose"] for f in frames[:k]]))


def test_generate_is_deterministic_per_seed(static_demos):
    again = generate("static", 30, 20, progress=False)
    for k in COLUMNS:
        np.testing.assert_array_equal(getattr(again, k), getattr(static_demos, k), err_msg=k)
    other = generate("static", 30, 20, seed=5, progress=False)
    assert not np.array_equal(other.pose, static_demos.pose)
    assert other.meta["generator_seed"] == 5


def test_generate_elevator_is_deterministic(elevator_demos):
    again = generate("hr-rl", 40, 20, progress=False)
    for k in COLUMNS:
        np.testing.assert_array_equal(getattr(again, k), getattr(elevator_demos, k), err_msg=k)


def test_only_one_sign_may_be_requested():
    d = generate("static", 0, 7, progress=False)
    assert (d.n_positive, d.n_negative) == (0, 7)


@pytest.mark.parametrize(("n_pos", "n_neg"), [(-1, 5), (5, -1), (0, 0)])
def test_bad_counts_are_refused(n_pos, n_neg):
    with pytest.raises(ConfigError) as exc:
        generate("static", n_pos, n_neg, progress=False)
    msg = str(exc.value)
    assert "sample counts" in msg and "expected" in msg and "fix" in msg


def _frames(times: np.ndarray) -> list[dict[str, Any]]:
    return [{"time": float(t), "step": k} for k, t in enumerate(times)]


def test_negative_frames_keeps_exactly_one_second():
    dt = 0.1
    frames = _frames(np.arange(31) * dt)  # 0.0 … 3.0 s, collision at 3.1 s
    kept = negative_frames(frames, dt)
    assert [f["step"] for f in kept] == list(range(21, 31))  # 2.1 … 3.0 s
    short = _frames(np.arange(4) * dt)  # collision after 0.4 s: all frames
    assert negative_frames(short, dt) == short
    wider = negative_frames(frames, dt, window=2.0)
    assert len(wider) == 20
