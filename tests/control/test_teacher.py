"""The lookahead teacher (paper §IV-A.2): reaches goals, never picks a predicted collision,
stops when boxed in, smooths its command, reports its per-term scores, and its ablations run."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pioneer.control.registry import build_policy, policy_names
from pioneer.control.rollout import rollout
from pioneer.control.teacher import (
    Assumptions,
    LookaheadTeacher,
    Patience,
    SoftMargins,
    TeacherConfig,
    make_teacher,
)
from pioneer.envs.env import NavEnv
from pioneer.errors import ConfigError
from pioneer.eval.episode import run_episode
from pioneer.reward.features import feature_map
from pioneer.reward.recipe import default_reward
from pioneer.reward.rules import RuleWeights, combine, goal_term, obstacle_term
from pioneer.sim.humans import ARRIVED, SocialForceConfig
from pioneer.sim.scenarios import HumanSpec, Region, ScenarioConfig, get_scenario
from pioneer.sim.world import SimConfig, advance
from pioneer_testutils import make_state, open_world, room_world

ABLATIONS = ("teacher", "teacher-no-density", "teacher-no-goal", "teacher-no-obstacle")


def _room(humans: tuple[HumanSpec, ...] = ()) -> ScenarioConfig:
    """A closed 4 × 6 m room; start near the bottom wall, goal near the top wall."""
    return ScenarioConfig(
        name="room",
        walls=((-2, -3, 2, -3), (2, -3, 2, 3), (2, 3, -2, 3), (-2, 3, -2, -3)),
        bounds=(-2.0, 2.0, -3.0, 3.0),
        robot_start=Region(x=(-0.3, 0.3), y=(-2.4, -2.2)),
        robot_goal=Region(x=(-0.4, 0.4), y=(2.0, 2.3)),
        robot_heading=(math.pi / 2 - 0.3, math.pi / 2 + 0.3),
        humans=humans,
    )


def _corner_human() -> HumanSpec:
    """A person standing still in the far corner, well away from the straight route."""
    spot = Region(x=(1.3, 1.3), y=(2.3, 2.3))
    return HumanSpec(
        role="static", start=spot, goal=spot, radius=0.4, v_pref_choices=(0.0,), static=True
    )


NO_MARGINS = TeacherConfig(margins=SoftMargins(human=0.0, wall=0.0))  # the paper's teacher


def _rollout_of(teacher: LookaheadTeacher, world, state):
    cfg = teacher.config
    return rollout(world, state, teacher.candidates, cfg.horizon, cfg.dt, cfg.human_model)


# --------------------------------------------------------------------------------------------
# 1. reaches the goal in an empty room


@pytest.mark.parametrize("humans", [(), (_corner_human(),)], ids=["empty", "corner-human"])
@pytest.mark.parametrize(
    ("density", "seed"),
    [(False, 0), (False, 7), (True, 0)],
    ids=["no-density-0", "no-density-7", "density-0"],
)
def test_teacher_drives_to_the_goal_in_a_room(humans, density, seed):
    cfg = _room(humans)
    teacher = make_teacher("static") if density else LookaheadTeacher(None)
    assert (teacher.density is not None) is density
    rec, _ = run_episode(cfg, teacher, seed)
    assert rec.event == "success"
    assert rec.scenario == "room"
    assert rec.time_s < cfg.sim.time_limit
    # an efficient route: not much longer than the straight line from start to goal
    env = NavEnv(cfg)
    _, info = env.reset(seed=seed)
    straight = float(np.linalg.norm(info["goal"] - info["robot_pose"][:2]))
    assert straight - cfg.sim.goal_tolerance <= rec.path_length_m <= 1.25 * straight
    if humans:
        assert rec.min_gap_m > 0.5
    else:
        assert math.isinf(rec.min_gap_m)


# --------------------------------------------------------------------------------------------
# 2. feasibility: never a predicted collision; stop when boxed in; safety margin


def _unsafe_states():
    r = room_world(3.0, 3.0)
    # People who step aside for the robot: with the paper world's weak reaction no held
    # command escapes a person walking straight at the robot within the 3 s horizon.
    polite = room_world(3.0, 3.0, SimConfig(social_force=SocialForceConfig.preset("compact")))
    return {
        # a person standing 0.1 m (clearance) ahead: almost every candidate runs into them
        "human-ahead": (
            r,
            make_state((0.0, 0.0, 0.0), goal=(2.5, 0.0), humans=[{"pos": (1.0, 0.0)}]),
        ),
        # a person walking straight at the robot
        "human-approaching": (
            polite,
            make_state(
                (0.0, 0.0, 0.0),
                goal=(2.5, 0.0),
                humans=[{"pos": (1.8, 0.0), "goal": (-2.5, 0.0), "vel": (-0.4, 0.0)}],
            ),
        ),
        # a wall 0.2 m (clearance) ahead, goal just in front of it
        "wall-ahead": (r, make_state((2.5, 0.0, 0.0), goal=(2.6, 0.5))),
        # a corner: walls ahead and to the left
        "corner": (r, make_state((2.45, 2.45, math.pi / 4), goal=(0.0, 0.0))),
    }


@pytest.mark.parametrize("name", list(_unsafe_states()))
@pytest.mark.parametrize("human_model", ["privileged", "constant_velocity"])
def test_teacher_never_selects_a_candidate_predicted_to_collide(name, human_model):
    world, state = _unsafe_states()[name]
    teacher = LookaheadTeacher(None, config=TeacherConfig(human_model=human_model))
    d = teacher.decide(world, state)
    ro = _rollout_of(teacher, world, state)
    assert ro.collided.sum() >= 30, "the test state should make many candidates collide"
    assert d.n_feasible == int((~ro.collided).sum()) > 0
    assert 0 <= d.index < 120
    assert not ro.collided[d.index]
    np.testing.assert_array_equal(d.best, teacher.candidates[d.index])


def test_the_feasibility_mask_overrides_the_best_score():
    """In the human-ahead state the best score of rollouts driven on through their collisions
    belongs to a colliding candidate (the teacher's rollout stops a colliding candidate, which
    it then masks)."""
    world, state = _unsafe_states()["human-ahead"]
    teacher = LookaheadTeacher(None)
    d = teacher.decide(world, state)
    tr = advance(world, state.repeat(120), teacher.candidates, 0.3, 10)  # no stop
    collided = tr.final.collided
    np.testing.assert_array_equal(collided, _rollout_of(teacher, world, state).collided)
    d_total = float(np.linalg.norm(state.goal[0] - state.start[0]))
    d_goal = np.linalg.norm(tr.final.goal - tr.poses[:, -1, :2], axis=1)
    total, _ = combine(
        np.zeros(120),
        goal_term(d_goal, d_total),
        obstacle_term(tr.observations(world)),
        d_goal,
        d_total,
        RuleWeights(),
    )
    assert collided[int(np.argmax(total))]
    assert d.terms["total"] == pytest.approx(np.max(np.where(collided, -np.inf, total)))
    assert d.terms["total"] < np.max(total)


def _boxed_states():
    hs = [{"pos": p, "status": ARRIVED} for p in [(0.95, 0), (-0.95, 0), (0, 0.95), (0, -0.95)]]
    return {
        "walls": (room_world(0.36, 0.36), make_state((0.0, 0.0, 0.7), goal=(2.0, 0.0))),
        "humans": (open_world(), make_state((0.0, 0.0, 1.0), goal=(3.0, 0.0), humans=hs)),
    }


@pytest.mark.parametrize("name", list(_boxed_states()))
def test_teacher_stops_at_once_when_every_candidate_collides(name):
    world, state = _boxed_states()[name]
    teacher = LookaheadTeacher(None)
    assert _rollout_of(teacher, world, state).collided.all()
    # even while moving fast, the stop is immediate (no smoothing toward the old command)
    free_world, free_state = open_world(), make_state((0.0, 0.0, 0.0), goal=(5.0, 0.0))
    moving = teacher.decide(free_world, free_state)
    assert moving.command[0] > 0.0
    d = teacher.decide(world, state)
    np.testing.assert_array_equal(d.command, [0.0, 0.0])
    np.testing.assert_array_equal(d.best, [0.0, 0.0])
    assert d.index == -1
    assert d.n_feasible == 0
    # after a stop the smoothing restarts from zero
    again = teacher.decide(free_world, free_state)
    np.testing.assert_array_equal(again.command, 0.5 * again.best)


def _rear_ended():
    """A dead-end corridor 0.72 m wide: the robot faces the end wall 0.9 m ahead, a person
    walks up behind it at 1 m/s toward a goal past the wall. Every candidate reaches the wall
    or is caught, and standing still is run into."""
    world = room_world(3.0, 0.36)
    walls = np.array(
        [(-3, -0.36, 0.9, -0.36), (0.9, -0.36, 0.9, 0.36), (0.9, 0.36, -3, 0.36)], dtype=float
    )
    world = dataclasses.replace(world, walls=walls)
    human = {"pos": (-1.6, 0.0), "goal": (3.0, 0.0), "vel": (1.0, 0.0), "radius": 0.3,
             "vpref": 1.0}  # fmt: skip
    return world, make_state((0.0, 0.0, 0.0), goal=(0.6, 0.0), humans=[human])


def _first_collision(world, state, command, cfg):
    """Brute force: roll one command alone; its 1-based first collision step (L + 1: none)."""
    n_steps = math.floor(cfg.horizon / cfg.dt + 1e-9)
    s = state
    for k in range(1, n_steps + 1):
        s = advance(world, s, np.asarray(command, dtype=float)[None], cfg.dt, 1).final
        if s.collided[0]:
            return k
    return n_steps + 1


def test_evade_drives_the_candidate_that_collides_latest_when_standing_is_run_into():
    world, state = _rear_ended()
    evade = LookaheadTeacher(None, config=TeacherConfig(fallback="evade"))
    stop = LookaheadTeacher(None, config=TeacherConfig(fallback="stop"))
    cfg = evade.config
    assert _rollout_of(evade, world, state).collided.all()
    standing = _first_collision(world, state, (0.0, 0.0), cfg)
    assert standing <= 10  # the person walks into the robot if it stops
    steps = np.array([_first_collision(world, state, u, cfg) for u in evade.candidates])
    np.testing.assert_array_equal(_rollout_of(evade, world, state).collision_step, steps)
    assert steps.max() > standing
    d = evade.decide(world, state)
    assert d.index == -1 and d.n_feasible == 0
    chosen = int(np.flatnonzero((evade.candidates == d.command).all(axis=1))[0])
    assert steps[chosen] == steps.max()
    np.testing.assert_array_equal(d.best, d.command)  # sent unsmoothed
    np.testing.assert_array_equal(stop.decide(world, state).command, [0.0, 0.0])


def test_fallback_must_be_stop_or_evade():
    with pytest.raises(ConfigError, match="fallback"):
        TeacherConfig(fallback="run")  # type: ignore[arg-type]


@pytest.mark.parametrize("margin", [0.2, 0.3, 0.5])
def test_safety_margin_bounds_the_predicted_clearance_of_the_choice(margin):
    world = room_world(3.0, 3.0)
    # the person stands just beside the straight route to the goal
    state = make_state(
        (0.0, 0.0, 0.0), goal=(2.5, 0.0), humans=[{"pos": (1.6, 0.45), "status": ARRIVED}]
    )
    plain = LookaheadTeacher(None)
    d0 = plain.decide(world, state)
    ro = _rollout_of(plain, world, state)
    assert ro.min_gap[d0.index] < margin, "without a margin the teacher cuts close"
    safe = LookaheadTeacher(None, config=TeacherConfig(safety_margin=margin))
    d = safe.decide(world, state)
    assert d.index >= 0
    assert ro.min_gap[d.index] >= margin
    assert not ro.collided[d.index]
    expected = int((~ro.collided & (ro.min_gap >= margin)).sum())
    assert d.n_feasible == expected < d0.n_feasible


def _beside_the_route():
    """A person standing just beside the straight route to the goal (the plain teacher passes
    closer than 0.2 m)."""
    world = room_world(3.0, 3.0)
    state = make_state(
        (0.0, 0.0, 0.0), goal=(2.5, 0.0), humans=[{"pos": (1.6, 0.45), "status": ARRIVED}]
    )
    return world, state


@pytest.mark.parametrize("margin", [0.2, 0.3])
def test_a_soft_margin_is_kept_when_some_candidate_keeps_it(margin):
    world, state = _beside_the_route()
    plain = LookaheadTeacher(None, config=NO_MARGINS)
    d0 = plain.decide(world, state)
    ro = _rollout_of(plain, world, state)
    assert ro.min_gap[d0.index] < margin
    soft = LookaheadTeacher(None, config=TeacherConfig(margins=SoftMargins(human=margin)))
    d = soft.decide(world, state)
    assert ro.min_gap[d.index] >= margin and not ro.collided[d.index]
    # the best-scoring candidate among those that keep the margin (brute force)
    keep = ~ro.collided & (ro.min_gap >= margin)
    scores = plain.scores(world, state)
    assert d.index == int(np.argmax(np.where(keep, scores, -np.inf)))
    # soft: every collision-free candidate still counts as feasible
    assert d.n_feasible == d0.n_feasible


def test_a_soft_margin_no_candidate_keeps_falls_back_to_the_collision_free_choice():
    world, state = _beside_the_route()
    plain = LookaheadTeacher(None, config=NO_MARGINS).decide(world, state)
    huge = LookaheadTeacher(None, config=TeacherConfig(margins=SoftMargins(human=5.0, wall=5.0)))
    d = huge.decide(world, state)
    assert d.index == plain.index >= 0  # unlike the hard margin, it never leaves it stopped
    np.testing.assert_array_equal(d.command, plain.command)


def test_a_soft_wall_margin_keeps_the_choice_off_the_walls():
    world = room_world(3.0, 3.0)
    # heading along a wall, 0.15 m off it (surface): the plain teacher may hug it
    state = make_state((0.0, 2.55, 0.0), goal=(2.5, 2.55))
    plain = LookaheadTeacher(None, config=NO_MARGINS)
    ro = _rollout_of(plain, world, state)
    soft = LookaheadTeacher(None, config=TeacherConfig(margins=SoftMargins(wall=0.1)))
    d = soft.decide(world, state)
    keep = ~ro.collided & (ro.min_wall_gap >= 0.1)
    assert keep.any()
    assert ro.min_wall_gap[d.index] >= 0.1
    assert d.index == int(np.argmax(np.where(keep, plain.scores(world, state), -np.inf)))


def test_margin_tiers_keep_the_largest_fraction_of_the_margins_some_candidate_keeps():
    world, state = _beside_the_route()
    plain = LookaheadTeacher(None, config=NO_MARGINS)
    ro = _rollout_of(plain, world, state)
    best_gap = float(ro.min_gap[~ro.collided].max())
    margin = 1.5 * best_gap  # no candidate keeps it; some keep its 3/4 and 1/2
    one = LookaheadTeacher(None, config=TeacherConfig(margins=SoftMargins(human=margin, tiers=1)))
    assert one.decide(world, state).index == plain.decide(world, state).index  # all feasible
    tiered = LookaheadTeacher(
        None, config=TeacherConfig(margins=SoftMargins(human=margin, tiers=4))
    )
    assert tiered.config.margins.factors() == (1.0, 0.75, 0.5, 0.25)
    d = tiered.decide(world, state)
    keep = ~ro.collided & (ro.min_gap >= 0.5 * margin)  # 3/4 · 1.5 > 1: kept by none
    assert keep.any() and not (~ro.collided & (ro.min_gap >= 0.75 * margin)).any()
    assert d.index == int(np.argmax(np.where(keep, plain.scores(world, state), -np.inf)))


def test_make_teacher_passes_its_soft_margins():
    t = make_teacher("hr-rl", density=False, human_margin=0.1, wall_margin=0.05)
    assert t.config.margins == SoftMargins(human=0.1, wall=0.05)
    with pytest.raises(ConfigError, match="human"):
        SoftMargins(human=-0.1)


def test_assumptions_the_world_already_holds_change_no_decision():
    # the paper world's people are 0.6 m and all react with A_r = 0.5: assuming exactly that
    # is the ordinary teacher, command for command
    world = get_scenario("hr-rl").sim.social_force
    assert world.a_robot == 0.5
    plain = make_teacher("hr-rl", density=False)
    assuming = make_teacher("hr-rl", density=False, assume_radius=0.6, assume_a_robot=0.5)
    assert assuming.config.assume.active
    a, _ = run_episode("hr-rl", plain, 4)
    b, _ = run_episode("hr-rl", assuming, 4)
    assert a.event == b.event and a.steps == b.steps and a.path_length_m == b.path_length_m


def _driven(seed: int, steps: int, command: list[float]):
    """``(world, state)`` of HR-RL episode ``seed`` after ``steps`` steps of ``command``."""
    env = NavEnv("hr-rl")
    _, info = env.reset(seed=seed)
    for _ in range(steps):
        _, _, _, _, info = env.step(command)
    return info["world"], info["state"]


def test_assumptions_decide_as_the_teacher_of_the_assumed_world():
    # oracle: assuming (r >= 0.75 m, everyone reacting with A_r = 1.5) decides exactly as the
    # plain teacher does in a world and state that are so
    world, state = _driven(2, 25, [0.3, 0.0])
    state = dataclasses.replace(state, h_reacts=np.zeros_like(state.h_reacts))  # nobody reacts
    sim = world.sim
    force = dataclasses.replace(sim.social_force, a_robot=1.5)
    assumed_world = type(world)(
        world.walls, world.bounds, dataclasses.replace(sim, social_force=force)
    )
    assumed_state = dataclasses.replace(
        state, h_radius=np.maximum(state.h_radius, 0.75), h_reacts=np.ones_like(state.h_reacts)
    )
    assuming = make_teacher("hr-rl", density=False, assume_radius=0.75, assume_a_robot=1.5)
    plain = make_teacher("hr-rl", density=False)
    got = assuming.decide(world, state)
    want = plain.decide(assumed_world, assumed_state)
    np.testing.assert_array_equal(got.command, want.command)
    np.testing.assert_array_equal(
        assuming.scores(world, state), plain.scores(assumed_world, assumed_state)
    )
    # and they are assumptions, not what the teacher sees: the state it was given is unchanged
    assert not state.h_reacts.any() and state.h_radius.max() < 0.75
    assert not np.array_equal(plain.scores(world, state), assuming.scores(world, state))


def test_assumptions_are_checked():
    with pytest.raises(ConfigError, match="human_radius"):
        Assumptions(human_radius=-0.1)
    with pytest.raises(ConfigError, match="a_robot"):
        Assumptions(a_robot=-1.0)
    assert not Assumptions().active and TeacherConfig().assume == Assumptions()


# --------------------------------------------------------------------------------------------
# 3. smoothing


def _teacher_states(n: int, seed: int = 3):
    """n consecutive states of an HR-RL episode driven by a plain go-ahead command."""
    env = NavEnv("hr-rl")
    _, info = env.reset(seed=seed)
    out = [(info["world"], info["state"])]
    for _ in range(n - 1):
        _, _, term, trunc, info = env.step([0.3, 0.05])
        assert not (term or trunc)
        out.append((info["world"], info["state"]))
    return out


def test_smoothing_is_half_best_plus_half_previous():
    teacher = LookaheadTeacher(None)
    prev = np.zeros(2)
    changed = 0
    for world, state in _teacher_states(8):
        d = teacher.decide(world, state)
        assert d.index >= 0
        np.testing.assert_array_equal(d.command, 0.5 * d.best + 0.5 * prev)
        changed += int(not np.array_equal(d.command, d.best))
        prev = d.command
    assert changed >= 1  # the smoothed command really lags behind u*


def test_reset_forgets_the_previous_command():
    teacher = LookaheadTeacher(None)
    (world, state), *_ = _teacher_states(1)
    first = teacher.decide(world, state)
    np.testing.assert_array_equal(first.command, 0.5 * first.best)
    teacher.decide(world, state)
    teacher.reset({}, np.random.default_rng(0))
    assert teacher.last is None
    np.testing.assert_array_equal(teacher.decide(world, state).command, first.command)


def test_smoothing_one_sends_the_best_candidate():
    teacher = LookaheadTeacher(None, config=TeacherConfig(smoothing=1.0))
    for world, state in _teacher_states(4):
        d = teacher.decide(world, state)
        np.testing.assert_array_equal(d.command, d.best)


@pytest.mark.parametrize("bad", [0.0, -0.5, 1.5])
def test_smoothing_outside_the_unit_interval_is_refused(bad):
    with pytest.raises(ConfigError, match="smoothing"):
        TeacherConfig(smoothing=bad)


# --------------------------------------------------------------------------------------------
# 4. per-term scores and ablations


@pytest.fixture(scope="module")
def hr_rl_reward():
    return default_reward("hr-rl")


def _decide_with(weights: RuleWeights, reward):
    (world, state), *_ = _teacher_states(1, seed=5)
    t = LookaheadTeacher(reward, config=TeacherConfig(weights=weights))
    return t.decide(world, state)


def test_terms_add_up_to_the_total(hr_rl_reward):
    def bonus(ro, state, world):
        return 0.01 * ro.commands[:, 0]

    (world, state), *_ = _teacher_states(1, seed=5)
    t = LookaheadTeacher(hr_rl_reward, extra_score=bonus)
    d = t.decide(world, state)
    assert set(d.terms) == {"density", "goal", "obstacle", "extra", "total"}
    assert set(d.raw_terms) == {"density", "goal", "obstacle"}
    parts = d.terms["density"] + d.terms["goal"] + d.terms["obstacle"] + d.terms["extra"]
    assert d.terms["total"] == pytest.approx(parts, rel=1e-12, abs=1e-12)
    assert d.terms["extra"] == pytest.approx(0.01 * d.best[0])
    for k in ("density", "goal", "obstacle"):
        assert d.terms[k] != 0.0
        assert d.raw_terms[k] != 0.0
    # the weighted goal/obstacle terms are the unweighted ones times their adaptive weights
    ro = _rollout_of(t, world, state)
    d_total = float(np.linalg.norm(state.goal[0] - state.start[0]))
    r = min(1.0, ro.final_goal_distance[d.index] / d_total)
    assert d.terms["goal"] == pytest.approx(2.0 * (1.0 - r) * d.raw_terms["goal"])
    assert d.terms["obstacle"] == pytest.approx(d.raw_terms["obstacle"])
    a_den = 1.0 + math.cos(math.pi * (1.0 - r))
    assert d.terms["density"] == pytest.approx(a_den * d.raw_terms["density"])


@pytest.mark.parametrize("off", ["density", "goal", "obstacle"])
def test_switching_a_term_off_zeroes_it(off, hr_rl_reward):
    d = _decide_with(RuleWeights(**{f"use_{off}": False}), hr_rl_reward)
    assert d.terms[off] == 0.0
    for k in {"density", "goal", "obstacle"} - {off}:
        assert d.terms[k] != 0.0
    parts = d.terms["density"] + d.terms["goal"] + d.terms["obstacle"] + d.terms["extra"]
    assert d.terms["total"] == pytest.approx(parts, rel=1e-12, abs=1e-12)


def test_density_is_evaluated_for_feasible_candidates_only(hr_rl_reward):
    """Infeasible candidates (and, when some keep the soft margins, those that do not) are
    never chosen, so their density is not computed; the choice equals the one from scoring
    every candidate (eq. 14 for all 120)."""
    rows: list[int] = []

    def recording(z):
        rows.append(z.shape[0])
        return hr_rl_reward(z)

    t = LookaheadTeacher(recording, features=hr_rl_reward.info_["features"])  # type: ignore[arg-type]
    mixed = 0
    for world, state in _teacher_states(12, seed=4):
        t.reset({}, np.random.default_rng(0))
        rows.clear()
        d = t.decide(world, state)
        ro = _rollout_of(t, world, state)
        c, n_l = ro.robot.shape[:2]
        feasible = ~ro.collided & (ro.min_gap >= t.config.safety_margin)
        m = t.config.margins
        keep = feasible & (ro.min_gap >= m.human) & (ro.min_wall_gap >= m.wall)
        feasible = keep if keep.any() else feasible  # the candidates it chooses among
        assert rows == ([int(feasible.sum()) * n_l] if feasible.any() else [])
        mixed += int(0 < feasible.sum() < c)
        # reference: the density of all candidates, then the feasibility mask
        fm = feature_map(hr_rl_reward.info_["features"])
        feats = fm.from_rollout(ro.robot, ro.obs, ro.commands)
        r_den = hr_rl_reward(feats).reshape(c, n_l).mean(axis=1)
        d_total = float(np.linalg.norm(state.goal[0] - state.start[0]))
        total, _ = combine(
            r_den,
            goal_term(ro.final_goal_distance, d_total),
            obstacle_term(ro.obs),
            ro.final_goal_distance,
            d_total,
            t.config.weights,
        )
        assert d.index == int(np.argmax(np.where(feasible, total, -np.inf)))
        assert d.raw_terms["density"] == pytest.approx(r_den[d.index], rel=1e-6)
    assert mixed >= 3  # states where some candidates collide and some do not


def test_weight_overrides_replace_the_adaptive_weights(hr_rl_reward):
    w = RuleWeights(density_weight=0.5, goal_weight=3.0, obstacle_weight=2.0)
    d = _decide_with(w, hr_rl_reward)
    assert d.terms["density"] == pytest.approx(0.5 * d.raw_terms["density"])
    assert d.terms["goal"] == pytest.approx(3.0 * d.raw_terms["goal"])
    assert d.terms["obstacle"] == pytest.approx(2.0 * d.raw_terms["obstacle"])


def test_make_teacher_ablation_switches():
    full = make_teacher("hr-rl")
    assert full.density is not None and full.features == "obs_action_sincos"
    assert full.config.weights == RuleWeights()
    no_den = make_teacher("hr-rl", density=False)
    assert no_den.density is None and not no_den.config.weights.use_density
    assert not make_teacher("hr-rl", goal=False).config.weights.use_goal
    assert not make_teacher("hr-rl", obstacle=False).config.weights.use_obstacle
    assert make_teacher("static").features == "xy"
    assert make_teacher("hr-rl", human_model="constant_velocity").config.human_model == (
        "constant_velocity"
    )


@pytest.mark.slow
@pytest.mark.parametrize("name", ABLATIONS)
def test_registered_teachers_construct_and_run(name):
    assert name in policy_names()
    policy = build_policy(name, "hr-rl")
    assert isinstance(policy, LookaheadTeacher)
    assert policy.name == name
    decisions = []
    act = policy.act

    def spy(obs, info):
        cmd = act(obs, info)
        decisions.append(policy.last)
        return cmd

    policy.act = spy
    # a 10 s limit keeps the run short (an ablated teacher may dawdle until the time limit)
    scenario = dataclasses.replace(get_scenario("hr-rl"), sim=SimConfig(time_limit=10.0))
    rec, _ = run_episode(scenario, policy, seed=11)
    assert rec.policy == name
    assert rec.event in {"success", "collision", "timeout"}
    assert len(decisions) == rec.steps > 0
    feasible = [d for d in decisions if d.index >= 0]
    assert feasible
    off = name.removeprefix("teacher-no-") if name != "teacher" else None
    for d in feasible:
        for k in ("density", "goal", "obstacle"):
            if k == off:
                assert d.terms[k] == 0.0
    if off is None:
        assert any(d.terms["density"] != 0.0 for d in feasible)


def test_start_now_decides_as_the_teacher_of_people_who_start_now():
    # oracle: assuming everyone who has not started walking starts now decides exactly as the
    # plain teacher does in the state whose delays have all passed
    env = NavEnv("hr-rl")
    _, info = env.reset(seed=3)
    world, state = info["world"], info["state"]
    waiting = state.h_delay[0] > state.t[0]
    assert waiting.any()  # someone has not started yet (the exiting passenger's delay)
    started = dataclasses.replace(state, h_delay=np.minimum(state.h_delay, state.t[:, None]))
    assuming = make_teacher("hr-rl", density=False, assume_start_now=True)
    plain = make_teacher("hr-rl", density=False)
    assert assuming.config.assume.active
    np.testing.assert_array_equal(assuming.scores(world, state), plain.scores(world, started))
    np.testing.assert_array_equal(
        assuming.decide(world, state).command, plain.decide(world, started).command
    )
    assert (state.h_delay[0] > state.t[0]).sum() == waiting.sum()  # the given state unchanged


def _placed_on_the_way():
    """``(at, d0)``: ``at(time, dist)`` is an hr-rl start state with the robot ``dist`` from
    the goal (on the start–goal line) at ``time``; ``d0`` the start's distance."""
    env = NavEnv("hr-rl")
    _, info = env.reset(seed=5)
    state = info["state"]
    d0 = float(np.linalg.norm(state.robot[0, :2] - state.goal[0]))

    def at(time: float, dist: float):
        toward = (state.goal[0] - state.robot[0, :2]) / d0
        robot = state.robot.copy()
        robot[0, :2] = state.goal[0] - toward * dist
        return dataclasses.replace(state, robot=robot, t=np.array([time]))

    return at, d0


