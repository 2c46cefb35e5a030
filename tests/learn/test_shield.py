"""The uncertainty shield (``pioneer.learn.shield``): when it hands over, what it sends instead,
where its default threshold comes from, its registry entry, and the frames it records."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

from pioneer.baselines.classic import GoalPolicy
from pioneer.control.registry import build_policy, policy_names
from pioneer.control.teacher import LookaheadTeacher, make_teacher
from pioneer.envs.env import NavEnv
from pioneer.envs.policy import Policy
from pioneer.errors import ConfigError
from pioneer.eval.episode import run_episode
from pioneer.learn import (
    MDN,
    MLPStudent,
    ShieldPolicy,
    StudentPolicy,
    make_shield_policy,
    make_student_policy,
    save_student,
    train_student,
)
from pioneer.learn.shield import default_threshold
from pioneer.reward.recipe import default_reward
from pioneer.sim.scenarios import static_study_scenario
from pioneer.sim.world import SimConfig
from pioneer_testutils import assert_house_message

torch.set_num_threads(1)

QUANTILES = {
    "aleatoric": {"0.5": 0.05, "0.9": 0.1, "0.95": 0.2, "0.99": 0.4},
    "epistemic": {"0.5": 0.01, "0.9": 0.03, "0.95": 0.07, "0.99": 0.09},
}
HUGE = 1e9


def _random_data(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    x = (rng.normal(size=(n, 29)) * 2.0).astype(np.float32)
    y = np.stack([np.tanh(x[:, 0]), 0.5 * np.sin(x[:, 1])], axis=1).astype(np.float32)
    return x, y


@pytest.fixture(scope="module")
def ckpt(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small MDN trained briefly on random data, saved with DAgger-style quantiles."""
    x, y = _random_data(np.random.default_rng(7), 300)
    model = MDN(seed=1)
    train_student(model, x, y, epochs=3, seed=3)
    path = tmp_path_factory.mktemp("shield") / "static.safetensors"
    return save_student(model, path, info={"uncertainty_quantiles": QUANTILES})


@pytest.fixture(scope="module")
def reward_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("reward") / "static.npz"
    default_reward("static").save(path)
    return path


