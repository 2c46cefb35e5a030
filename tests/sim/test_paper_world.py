"""The paper world (paper §V-B; docs/simulator.md): human–robot interaction as configuration,
the layout's start states, and the compact world kept under its own names."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pioneer.errors import ConfigError, ScenarioError
from pioneer.sim import (
    ElevatorLayout,
    SimConfig,
    SocialForceConfig,
    elevator_scenario,
    get_scenario,
    sample_state,
    step,
)
from pioneer.sim.humans import PRESETS
from pioneer_testutils import make_state


def _walk(world, state, commands):
    out = [state.h_pos.copy()]
    for u in commands:
        state = step(world, state, u)
        out.append(state.h_pos.copy())
    return np.stack(out)


def test_a_zero_reaction_leaves_human_trajectories_identical_with_and_without_the_robot():
    sim = SimConfig(social_force=SocialForceConfig(a_robot=0.0))
    scenario = elevator_scenario(ElevatorLayout(), sim=sim)
    world = scenario.world()
    rng = np.random.default_rng(3)
    for seed in range(4):
        s0 = sample_state(scenario, np.random.default_rng(seed))
        away = s0.copy()
        away.robot[0, :2] = 1e3  # no robot in the map
        cmds = [rng.uniform([0.0, -1.2], [0.8, 1.2]).reshape(1, 2) for _ in range(60)]
        with_robot = _walk(world, s0, cmds)
        without = _walk(world, away, [np.zeros((1, 2))] * 60)
        np.testing.assert_array_equal(with_robot, without)


def test_the_default_humans_react_to_the_robot():
    """The default strength is weak but not zero: a robot in the way deflects people."""
    scenario = get_scenario("hr-rl")
    assert 0.0 < scenario.sim.social_force.a_robot < scenario.sim.social_force.a_human
    world = scenario.world()
    s0 = sample_state(scenario, np.random.default_rng(0))
    away = s0.copy()
    away.robot[0, :2] = 1e3
    stand = [np.zeros((1, 2))] * 80
    assert not np.array_equal(_walk(world, s0, stand), _walk(world, away, stand))


@pytest.mark.parametrize("reacts", [True, False])
def test_the_per_human_flag(reacts):
    """A human flagged not to react walks through the robot's place as if it were absent."""
    human = {"pos": (0.0, -1.5), "waypoints": [], "goal": (0.0, 2.0), "reacts": reacts}
    state = make_state(robot=(0.0, 0.0, 0.0), goal=(5.0, 5.0), humans=[human])
    world = (
        get_scenario("static")
        .world()
        .__class__(walls=np.zeros((0, 4)), bounds=np.array([-9.0, 9.0, -9.0, 9.0]))
    )
    away = state.copy()
    away.robot[0, :2] = 1e3
    stand = [np.zeros((1, 2))] * 15
    same = np.array_equal(_walk(world, state, stand), _walk(world, away, stand))
    assert same is (not reacts)


def test_layout_flags_reach_the_state():
    lay = ElevatorLayout(boarders_react_to_robot=False, exiting_react_to_robot=True)
    s = sample_state(elevator_scenario(lay), np.random.default_rng(0))
    roles = [h.role for h in elevator_scenario(lay).humans]
    np.testing.assert_array_equal(s.h_reacts[0], [r == "exiting" for r in roles])


def test_reaction_strength_is_validated():
    SocialForceConfig(a_robot=0.0)  # allowed: the robot is invisible
    with pytest.raises(ConfigError, match="a_robot"):
        SocialForceConfig(a_robot=-0.1)
    with pytest.raises(ConfigError, match="tau"):
        SocialForceConfig(tau=0.0)


def test_presets():
    assert SocialForceConfig.preset("paper") == SocialForceConfig()
    assert SocialForceConfig.preset("robot-invisible").a_robot == 0.0
    assert SocialForceConfig.preset("robot-as-human").a_robot == SocialForceConfig().a_human
    assert SocialForceConfig.preset("cvar-bf").tau == SocialForceConfig.preset("crowdnav").tau == 1
    assert set(PRESETS) >= {"paper", "compact", "cvar-bf", "crowdnav"}
    with pytest.raises(ConfigError, match="preset"):
        SocialForceConfig.preset("nope")


def test_the_paper_world_geometry():
    """4 × 4 m lobby in front of the attached 2.5 × 2.7 m cabin, 1.8 m door (paper §V-B)."""
    sc = get_scenario("hr-rl")
    assert sc.bounds == (-2.0, 2.0, -4.0, 2.7)
    walls = np.asarray(sc.walls)
    assert (-2.0, 0.0, -0.9, 0.0) in sc.walls and (0.9, 0.0, 2.0, 0.0) in sc.walls
    assert np.isclose(walls[:, [0, 2]].max(), 2.0) and np.isclose(walls[:, [1, 3]].min(), -4.0)
    y = sc.robot_start.y
    assert -2.6 <= y[0] <= y[1] <= -1.8  # ≈ 2 m in front of the door
    roles = [h.role for h in sc.humans]
    assert roles == ["boarding", "boarding", "exiting"]
    xs = [h.start.center[0] for h in sc.humans if h.role == "boarding"]
    assert min(xs) < sc.robot_start.x[0] and max(xs) > sc.robot_start.x[1]  # robot between
    exiting = sc.humans[2]
    assert exiting.goal.y[1] < sc.bounds[2] - exiting.radius  # leaves through the far side
    assert abs(exiting.waypoints[-1][0]) > 0.9  # … after turning aside