def test_patience_runs_out_after_its_time_without_progress():
    at, d0 = _placed_on_the_way()
    t = make_teacher("hr-rl", density=False, patience=1.0)
    assert t.config.patience == Patience(after=1.0)
    assert not t.impatient(at(0.0, d0))
    assert not t.impatient(at(0.9, d0 - 0.04))  # less than `progress` (5 cm): no progress
    assert t.impatient(at(1.0, d0 - 0.04))  # 1 s since the last progress
    assert not t.impatient(at(1.1, d0 - 0.1))  # progress: patient again
    assert t.impatient(at(2.1, d0 + 0.3))  # backwards for 1 s
    assert not t.impatient(at(0.0, d0))  # an earlier time: a new episode
    assert not make_teacher("hr-rl", patience=0.0).impatient(at(100.0, d0))


def test_an_impatient_teacher_decides_by_the_rule_terms_alone():
    # oracle: impatient, the teacher decides as the teacher without margins and learned term
    world, state = _driven(6, 20, [0.2, 0.0])
    impatient = make_teacher("hr-rl", patience=0.5)
    impatient._progress = (0.0, float(state.t[0]) - 1.0)  # no progress for 1 s
    rules = make_teacher("hr-rl", density=False, human_margin=0.0, wall_margin=0.0, patience=0)
    got, want = impatient.decide(world, state), rules.decide(world, state)
    np.testing.assert_array_equal(got.command, want.command)
    np.testing.assert_array_equal(got.scores, want.scores)
    patient = make_teacher("hr-rl", patience=100.0)
    assert not np.array_equal(patient.decide(world, state).scores, got.scores)


