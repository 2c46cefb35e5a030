"""The world core: pure batched step, exact robot motion, swept collision checks."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pioneer.errors import CommandError, ConfigError
from pioneer.sim import (
    ARRIVED,
    GONE,
    SimConfig,
    SocialForceConfig,
    State,
    World,
    get_scenario,
    observe,
    sample_state,
    static_study_scenario,
    step,
)
from pioneer.sim.robot import integrate_unicycle
from pioneer.sim.world import advance, observe_states
from pioneer_testutils import (
    assert_house_message,
    make_state,
    open_world,
    room_world,
    states_equal,
    wall_distances,
)

R_ROBOT = 0.3


def _hr_rl_state(seed=0, n_steps=0):
    cfg = get_scenario("hr-rl")
    world = cfg.world()
    state = sample_state(cfg, np.random.default_rng(seed))
    for _ in range(n_steps):
        state = step(world, state, [0.4, 0.1])
    return world, state


# --------------------------------------------------------------------------------------------
# purity and batching


def test_step_is_pure():
    world, state = _hr_rl_state(seed=1, n_steps=5)
    before = state.copy()
    new = step(world, state, [0.8, 0.5])
    assert states_equal(state, before)
    assert new is not state
    for f in dataclasses.fields(State):
        assert not np.shares_memory(getattr(new, f.name), getattr(state, f.name)), f.name
    assert not np.array_equal(new.robot, state.robot)
    assert not np.array_equal(new.h_pos, state.h_pos)


def test_world_arrays_are_read_only():
    world = room_world(2.0, 3.0)
    with pytest.raises(ValueError):
        world.walls[0, 0] = 5.0
    with pytest.raises(ValueError):
        world.bounds[0] = 5.0


def test_batched_step_equals_separate_steps():
    world, state = _hr_rl_state(seed=2, n_steps=3)
    rng = np.random.default_rng(99)
    # 120 commands, some outside the limits (they are clipped identically).
    commands = np.column_stack([rng.uniform(-0.2, 1.0, 120), rng.uniform(-1.6, 1.6, 120)])
    batch = state.repeat(120)
    assert batch.batch_size == 120
    for _ in range(4):
        batch = step(world, batch, commands)
    for i in range(120):
        single = state
        for _ in range(4):
            single = step(world, single, commands[i])
        assert states_equal(batch.take(i), single), i


def test_step_with_long_dt_equals_short_steps_in_empty_world():
    world = open_world()
    state = make_state((0.3, -0.2, 0.4), goal=(40.0, 40.0))
    for u in ([0.8, 0.0], [0.5, 0.9], [0.8, -1.2], [0.0, 1.0]):
        one = step(world, state, u, dt=0.3)
        three = step(world, step(world, step(world, state, u), u), u)
        np.testing.assert_allclose(one.robot, three.robot, atol=1e-9)
        assert one.t[0] == pytest.approx(0.3)
        assert one.path_length[0] == pytest.approx(three.path_length[0])


def test_single_arc_equals_three_arcs():
    """With one substep per step the 0.3 s step is a single exact arc."""
    sim = SimConfig(social_force=SocialForceConfig(max_substep=10.0))
    world = open_world(sim=sim)
    state = make_state((-1.0, 2.0, -2.5), goal=(40.0, 40.0))
    for u in ([0.8, 0.0], [0.6, 1.25], [0.7, -0.3]):
        one = step(world, state, u, dt=0.3)
        three = step(world, step(world, step(world, state, u, 0.1), u, 0.1), u, 0.1)
        np.testing.assert_allclose(one.robot, three.robot, atol=1e-9)
        expected = integrate_unicycle(-1.0, 2.0, -2.5, u[0], u[1], 0.3)
        np.testing.assert_allclose(one.robot[0], expected, atol=1e-12)


def test_full_circle_through_steps():
    world = open_world()
    state = make_state((1.0, 1.0, 0.0), goal=(40.0, 40.0))
    w = 0.4 * math.pi
    n = round(2 * math.pi / w / 0.1)  # 50 steps of 0.1 s
    for _ in range(n):
        state = step(world, state, [0.5, w])
    np.testing.assert_allclose(state.robot[0, :2], [1.0, 1.0], atol=1e-9)
    assert abs(math.remainder(state.robot[0, 2], 2 * math.pi)) < 1e-9
    assert state.path_length[0] == pytest.approx(0.5 * n * 0.1)


def test_commands_are_clipped():
    world = open_world()
    state = make_state((0.0, 0.0, 0.0), goal=(40.0, 40.0))
    new = step(world, state, [5.0, -9.0])
    np.testing.assert_array_equal(new.command[0], [0.8, -0.4 * math.pi])
    ref = integrate_unicycle(0.0, 0.0, 0.0, 0.8, -0.4 * math.pi, 0.1)
    np.testing.assert_allclose(new.robot[0], ref, atol=1e-12)
    backwards = step(world, state, [-1.0, 0.0])
    np.testing.assert_array_equal(backwards.robot, state.robot)  # v_min = 0


@pytest.mark.parametrize(
    "bad", [[math.nan, 0.0], [0.0, math.inf], [[0.1, 0.2], [0.1, 0.2]], [1.0, 2.0, 3.0]]
)
def test_bad_command_raises(bad):
    world, state = _hr_rl_state()
    with pytest.raises(CommandError) as exc:
        step(world, state, bad)
    assert_house_message(str(exc.value), "command")


@pytest.mark.parametrize("dt", [0.0, -0.1, math.nan])
def test_bad_dt_raises(dt):
    world, state = _hr_rl_state()
    with pytest.raises(ConfigError) as exc:
        step(world, state, [0.0, 0.0], dt=dt)
    assert_house_message(str(exc.value), "dt")


def test_state_helpers():
    _, state = _hr_rl_state()
    many = state.repeat(5)
    assert many.batch_size == 5
    assert many.n_humans == state.n_humans == 3
    with pytest.raises(ConfigError) as exc:
        many.repeat(2)
    assert_house_message(str(exc.value), "repeat")
    sub = many.take(np.array([1, 3]))
    assert sub.batch_size == 2
    sub.robot[0, 0] = 99.0
    assert many.robot[1, 0] != 99.0  # take copies
    assert many.take(0).batch_size == 1
    assert state.humans_present.shape == (1, 3)


def test_world_rejects_non_finite_walls():
    with pytest.raises(ConfigError) as exc:
        World(walls=np.array([[0.0, 0.0, np.nan, 1.0]]), bounds=np.array([-1, 1, -1, 1.0]))
    assert_house_message(str(exc.value), "World")


# --------------------------------------------------------------------------------------------
# collisions


def _first_collision(world, state, u, max_steps, dt=None):
    for k in range(1, max_steps + 1):
        state = step(world, state, u, dt=dt)
        if state.collided[0]:
            return k, state
    return None, state


@pytest.mark.parametrize("distance", [1.0, 1.234, 0.77])
def test_straight_drive_into_wall_flags_collision_at_contact_step(distance):
    """Static room (walls x = ±2, y = ±3); the robot faces the wall x = 2 from ``distance``."""
    cfg = static_study_scenario()
    world = cfg.world()
    state = make_state(
        (2.0 - distance, -1.0, 0.0),
        goal=(0.0, 2.4),
        humans=[{"pos": (0.0, 0.0), "status": GONE}],
    )
    v, dt = 0.8, 0.1
    # Contact when the travelled distance exceeds distance − r_r (first step where it does).
    expected = math.floor((distance - R_ROBOT) / (v * dt)) + 1
    k, st = _first_collision(world, state, [v, 0.0], 100)
    assert k == expected
    assert st.wall_gap[0] < 0.0
    assert st.wall_gap[0] == pytest.approx(distance - R_ROBOT - v * dt * k, abs=1e-9)
    # One step earlier the robot was clear.
    prev = state
    for _ in range(expected - 1):
        prev = step(world, prev, [v, 0.0])
    assert not prev.collided[0]
    assert prev.wall_gap[0] > 0.0


def test_straight_drive_into_static_human_flags_collision_at_contact_step():
    cfg = static_study_scenario()
    world = cfg.world()
    state = sample_state(cfg, np.random.default_rng(0))
    state.robot[0] = [0.0, -2.0, math.pi / 2]
    assert state.h_status[0, 0] == ARRIVED  # the static human never moves
    r_h = state.h_radius[0, 0]
    v, dt = 0.8, 0.1
    expected = math.floor((2.0 - r_h - R_ROBOT) / (v * dt)) + 1
    k, st = _first_collision(world, state, [v, 0.0], 100)
    assert k == expected
    assert st.gap[0] == pytest.approx(2.0 - r_h - R_ROBOT - v * dt * k, abs=1e-9)
    assert np.array_equal(st.h_pos[0, 0], [0.0, 0.0])
    # Collision is sticky and the goal can no longer be reached.
    st = step(world, st, [0.0, 0.0])
    assert st.collided[0]
    assert not st.reached[0]


@pytest.mark.parametrize("max_substep", [0.1, 10.0])
def test_fast_pass_through_a_human_is_detected(max_substep):
    """End poses are clear but the straight path crosses the human: the swept check fires."""
    sim = SimConfig(social_force=SocialForceConfig(max_substep=max_substep))
    world = open_world(sim=sim)
    r_h = 0.1
    state = make_state(
        (0.0, -0.8, math.pi / 2),
        goal=(30.0, 30.0),
        humans=[{"pos": (0.0, 0.0), "radius": r_h, "status": ARRIVED}],
    )
    new = step(world, state, [0.8, 0.0], dt=2.0)
    end_clearance = np.linalg.norm(new.robot[0, :2] - new.h_pos[0, 0]) - r_h - R_ROBOT
    assert new.robot[0, 1] == pytest.approx(0.8)
    assert end_clearance > 0.3  # the end pose alone looks fine
    assert new.collided[0]
    assert new.gap[0] == pytest.approx(-(r_h + R_ROBOT), abs=1e-9)


@pytest.mark.parametrize("max_substep", [0.1, 10.0])
def test_fast_pass_through_a_thin_wall_is_detected(max_substep):
    sim = SimConfig(social_force=SocialForceConfig(max_substep=max_substep))
    world = World(
        walls=np.array([[0.0, -1.0, 0.0, 1.0]]), bounds=np.array([-9, 9, -9, 9.0]), sim=sim
    )
    state = make_state((-0.8, 0.0, 0.0), goal=(5.0, 5.0))
    new = step(world, state, [0.8, 0.0], dt=2.0)
    assert new.robot[0, 0] == pytest.approx(0.8)
    assert abs(new.robot[0, 0]) - R_ROBOT > 0.3
    assert new.collided[0]
    assert new.wall_gap[0] == pytest.approx(-R_ROBOT, abs=1e-9)


def test_moving_human_crossing_the_robot_between_steps_is_detected():
    """Both move: the human crosses the robot's position mid-step (relative swept motion)."""
    sim = SimConfig(social_force=SocialForceConfig(max_substep=10.0, a_robot=1e-9))
    world = open_world(sim=sim)
    state = make_state(
        (0.0, 0.0, 0.0),
        goal=(30.0, 30.0),
        humans=[
            {
                "pos": (-0.9, 0.0),
                "goal": (10.0, 0.0),
                "vel": (1.0, 0.0),
                "vpref": 1.0,
                "radius": 0.2,
            }
        ],
    )
    new = step(world, state, [0.0, 0.0], dt=1.8)
    assert np.linalg.norm(new.h_pos[0, 0] - new.robot[0, :2]) > 0.5 + 0.2
    assert new.collided[0]