def _drive(
    shield: ShieldPolicy,
    steps: int,
    scenario: str = "hr-rl",
    seed: int = 3,
    reference: Policy | None = None,
    thresholds: list[float] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
    """Drive the shield for up to ``steps`` steps (fewer if the episode ends); returns its
    commands, the bare student's and the reference policy's on the same observations, and the
    infos the shield acted on. ``thresholds``: the shield's threshold at each step."""
    bare = StudentPolicy(shield.student.model)
    env = NavEnv(scenario)
    obs, info = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    shield.reset(info, rng)
    bare.reset(info, rng)
    if reference is not None:
        reference.reset(info, rng)
    sent, student, ref, infos = [], [], [], []
    for t in range(steps):
        student.append(bare.act(obs, info))
        if reference is not None:
            ref.append(reference.act(obs, info))
        infos.append(info)
        if thresholds is not None:
            shield.threshold = thresholds[t]
        u = shield.act(obs, info)
        sent.append(u)
        obs, _, term, trunc, info = env.step(u)
        if term or trunc:
            break
    assert bare.uncertainty == shield.uncertainty  # the shield reports its student's
    return np.array(sent), np.array(student), np.array(ref), infos


def _signal(shield: ShieldPolicy) -> np.ndarray:
    unc = np.asarray(shield.uncertainty)
    return {"aleatoric": unc[:, 0], "epistemic": unc[:, 1], "total": unc.sum(axis=1)}[shield.signal]


# ------------------------------------------------------------------------------ when it acts
def test_threshold_zero_hands_every_step_to_the_fallback(ckpt):
    shield = make_shield_policy(ckpt, fallback="goal", threshold=0.0)
    assert isinstance(shield.fallback, GoalPolicy)
    sent, student, goal, _ = _drive(shield, 25, reference=GoalPolicy())
    assert len(sent) >= 10
    assert shield.shielded == [1.0] * len(sent)
    np.testing.assert_array_equal(sent, goal)
    assert not np.allclose(sent, student)


def test_huge_threshold_never_intervenes(ckpt):
    shield = make_shield_policy(ckpt, fallback="goal", threshold=HUGE)
    sent, student, _, _ = _drive(shield, 25)
    assert shield.shielded == [0.0] * len(sent) and len(sent) >= 10
    np.testing.assert_array_equal(sent, student)


@pytest.mark.parametrize("signal", ["epistemic", "aleatoric", "total"])
def test_the_shield_intervenes_exactly_above_the_threshold(ckpt, signal):
    # The threshold: the median of the signal along the bare student's own run.
    probe = make_shield_policy(ckpt, fallback="goal", threshold=HUGE, signal=signal)
    _drive(probe, 30)
    thr = float(np.median(_signal(probe)))

    shield = make_shield_policy(ckpt, fallback="goal", threshold=thr, signal=signal, hold=0)
    sent, student, goal, _ = _drive(shield, 30, reference=GoalPolicy())
    over = _signal(shield) > thr
    assert 0 < over.sum() < len(over)  # both cases occur
    assert shield.shielded == [float(o) for o in over]
    np.testing.assert_array_equal(sent[over], goal[over])
    np.testing.assert_array_equal(sent[~over], student[~over])


@pytest.mark.parametrize("hold", [1, 3])
def test_the_fallback_holds_for_hold_steps_after_each_unsure_one(ckpt, hold):
    probe = make_shield_policy(ckpt, fallback="goal", threshold=HUGE)
    _drive(probe, 40)
    thr = float(np.quantile(_signal(probe), 0.8))
    shield = make_shield_policy(ckpt, fallback="goal", threshold=thr, hold=hold)
    sent, student, goal, _ = _drive(shield, 40, reference=GoalPolicy())
    over = _signal(shield) > thr
    # brute force: step t is the fallback's if any of the steps t − hold … t was unsure
    want = [float(over[max(0, t - hold) : t + 1].any()) for t in range(len(over))]
    assert 0 < sum(want) < len(want) and sum(want) > over.sum()  # the hold shows
    assert shield.shielded == want
    mine = np.asarray(want, dtype=bool)
    np.testing.assert_array_equal(sent[mine], goal[mine])
    np.testing.assert_array_equal(sent[~mine], student[~mine])


def test_slow_mode_scales_the_speed_and_keeps_the_turn_rate(ckpt):
    shield = make_shield_policy(ckpt, mode="slow", slow_factor=0.25, threshold=0.0)
    assert shield.fallback is None  # no fallback is built for "slow"
    sent, student, _, _ = _drive(shield, 20)
    assert shield.shielded == [1.0] * len(sent) and len(sent) >= 10
    np.testing.assert_allclose(sent[:, 0], 0.25 * student[:, 0], rtol=1e-12)
    np.testing.assert_array_equal(sent[:, 1], student[:, 1])
    assert np.any(np.abs(student[:, 0]) > 1e-3)  # the scaling is visible

    calm = make_shield_policy(ckpt, mode="slow", threshold=HUGE)
    sent, student, _, _ = _drive(calm, 10)
    np.testing.assert_array_equal(sent, student)


def test_reset_starts_a_new_episode(ckpt):
    shield = make_shield_policy(ckpt, fallback="goal", threshold=0.0)
    _drive(shield, 5)
    assert len(shield.shielded) == len(shield.uncertainty) == 5
    shield.reset({}, np.random.default_rng(0))
    assert shield.shielded == [] and shield.uncertainty == []


@pytest.mark.parametrize("fallback", ["goal", "dwa", "sfm"])
def test_rule_based_fallbacks_take_over(ckpt, fallback):
    """The module docstring promises ``fallback="goal" | "dwa" | "sfm"``."""
    shield = make_shield_policy(ckpt, scenario="static", fallback=fallback, threshold=0.0)
    reference = build_policy(fallback, "static")
    sent, _, ref, _ = _drive(shield, 5, scenario="static", reference=reference)
    assert shield.shielded == [1.0] * len(sent) == [1.0] * 5
    np.testing.assert_allclose(sent, ref, rtol=1e-12, atol=1e-12)


# ------------------------------------------------------------------------------ teacher fallback
def test_the_teacher_takes_over_from_the_applied_command(ckpt, reward_file):
    """On a handover the teacher smooths from ``state.command`` (the command last applied,
    here the student's as the robot executed it), not from its own previous decision."""
    shield = make_shield_policy(
        ckpt,
        scenario="static",
        fallback="teacher",
        reward=str(reward_file),
        threshold=0.0,
        hold=0,
    )
    assert isinstance(shield.fallback, LookaheadTeacher) and shield.fallback.density is not None
    schedule = [0.0 if t % 2 else HUGE for t in range(12)]  # hand over every other step
    sent, student, _, infos = _drive(shield, 12, scenario="static", thresholds=schedule)
    assert len(sent) == 12
    assert shield.shielded == [float(t % 2) for t in range(12)]
    teacher = make_teacher("static", reward=str(reward_file))
    for t, info in enumerate(infos):
        if t % 2:
            state = info["state"]
            expected = teacher.decide(info["world"], state, prev=state.command[0]).command
            np.testing.assert_array_equal(sent[t], expected)
        else:
            np.testing.assert_array_equal(sent[t], student[t])


def test_a_teacher_shielded_episode_records_shielded_frames(ckpt, reward_file):
    scenario = dataclasses.replace(
        static_study_scenario(sim=SimConfig(time_limit=1.0)), name="static-short"
    )
    shield = make_shield_policy(
        ckpt, scenario="static", fallback="teacher", reward=str(reward_file), threshold=0.0
    )
    rec, _ = run_episode(scenario, shield, seed=5)
    assert rec.policy == "student-shield" and rec.steps == 10
    assert rec.frames is not None
    assert set(rec.frames) == {"gap", "clearance", "aleatoric", "epistemic", "shielded"}
    assert all(len(v) == rec.steps for v in rec.frames.values())
    assert rec.frames["shielded"] == [1.0] * rec.steps
    assert rec.to_dict()["frames"]["shielded"] == [1.0] * rec.steps

    calm = make_shield_policy(ckpt, scenario="static", fallback="goal", threshold=HUGE)
    rec, _ = run_episode(scenario, calm, seed=5)
    assert rec.frames is not None and rec.frames["shielded"] == [0.0] * rec.steps


# ------------------------------------------------------------------------------ threshold
def test_default_threshold_is_read_from_the_checkpoint(ckpt):
    assert default_threshold(ckpt, "epistemic", 0.95) == 0.07
    assert default_threshold(ckpt, "aleatoric", 0.9) == 0.1
    assert default_threshold(ckpt, "total", 0.99) == pytest.approx(0.4 + 0.09)
    # the default: total, q = 0.95 (aleatoric 0.2 + epistemic 0.07), held 10 steps
    default = make_shield_policy(ckpt, fallback="goal")
    assert default.threshold == pytest.approx(0.27) and default.hold == 10
    shield = make_shield_policy(ckpt, fallback="goal", signal="total", quantile=0.5)
    assert shield.threshold == pytest.approx(0.06)
    assert make_shield_policy(ckpt, fallback="goal", threshold=0.5).threshold == 0.5


def test_a_missing_default_threshold_is_a_config_error(ckpt, tmp_path):
    bare = save_student(MDN(seed=0), tmp_path / "bare.safetensors")  # no quantiles stored
    with pytest.raises(ConfigError) as err:
        make_shield_policy(bare, fallback="goal")
    assert_house_message(str(err.value), "uncertainty_quantiles", "threshold=")
    with pytest.raises(ConfigError) as err:
        default_threshold(ckpt, "epistemic", 0.42)  # not a stored quantile
    assert_house_message(str(err.value), "0.42")
    assert make_shield_policy(bare, fallback="goal", threshold=0.1).threshold == 0.1


# ------------------------------------------------------------------------------ bad settings
@pytest.mark.parametrize(
    ("changes", "needle"),
    [
        ({"signal": "variance"}, "signal"),
        ({"mode": "stop"}, "mode"),
        ({"threshold": -0.1}, "threshold"),
        ({"threshold": math.nan}, "threshold"),
        ({"threshold": math.inf}, "threshold"),
        ({"slow_factor": 1.5}, "slow_factor"),
        ({"slow_factor": -0.1}, "slow_factor"),
        ({"fallback": None}, "fallback"),
        ({"hold": -1}, "hold"),
    ],
)
def test_bad_settings_are_refused(ckpt, changes, needle):
    kwargs: dict[str, Any] = {
        "student": make_student_policy(ckpt),
        "fallback": GoalPolicy(),
        "threshold": 0.1,
        **changes,
    }
    with pytest.raises(ConfigError) as err:
        ShieldPolicy(**kwargs)
    assert_house_message(str(err.value), needle)


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"signal": "variance", "threshold": 0.1}, "signal"),
        ({"mode": "stop", "threshold": 0.1}, "mode"),
        ({"threshold": -1.0}, "threshold"),
    ],
)
def test_the_factory_refuses_bad_settings(ckpt, kwargs, needle):
    with pytest.raises(ConfigError) as err:
        make_shield_policy(ckpt, fallback="goal", **kwargs)
    assert_house_message(str(err.value), needle)