def test_the_mirror_scenario():
    a, b = get_scenario("hr-rl"), get_scenario("hl-rr")
    for ha, hb in zip(a.humans, b.humans, strict=True):
        assert ha.goal.mirrored() == hb.goal
        assert [(-x, y) for x, y in ha.waypoints] == [(x + 0.0, y) for x, y in hb.waypoints]
    assert a.robot_goal.mirrored() == b.robot_goal


def test_the_last_boarders_spot_beside_the_door_is_a_layout_parameter():
    # the default is the paper world's spot (docs/simulator.md); another span moves only the
    # last boarder's goal, towards the humans' side in both worlds
    assert get_scenario("hr-rl").humans[1].goal.x == (0.1, 0.35)
    for side, sign in (("right", 1.0), ("left", -1.0)):
        base = elevator_scenario(ElevatorLayout(human_side=side))
        moved = elevator_scenario(ElevatorLayout(human_side=side, last_boarder_x=(0.45, 0.6)))
        assert sorted(sign * x for x in moved.humans[1].goal.x) == [0.45, 0.6]
        assert moved.humans[1].goal.y == base.humans[1].goal.y
        assert moved.humans[0] == base.humans[0] and moved.humans[2] == base.humans[2]


def _obstacles_within(s, i: int, gap: float, walls: np.ndarray) -> int:
    """How many bodies and walls are within ``gap`` of human i's surface."""
    from pioneer.sim.scenarios.spec import _wall_distance

    p, r = s.h_pos[0, i], s.h_radius[0, i]
    n = 0
    for j in range(s.n_humans):
        if j != i and np.linalg.norm(s.h_pos[0, j] - p) - r - s.h_radius[0, j] < gap:
            n += 1
    if np.linalg.norm(s.robot[0, :2] - p) - r - 0.3 < gap:
        n += 1
    for w in walls:
        if _wall_distance(p, w.reshape(1, 4)) - r < gap:
            n += 1
    return n


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), name=st.sampled_from(["hr-rl", "hl-rr"]))
def test_every_initial_state_is_collision_free_and_nobody_is_boxed_in(seed, name):
    sc = get_scenario(name)
    s = sample_state(sc, np.random.default_rng(seed))
    walls = np.asarray(sc.walls)
    gap = sc.min_start_gap
    assert s.gap[0] >= gap and s.wall_gap[0] >= gap
    for i in range(s.n_humans):
        for j in range(i):
            d = np.linalg.norm(s.h_pos[0, i] - s.h_pos[0, j]) - s.h_radius[0, i] - s.h_radius[0, j]
            assert d >= gap
        # Boxed in: pressed against two or more bodies or walls at once.
        assert _obstacles_within(s, i, gap, walls) == 0


def test_the_compact_world_is_the_earlier_default():
    sc = get_scenario("hr-rl-compact")
    assert sc.bounds == (-2.0, 2.0, -1.3, 2.7)
    assert sc.sim.social_force == SocialForceConfig.preset("compact")
    assert sc.sim.social_force.a_robot == sc.sim.social_force.a_human
    assert get_scenario("hl-rr-compact").robot_goal == sc.robot_goal.mirrored()


def test_release_waypoints_are_validated():
    with pytest.raises(ScenarioError, match="exit_release_waypoint"):
        ElevatorLayout(exit_release_waypoint=9)
    with pytest.raises(ScenarioError, match="boarder_release_waypoint"):
        ElevatorLayout(boarder_release_waypoint=0)


def test_boarders_wait_until_the_exiting_passenger_is_out_of_the_door():
    sc = get_scenario("hr-rl")
    world = sc.world()
    s = sample_state(sc, np.random.default_rng(1))
    s.robot[0, :2] = 1e3
    start = s.h_pos[0, :2].copy()
    while s.h_wp_index[0, 2] < sc.humans[2].release_waypoint:
        s = step(world, s, np.zeros((1, 2)))
        # Until the passenger is out, the boarders hold their places (nudged at most a little).
        assert np.linalg.norm(s.h_pos[0, :2] - start, axis=1).max() < 0.3
    for _ in range(30):
        s = step(world, s, np.zeros((1, 2)))
    assert np.linalg.norm(s.h_pos[0, 0] - start[0]) > 0.5  # the first boarder goes