def test_clearance_is_reported_without_collision():
    world = open_world()
    state = make_state(
        (0.0, 0.0, 0.0),
        goal=(30.0, 30.0),
        humans=[{"pos": (3.0, 0.0), "status": ARRIVED, "radius": 0.5}],
    )
    new = step(world, state, [0.0, 0.0])
    assert new.gap[0] == pytest.approx(3.0 - 0.5 - R_ROBOT)
    assert new.wall_gap[0] == math.inf  # no walls
    assert not new.collided[0]
    # Without humans the clearance is +inf.
    empty = step(world, make_state((0.0, 0.0, 0.0), goal=(9.0, 9.0)), [0.1, 0.0])
    assert empty.gap[0] == math.inf


def test_gone_humans_are_ignored_by_collisions():
    world = open_world()
    state = make_state(
        (0.0, 0.0, 0.0), goal=(30.0, 30.0), humans=[{"pos": (0.2, 0.0), "status": GONE}]
    )
    new = step(world, state, [0.5, 0.0])
    assert not new.collided[0]
    assert new.gap[0] == math.inf


def test_reaching_the_goal():
    world = open_world()
    state = make_state((0.0, 0.0, 0.0), goal=(1.0, 0.0))
    for _ in range(9):
        state = step(world, state, [0.8, 0.0])
        if state.reached[0]:
            break
    # Reached once ‖p − goal‖ < 0.3: after 1.0 − 0.3 = 0.7 m, i.e. step 9 (0.72 m).
    assert state.reached[0]
    assert state.t[0] == pytest.approx(0.9)
    assert not state.collided[0]
    # Sticky: driving on keeps it reached.
    state = step(world, state, [0.8, 0.0])
    assert state.reached[0]