def test_an_impatient_teacher_holds_its_impatience_for_its_hold_time():
    at, d0 = _placed_on_the_way()
    t = make_teacher("hr-rl", density=False, patience=1.0, patience_hold=2.0)
    assert not t.impatient(at(0.0, d0))
    assert t.impatient(at(1.0, d0))  # 1 s without progress: impatient until t = 3 s
    assert t.impatient(at(1.5, d0 - 1.0))  # progress, but within the hold
    assert t.impatient(at(2.9, d0 - 1.5))
    assert not t.impatient(at(3.1, d0 - 1.6))  # the hold over, and progress made
    assert not t.impatient(at(0.0, d0))  # a new episode forgets the hold
    assert not t.impatient(at(0.5, d0))


def test_a_patient_teacher_that_keeps_its_margins_drops_only_the_learned_term():
    # oracle: impatient with keep_margins, the teacher decides as the teacher without R_den
    world, state = _driven(6, 20, [0.2, 0.0])
    impatient = make_teacher("hr-rl", patience=0.5, patience_keep_margins=True)
    impatient._progress = (0.0, float(state.t[0]) - 1.0)  # no progress for 1 s
    rules = make_teacher("hr-rl", density=False, patience=0)
    got, want = impatient.decide(world, state), rules.decide(world, state)
    np.testing.assert_array_equal(got.command, want.command)
    np.testing.assert_array_equal(got.scores, want.scores)
    dropped = make_teacher("hr-rl", patience=0.5)  # without keep_margins: the margins go too
    dropped._progress = impatient._progress
    bare = make_teacher("hr-rl", density=False, human_margin=0.0, wall_margin=0.0, patience=0)
    np.testing.assert_array_equal(
        dropped.decide(world, state).scores, bare.decide(world, state).scores
    )