def test_an_mlp_student_cannot_be_shielded(tmp_path):
    path = save_student(MLPStudent(seed=0), tmp_path / "mlp.safetensors")
    with pytest.raises(ConfigError) as err:
        make_shield_policy(path, fallback="goal", threshold=0.1)
    assert_house_message(str(err.value), "mdn")


# ------------------------------------------------------------------------------ registry
def test_registered_as_student_shield(ckpt, reward_file):
    assert "student-shield" in policy_names()
    pattern = str(ckpt.parent / "{scenario}.safetensors")  # the fixture saved static.safetensors
    pol = build_policy("student-shield", "static", checkpoint=pattern, fallback="goal")
    assert isinstance(pol, ShieldPolicy) and pol.name == "student-shield"
    assert isinstance(pol.fallback, GoalPolicy)
    total = QUANTILES["aleatoric"]["0.95"] + QUANTILES["epistemic"]["0.95"]
    assert pol.threshold == pytest.approx(total)  # read from the filled-in path
    assert (pol.signal, pol.mode) == ("total", "handover")

    pol = build_policy(
        "student-shield",
        "static",
        checkpoint=pattern,
        reward=str(reward_file),
        threshold=0.2,
        signal="total",
    )
    assert isinstance(pol, ShieldPolicy)
    assert isinstance(pol.fallback, LookaheadTeacher) and pol.fallback.density is not None
    assert (pol.threshold, pol.signal) == (0.2, "total")
    assert make_shield_policy(ckpt, fallback="goal", threshold=0.2, name="mine").name == "mine"