# --------------------------------------------------------------------------------------------
# the swept check is conservative along the exact arc (no missed contact)

_pos = st.floats(-2.0, 2.0, allow_nan=False, allow_subnormal=False)


def _arc_samples(x, y, th, v, w, dt, n=400):
    ts = np.linspace(0.0, dt, n + 1)
    return np.array([integrate_unicycle(x, y, th, v, w, t)[:2] for t in ts])


@settings(max_examples=80, deadline=None)
@given(
    x=_pos,
    y=_pos,
    th=st.floats(-math.pi, math.pi, allow_nan=False),
    v=st.floats(0.0, 0.8, allow_nan=False),
    w=st.floats(-0.4 * math.pi, 0.4 * math.pi, allow_nan=False),
    dt=st.sampled_from([0.1, 0.35, 1.0]),
    max_substep=st.sampled_from([0.1, 10.0]),
    wall=st.tuples(_pos, _pos, _pos, _pos),
    human=st.tuples(_pos, _pos, st.floats(0.05, 0.8, allow_nan=False)),
)
def test_swept_clearances_never_exceed_true_arc_clearances(
    x, y, th, v, w, dt, max_substep, wall, human
):
    sim = SimConfig(social_force=SocialForceConfig(max_substep=max_substep))
    world = World(walls=np.array([wall], dtype=float), bounds=np.array([-9, 9, -9, 9.0]), sim=sim)
    hx, hy, hr = human
    state = make_state(
        (x, y, th), goal=(8.0, 8.0), humans=[{"pos": (hx, hy), "radius": hr, "status": ARRIVED}]
    )
    new = step(world, state, [v, w], dt=dt)
    arc = _arc_samples(x, y, th, v, w, dt)
    true_wall = float(wall_distances(arc, world.walls).min()) - R_ROBOT
    true_human = float(np.linalg.norm(arc - (hx, hy), axis=1).min()) - hr - R_ROBOT
    assert new.wall_gap[0] <= true_wall + 1e-9
    assert new.gap[0] <= true_human + 1e-9
    if true_wall < -1e-9 or true_human < -1e-9:
        assert new.collided[0]
    # Not absurdly pessimistic either: within the chord–arc sag of the truth.
    h = dt / max(1, math.ceil(dt / max_substep - 1e-9))
    sag = v * h * abs(w * h) / 8
    step_len = v * dt / 400
    assert new.wall_gap[0] >= true_wall - 2 * sag - step_len - 1e-9
    assert new.gap[0] >= true_human - 2 * sag - step_len - 1e-9


