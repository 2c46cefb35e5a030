"""The teacher with faster arithmetic (``TeacherConfig.precision``: float32 rays, or the fast
rollouts): it chooses what the float64 reference chooses on recorded teacher states, and a
seeded run of it repeats bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from pioneer.control.precision_check import (
    MIN_SAME_SHARE,
    SCORE_TOLERANCE,
    DecisionInput,
    PrecisionReport,
    chosen_index,
    compare_precision,
    record_decision_inputs,
    with_precision,
)
from pioneer.control.rollout import RolloutPrecision, rollout
from pioneer.control.teacher import (
    LookaheadTeacher,
    TeacherConfig,
    TeacherDecision,
    make_teacher,
)
from pioneer.envs.env import NavEnv
from pioneer.envs.episode import Episode, Step
from pioneer.errors import ConfigError
from pioneer_testutils import assert_house_message

SCENARIOS = ("hr-rl", "hl-rr")


@pytest.fixture(scope="module")
def recorded() -> dict[str, list[DecisionInput]]:
    """Every decision input of one seeded reference-teacher episode per scenario (≈ 140
    states each)."""
    return {scenario: record_decision_inputs(scenario, [3]) for scenario in SCENARIOS}


def test_the_fast_rollouts_are_the_default_and_the_reference_stays():
    assert TeacherConfig().precision == "fast"
    assert make_teacher("hr-rl").config.precision == "fast"
    assert make_teacher("hr-rl", precision="float64").config.precision == "float64"


def test_the_precision_is_a_teacher_parameter_that_runs_record():
    """A policy spec sets it, and the made_by of an evaluation row names it (so a folder of
    one precision refuses to resume with the other)."""
    from pioneer.control.registry import build_policy
    from pioneer.eval.harness import PolicySpec, made_by

    spec = PolicySpec.parse("teacher:precision=float32")
    teacher = build_policy(spec.name, "hr-rl", **dict(spec.kwargs))
    assert isinstance(teacher, LookaheadTeacher) and teacher.config.precision == "float32"
    assert made_by(spec, "hr-rl")["params"]["precision"] == "float32"
    assert made_by(PolicySpec.parse("teacher"), "hr-rl")["params"]["precision"] == "fast"
    fast = PolicySpec.parse("teacher:precision=fast")
    assert build_policy(fast.name, "hr-rl", **dict(fast.kwargs)).config.precision == "fast"
    assert made_by(fast, "hr-rl")["params"]["precision"] == "fast"


def test_an_unknown_precision_is_refused_with_the_fix():
    with pytest.raises(ConfigError, match="precision") as err:
        TeacherConfig(precision="float16")  # type: ignore[arg-type]
    assert "float32" in str(err.value)
    scenario_world = NavEnv("hr-rl")
    scenario_world.reset(seed=0)
    with pytest.raises(ConfigError) as err:
        rollout(
            scenario_world.world,
            scenario_world.state,
            np.zeros((1, 2)),
            precision="half",  # type: ignore[arg-type]
        )
    assert_house_message(str(err.value), "precision", "half")


def test_float32_rays_reach_the_rollout_observations(recorded):
    """The setting is wired through: the observations differ in their last bits, not more
    (a beam may flip from hit to miss where it grazes an obstacle: a few entries in 10⁵)."""
    d = recorded["hr-rl"][40]
    teacher = make_teacher("hr-rl")
    ref = rollout(d.world, d.state, teacher.candidates, precision="float64").obs
    f32 = rollout(d.world, d.state, teacher.candidates, precision="float32").obs
    assert ref.dtype == f32.dtype == np.float32
    assert not np.array_equal(ref, f32)
    close = np.isclose(f32, ref, rtol=0.0, atol=1e-3)  # [m, rad]: ranges move by ~1e-6 m
    assert close.mean() > 0.9999


def test_recorded_inputs_are_the_teachers_own(recorded):
    """A recorded input, decided again, gives the command the teacher sent (its previous
    command is the one applied before); ``every`` keeps every k-th input."""
    inputs = recorded["hr-rl"]
    commands: list[np.ndarray] = []
    Episode(NavEnv("hr-rl"), make_teacher("hr-rl"), 3).run(lambda s: commands.append(s.command))
    assert len(inputs) == len(commands)
    assert np.array_equal(inputs[0].prev, np.zeros(2))
    for k in (1, len(inputs) // 2, len(inputs) - 1):
        d = inputs[k]
        assert np.array_equal(d.prev, commands[k - 1])
        again = make_teacher("hr-rl").decide(d.world, d.state, d.prev)
        assert np.array_equal(again.command, commands[k])
    sparse = record_decision_inputs("hr-rl", [3], every=5)
    assert [d.state for d in sparse] == [d.state for d in inputs[::5]]


@pytest.mark.parametrize("precision", ["float32", "fast"])
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_faster_precisions_choose_the_reference_candidate(recorded, scenario, precision):
    """The acceptance of float32 rays, and of the fast rollouts (float32 rays, vectorised
    e^x), on a small recorded set: the same candidate in >= 99 % of the states, and where not,
    a reference-score loss below the stated tolerance."""
    report = compare_precision(make_teacher(scenario), recorded[scenario], precision)
    assert report.n_states == len(recorded[scenario]) >= 100
    assert report.same_share >= MIN_SAME_SHARE, report.summary()
    assert report.max_score_loss < SCORE_TOLERANCE, report.summary()
    assert report.equivalent
    assert report.max_score_change > 0.0  # the two paths did differ


def test_chosen_index_is_the_decision(recorded):
    """``compare_precision`` compares ``decide``'s choice, read from the scores."""
    teacher = with_precision(make_teacher("hr-rl"), "float32")
    for d in recorded["hr-rl"][::25]:
        decision = teacher.decide(d.world, d.state, d.prev)
        assert chosen_index(teacher.scores(d.world, d.state)) == decision.index
    assert chosen_index(np.full(3, -np.inf)) == -1
    assert chosen_index(np.array([-np.inf, 2.0, 2.0])) == 1  # ties: the lowest index