def test_an_impatient_teacher_with_a_goal_weight_is_drawn_back_from_beyond_its_start():
    # eq. 18's α_goal = 2 (1 − r) vanishes once the robot is farther from the goal than it
    # started (r ≥ 1); with the learned term dropped nothing then draws it back
    at, d0 = _placed_on_the_way()
    world = NavEnv("hr-rl").world
    far = at(5.0, 1.1 * d0)  # beyond its start, facing away: no candidate gets within d0
    robot = far.robot.copy()
    robot[0, 2] -= np.pi
    far = dataclasses.replace(far, robot=robot)
    kw = {"patience": 0.5, "patience_hold": 100.0, "patience_keep_margins": True}
    adaptive = make_teacher("hr-rl", **kw)
    adaptive._progress = (0.0, 4.0)  # no progress for 1 s
    assert adaptive.decide(world, far).terms["goal"] == 0.0
    weighted = make_teacher("hr-rl", **kw, patience_goal_weight=2.0)
    weighted._progress = (0.0, 4.0)
    got = weighted.decide(world, far)
    assert got.terms["goal"] > 0.0
    # oracle: the teacher without R_den whose goal weight is 2 everywhere
    rules = make_teacher("hr-rl", density=False, patience=0)
    rules.config = dataclasses.replace(
        rules.config, weights=dataclasses.replace(rules.config.weights, goal_weight=2.0)
    )
    want = rules.decide(world, far)
    np.testing.assert_array_equal(got.scores, want.scores)
    np.testing.assert_array_equal(got.command, want.command)