def test_observe_states_equals_observing_each_state():
    """One ray-casting call for a stack of states gives exactly each state's observation."""
    scenario = get_scenario("hr-rl")
    world = scenario.world()
    rng = np.random.default_rng(3)
    s = sample_state(scenario, rng).repeat(7)
    states = []
    for _ in range(4):
        s = step(world, s, rng.uniform(-1.0, 1.0, (7, 2)), dt=0.3)
        states.append(s)
    stacked = observe_states(world, states)
    assert stacked.shape == (4, 7, world.sim.lidar.obs_dim) and stacked.dtype == np.float32
    for k, state in enumerate(states):
        np.testing.assert_array_equal(stacked[k], observe(world, state))
    with pytest.raises(ConfigError, match="equal B and N"):
        observe_states(world, [states[0], states[1].take(0)])


def _trace_and_steps(name: str, seed: int, copies: int, n_steps: int):
    """A seeded state of ``name`` repeated ``copies`` times, advanced by one ``advance`` call
    of ``n_steps`` and by as many calls of ``step`` with the same random commands:
    ``(scenario, world, s0, trace, states)``."""
    scenario = get_scenario(name)
    world = scenario.world()
    rng = np.random.default_rng(seed)
    s0 = sample_state(scenario, rng).repeat(copies)
    u = rng.uniform(-1.0, 1.0, (copies, 2))
    tr = advance(world, s0, u, dt=0.3, n_steps=n_steps)
    s, states = s0, []
    for _ in range(n_steps):
        s = step(world, s, u, dt=0.3)
        states.append(s)
    return scenario, world, s0, tr, states


def test_float32_observations_of_a_trace_are_those_of_its_states():
    """The rollout observations with float32 rays (the teacher's option) come from one path:
    a trace's equal ``observe_states`` of its states in float32, bit for bit, and stay
    within the last bits of the float64 reference (``observe`` keeps float64)."""
    _, world, _, tr, states = _trace_and_steps("hr-rl", 12, copies=8, n_steps=5)
    f32 = tr.observations(world, precision="float32")
    np.testing.assert_array_equal(
        f32, observe_states(world, states, precision="float32").transpose(1, 0, 2)
    )
    ref = tr.observations(world)
    np.testing.assert_array_equal(ref, np.stack([observe(world, x) for x in states], axis=1))
    assert np.isclose(f32, ref, rtol=0.0, atol=1e-3).mean() > 0.999  # a grazing beam may flip