def test_a_report_names_the_loss_of_differing_states():
    report = PrecisionReport("float32", 200, 198, (5, 9), (0.01, 0.002), 0.01, SCORE_TOLERANCE)
    assert report.same_share == pytest.approx(0.99)
    assert report.max_score_loss == 0.01
    assert report.equivalent
    assert "198/200" in report.summary()
    worse = PrecisionReport("float32", 200, 197, (1, 5, 9), (0.0, 0.0, 0.0), 0.0, 0.05)
    assert not worse.equivalent  # 98.5 % the same
    far = PrecisionReport("float32", 1000, 999, (3,), (0.2,), 0.2, 0.05)
    assert not far.equivalent  # a loss beyond the tolerance


def _episode(
    seed: int, precision: RolloutPrecision
) -> tuple[list[np.ndarray], list[TeacherDecision]]:
    teacher = with_precision(make_teacher("hr-rl"), precision)
    commands: list[np.ndarray] = []
    decisions: list[TeacherDecision] = []

    def keep(step: Step) -> None:
        commands.append(step.command)
        assert teacher.last is not None
        decisions.append(teacher.last)

    Episode(NavEnv("hr-rl"), teacher, seed).run(keep)
    return commands, decisions


@pytest.mark.parametrize("precision", ["float32", "fast"])
def test_faster_teachers_are_deterministic(precision):
    """The same seed twice in one process: bit-identical commands and per-term scores."""
    first_cmd, first = _episode(11, precision)
    second_cmd, second = _episode(11, precision)
    assert len(first) == len(second) > 10
    for a, b, ca, cb in zip(first, second, first_cmd, second_cmd, strict=True):
        assert np.array_equal(ca, cb)
        assert a.index == b.index
        assert np.array_equal(a.command, b.command)
        assert a.terms == b.terms  # exact: the same run twice on one machine
        assert a.raw_terms == b.raw_terms