def test_a_stuck_teacher_gives_up_the_margin_to_people_but_not_the_walls():
    # oracle: stuck (no progress for `after` seconds), the teacher decides as the teacher
    # without R_den and without the human margin; within its hold after progress, as one that
    # keeps both margins
    world, state = _driven(6, 20, [0.2, 0.0])
    t_now = float(state.t[0])
    kw = {
        "patience": 0.5,
        "patience_hold": 100.0,
        "patience_keep_margins": True,
        "patience_stuck_drops_human_margin": True,
    }
    stuck = make_teacher("hr-rl", **kw)
    stuck._progress = (0.0, t_now - 1.0)  # no progress for 1 s
    walls_only = make_teacher("hr-rl", density=False, human_margin=0.0, patience=0)
    got, want = stuck.decide(world, state), walls_only.decide(world, state)
    assert stuck._stuck
    np.testing.assert_array_equal(got.scores, want.scores)
    np.testing.assert_array_equal(got.command, want.command)
    held = make_teacher("hr-rl", **kw)
    held._progress = (0.0, t_now)  # progress just made, impatient from earlier: both margins
    held._impatient_until = t_now + 50.0
    rules = make_teacher("hr-rl", density=False, patience=0)
    assert held.impatient(state) and not held._stuck
    np.testing.assert_array_equal(
        held.decide(world, state).scores, rules.decide(world, state).scores
    )
    # the two differ here: the human margin excludes candidates the walls alone allow
    assert not np.array_equal(got.scores, rules.decide(world, state).scores)


def test_teacher_patient_is_our_teacher_with_the_chosen_patience():
    from pioneer.control.registry import build_policy
    from pioneer.control.teacher import PATIENT

    patient, plain = build_policy("teacher-patient", "hr-rl"), build_policy("teacher", "hr-rl")
    assert patient.config.patience == PATIENT and PATIENT.active and PATIENT.keep_margins
    assert dataclasses.replace(patient.config, patience=Patience()) == plain.config


def test_no_teacher_is_patient_by_default():
    from pioneer.control.registry import build_policy

    for name in ("teacher", "teacher-paper"):
        assert not build_policy(name, "hr-rl").config.patience.active
    assert Patience().after == 0.0