@pytest.mark.parametrize("name", ["hr-rl", "hl-rr", "hr-rl-compact"])
def test_advance_equals_repeated_steps_bit_for_bit(name):
    """``advance`` (one kernel call for L steps, recording each) gives exactly the states,
    poses, humans, clearances and observations of L calls of ``step``."""
    scenario, world, s0, tr, states = _trace_and_steps(name, 11, copies=9, n_steps=6)
    assert states_equal(tr.final, states[-1])
    assert states_equal(s0, sample_state(scenario, np.random.default_rng(11)).repeat(9))
    np.testing.assert_array_equal(tr.poses, np.stack([x.robot for x in states], axis=1))
    np.testing.assert_array_equal(tr.circles[..., :2], np.stack([x.h_pos for x in states], 1))
    gone = np.stack([x.h_status == GONE for x in states], axis=1)
    np.testing.assert_array_equal(tr.circles[..., 2] == 0.0, gone)
    np.testing.assert_array_equal(tr.gap, np.min([x.gap for x in states], axis=0))
    np.testing.assert_array_equal(tr.wall_gap, np.min([x.wall_gap for x in states], axis=0))
    np.testing.assert_array_equal(
        tr.observations(world), observe_states(world, states).transpose(1, 0, 2)
    )


def test_advance_stops_colliding_copies_and_keeps_the_others_bit_for_bit():
    """``stop_at_collision``: a copy that never collides gets exactly the values of repeated
    ``step``; a colliding copy is left at its collision step, whose records it repeats."""
    scenario = get_scenario("hr-rl")
    world = scenario.world()
    rng = np.random.default_rng(5)
    n_b, n_l = 60, 10
    s0 = sample_state(scenario, rng).repeat(n_b)
    u = np.stack([rng.uniform(0.1, 0.8, n_b), rng.uniform(-1.2, 1.2, n_b)], axis=1)
    tr = advance(world, s0, u, dt=0.3, n_steps=n_l, stop_at_collision=True)
    s, states = s0, []
    for _ in range(n_l):
        s = step(world, s, u, dt=0.3)
        states.append(s)
    hit = np.stack([x.collided for x in states], axis=1)  # (B, L)
    first = np.where(hit.any(axis=1), hit.argmax(axis=1), n_l - 1)
    assert 0 < hit[:, -1].sum() < n_b  # both kinds present
    np.testing.assert_array_equal(tr.live_steps, first + 1)
    obs_steps = observe_states(world, states).transpose(1, 0, 2)
    obs = tr.observations(world)
    some = np.arange(n_b) % 3 == 1  # colliding and non-colliding copies alike
    np.testing.assert_array_equal(tr.observations(world, some), obs[some])
    for b in range(n_b):
        kc = first[b]
        for k in range(n_l):
            src = states[min(k, kc)]
            np.testing.assert_array_equal(tr.poses[b, k], src.robot[b])
            np.testing.assert_array_equal(tr.circles[b, k, :, :2], src.h_pos[b])
            np.testing.assert_array_equal(obs[b, k], obs_steps[b, min(k, kc)])
        end = states[kc]
        np.testing.assert_array_equal(tr.final.robot[b], end.robot[b])
        np.testing.assert_array_equal(tr.final.h_pos[b], end.h_pos[b])
        assert tr.final.collided[b] == hit[b, -1]
        np.testing.assert_array_equal(tr.gap[b], np.min([x.gap[b] for x in states[: kc + 1]]))
    # A copy collided from the start is never advanced.
    s1 = s0.copy()
    s1.collided[:] = True
    frozen = advance(world, s1, u, dt=0.3, n_steps=3, stop_at_collision=True)
    np.testing.assert_array_equal(frozen.live_steps, np.ones(n_b, dtype=np.int64))
    assert states_equal(frozen.final, s1)
    np.testing.assert_array_equal(frozen.poses, np.repeat(s1.robot[:, None], 3, axis=1))


def test_advance_refuses_bad_arguments():
    world, state = _hr_rl_state()
    with pytest.raises(ConfigError, match="n_steps"):
        advance(world, state, [0.3, 0.0], dt=0.3, n_steps=0)
    with pytest.raises(ConfigError, match="dt"):
        advance(world, state, [0.3, 0.0], dt=0.0, n_steps=3)
