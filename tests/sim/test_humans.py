"""Social-force humans: reacting to the robot, reaching goals, hard walls, elevator flows."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pioneer.errors import ConfigError
from pioneer.sim import (
    ARRIVED,
    GONE,
    WALKING,
    HumanSpec,
    Region,
    ScenarioConfig,
    SimConfig,
    SocialForceConfig,
    get_scenario,
    sample_state,
    step,
)
from pioneer_testutils import (
    assert_house_message,
    concat_states,
    make_state,
    open_world,
    room_world,
    wall_distances,
)

R_ROBOT = 0.3
R_HUMAN = 0.6


def far_walls_scenario(start_x: float, vpref: float) -> ScenarioConfig:
    """A 20 × 20 m room, robot standing at the origin, one human walking from y = −4 to 4.

    The human reacts to the robot as to another human (the ``robot-as-human`` preset), so
    these tests check the social-force avoidance itself, not the paper world's weak reaction.
    """
    walls = ((-10, -10, 10, -10), (10, -10, 10, 10), (10, 10, -10, 10), (-10, 10, -10, -10))
    return ScenarioConfig(
        name="crossing",
        walls=walls,
        bounds=(-10, 10, -10, 10),
        robot_start=Region(x=(0.0, 0.0), y=(0.0, 0.0)),
        robot_goal=Region(x=(5.0, 5.0), y=(5.0, 5.0)),
        robot_heading=(0.0, 0.0),
        humans=(
            HumanSpec(
                role="walking",
                start=Region(x=(start_x, start_x), y=(-4.0, -4.0)),
                goal=Region(x=(start_x, start_x), y=(4.0, 4.0)),
                v_pref_choices=(vpref,),
            ),
        ),
        sim=SimConfig(social_force=SocialForceConfig.preset("robot-as-human")),
    )


@pytest.mark.parametrize(("offset", "vpref"), [(0.1, 0.5), (0.2, 0.7), (-0.15, 0.6)])
def test_human_deflects_around_standing_robot(offset, vpref):
    cfg = far_walls_scenario(offset, vpref)
    world = cfg.world()
    state = sample_state(cfg, np.random.default_rng(0))
    assert np.array_equal(state.h_vel, np.zeros((1, 1, 2)))
    path = [state.h_pos[0, 0].copy()]
    for _ in range(300):
        state = step(world, state, [0.0, 0.0])
        path.append(state.h_pos[0, 0].copy())
    path = np.array(path)
    dist = np.linalg.norm(path - state.robot[0, :2], axis=1)
    # Never overlaps the robot body deeply.
    assert dist.min() > R_HUMAN + R_ROBOT - 0.15
    # Deflected sideways (to the side of its initial offset) while passing the robot ...
    passing = np.abs(path[:, 1]) < 0.5
    assert passing.any()
    lateral = path[passing, 0] * np.sign(offset)
    assert lateral.max() > 0.8
    # ... and still reaches its goal on the far side.
    assert state.h_status[0, 0] == ARRIVED
    assert path[-1, 1] > 3.5
    # The robot did not move and was never hit.
    assert np.array_equal(state.robot[0], [0.0, 0.0, 0.0])
    assert not state.collided[0]


def head_on(sf: SocialForceConfig) -> tuple[float, bool]:
    """A human walking straight at a standing robot (commanded v = 0) with the reaction
    ``sf``: the smallest centre distance over 10 s and whether they collided."""
    cfg = far_walls_scenario(0.0, 0.7)
    cfg = dataclasses.replace(cfg, sim=SimConfig(social_force=sf))
    world = cfg.world()
    state = sample_state(cfg, np.random.default_rng(0))
    closest = np.inf
    for _ in range(100):
        state = step(world, state, [0.0, 0.0])
        closest = min(closest, float(np.linalg.norm(state.h_pos[0, 0] - state.robot[0, :2])))
    return closest, bool(state.collided[0])


def test_a_standing_robot_can_be_avoided_like_a_standing_person():
    weak = SocialForceConfig()  # the paper world: the weak reaction whatever the robot does
    standing = SocialForceConfig.preset("standing-robot")
    assert standing.a_robot == weak.a_robot and standing.a_robot_standing == 2.0
    # the paper world: the weak term does not stop a person walking at a standing robot
    d_weak, hit_weak = head_on(weak)
    assert hit_weak and d_weak < R_HUMAN + R_ROBOT
    # with the standing reaction the person stops short of it, as in front of a person
    d_standing, hit_standing = head_on(standing)
    assert not hit_standing and d_standing > R_HUMAN + R_ROBOT
    # a robot moving (faster than standing_speed) keeps the weak reaction
    moving = dataclasses.replace(standing, standing_speed=0.0)
    d_moving, _ = head_on(moving)
    assert d_moving == d_weak


def test_human_starting_at_rest_reaches_goal():
    world = open_world()
    state = make_state((20.0, 20.0, 0.0), humans=[{"pos": (0.0, 0.0), "goal": (3.0, 1.0)}])
    assert np.all(state.h_vel == 0.0)
    state = step(world, state, [0.0, 0.0])
    assert np.linalg.norm(state.h_vel[0, 0]) > 0.0  # the classic zero-velocity trap
    for _ in range(150):
        state = step(world, state, [0.0, 0.0])
    assert state.h_status[0, 0] == ARRIVED
    assert np.linalg.norm(state.h_pos[0, 0] - (3.0, 1.0)) < SocialForceConfig().goal_tolerance
    assert np.array_equal(state.h_vel[0, 0], [0.0, 0.0])  # arrived humans stop


def test_speed_cap_and_waypoints():
    world = open_world()
    vpref = 0.5
    state = make_state(
        (20.0, 20.0, 0.0),
        humans=[{"pos": (0.0, 0.0), "waypoints": [(4.0, 0.0)], "goal": (4.0, 4.0), "vpref": vpref}],
    )
    visited_wp = False
    for _ in range(300):
        state = step(world, state, [0.0, 0.0])
        assert np.linalg.norm(state.h_vel[0, 0]) <= 1.3 * vpref + 1e-9
        visited_wp |= np.linalg.norm(state.h_pos[0, 0] - (4.0, 0.0)) < 0.3
    assert visited_wp
    assert state.h_status[0, 0] == ARRIVED
    assert state.h_wp_index[0, 0] == 1


def test_arrived_and_gone_humans_do_not_move():
    world = open_world()
    state = make_state(
        (0.0, 0.0, 0.0),
        humans=[
            {"pos": (1.0, 0.0), "goal": (5.0, 0.0), "status": ARRIVED},
            {"pos": (-1.0, 0.0), "goal": (-5.0, 0.0), "status": GONE},
        ],
    )
    for _ in range(20):
        state = step(world, state, [0.0, 0.0])
    assert np.array_equal(state.h_pos[0], [[1.0, 0.0], [-1.0, 0.0]])
    assert state.h_status[0].tolist() == [ARRIVED, GONE]


def test_start_delay_and_wait_for():
    world = open_world()
    state = make_state(
        (20.0, 20.0, 0.0),
        humans=[
            {"pos": (0.0, 0.0), "goal": (3.0, 0.0), "delay": 1.0},
            {"pos": (0.0, 5.0), "goal": (3.0, 5.0), "wait_for": [0]},
        ],
    )
    for _ in range(9):  # t < 1 s: both hold their start (up to their weak mutual repulsion)
        state = step(world, state, [0.0, 0.0])
    assert np.allclose(state.h_pos[0], [[0.0, 0.0], [0.0, 5.0]], atol=0.01)
    assert state.h_status[0].tolist() == [WALKING, WALKING]
    for _ in range(200):
        state = step(world, state, [0.0, 0.0])
        if state.h_status[0, 0] == WALKING:  # the second waits while the first walks
            assert np.linalg.norm(state.h_pos[0, 1] - (0.0, 5.0)) < 0.05
    assert state.h_status[0].tolist() == [ARRIVED, ARRIVED]


def test_human_leaving_the_map_is_removed():
    world = open_world(bounds=(-2, 2, -2, 2))
    state = make_state((0.0, 0.0, 0.0), humans=[{"pos": (1.0, 1.0), "goal": (1.0, 6.0)}])
    for _ in range(200):
        state = step(world, state, [0.0, 0.0])
        if state.h_status[0, 0] == GONE:
            break
    assert state.h_status[0, 0] == GONE
    assert not state.humans_present[0, 0]
    # Removed only once its body is fully outside the bounds.
    assert state.h_pos[0, 0, 1] > 2.0 + R_HUMAN


def test_human_cannot_be_pushed_through_a_wall_by_the_robot():
    """The robot drives into a human standing against a wall; the wall still holds."""
    world = room_world(2.0, 3.0)
    state = make_state(
        (0.0, 1.0, math.pi / 2), humans=[{"pos": (0.0, 3.0 - R_HUMAN - 0.05), "vpref": 0.5}]
    )
    walls = np.asarray(world.walls)
    for _ in range(60):
        state = step(world, state, [0.8, 0.0])
        d = wall_distances(state.h_pos[0], walls) - state.h_radius[0][:, None]
        assert d.min() >= -1e-6
    assert state.collided[0]


def _run_random_commands(name, seeds, n_steps, rng):
    cfg = get_scenario(name)
    world = cfg.world()
    walls = np.asarray(cfg.walls, dtype=float)
    state = concat_states([sample_state(cfg, np.random.default_rng(s)) for s in seeds])
    lo, hi = cfg.sim.robot.command_low, cfg.sim.robot.command_high
    worst = math.inf
    for _ in range(n_steps):
        state = step(world, state, rng.uniform(lo, hi, (state.batch_size, 2)))
        clearance = wall_distances(state.h_pos, walls) - state.h_radius[..., None]
        worst = min(worst, float(clearance.min()))
    return worst, state


@pytest.mark.parametrize("name", ["hr-rl", "hl-rr", "hr-rl-r03", "hl-rr-r03"])
def test_humans_never_cross_walls(name):
    rng = np.random.default_rng(sum(map(ord, name)))
    worst, state = _run_random_commands(name, range(24), 300, rng)
    assert worst >= -1e-6
    assert (state.h_status != WALKING).any()  # the episodes went somewhere


def test_wall_holds_while_another_human_accelerates():
    """Minimal case: the robot presses human 0 against the top wall while human 1 speeds up
    along +x. Human 0's body must stay out of the wall."""
    world = room_world(2.0, 3.0)
    walls = np.asarray(world.walls)
    state = make_state(
        (0.0, 1.9, math.pi / 2),
        humans=[
            {"pos": (0.0, 3.0 - R_HUMAN), "goal": (0.0, 5.0), "vpref": 0.5},
            {"pos": (-1.0, -2.0), "goal": (1.5, -2.0), "vpref": 2.0},
        ],
    )
    worst = math.inf
    for _ in range(10):
        state = step(world, state, [0.0, 0.0])
        clearance = wall_distances(state.h_pos[0], walls) - state.h_radius[0][:, None]
        worst = min(worst, float(clearance.min()))
    assert worst >= -1e-6


def test_humans_never_cross_walls_with_robot_chasing_them():
    """The robot drives straight at the nearest human (pushing it around)."""
    cfg = get_scenario("hr-rl")
    world = cfg.world()
    walls = np.asarray(cfg.walls, dtype=float)
    state = concat_states([sample_state(cfg, np.random.default_rng(s)) for s in range(16)])
    for _ in range(250):
        d = state.h_pos - state.robot[:, None, :2]
        dist = np.where(state.humans_present, np.linalg.norm(d, axis=-1), np.inf)
        k = dist.argmin(1)
        target = d[np.arange(state.batch_size), k]
        bearing = np.arctan2(target[:, 1], target[:, 0]) - state.robot[:, 2]
        bearing = (bearing + np.pi) % (2 * np.pi) - np.pi
        u = np.column_stack([np.full(state.batch_size, 0.8), 2.0 * bearing])
        state = step(world, state, u)
        clearance = wall_distances(state.h_pos, walls) - state.h_radius[..., None]
        assert clearance.min() >= -1e-6
    assert state.collided.all()


def _robot_away_rollout(name, n_steps):
    cfg = get_scenario(name)
    world = cfg.world()
    state = concat_states([sample_state(cfg, np.random.default_rng(s)) for s in range(10)])
    state.robot[:, :2] = [3.5, -3.5]
    for _ in range(n_steps):
        state = step(world, state, np.zeros((state.batch_size, 2)))
    roles = [h.role for h in cfg.humans]
    return state, roles


@pytest.mark.parametrize(
    ("name", "n_steps", "side"),
    [("hr-rl", 600, 1.0), ("hl-rr", 600, -1.0), ("hr-rl-r03", 300, 1.0), ("hl-rr-r03", 300, -1.0)],
)
def test_elevator_flows_complete_without_robot(name, n_steps, side):
    """Robot out of the way: the exiting passenger leaves, the boarders reach their half.

    The 0.6 m bodies crawl through the 1.8 m door (documented), hence 60 s for r = 0.6."""
    state, roles = _robot_away_rollout(name, n_steps)
    assert roles.count("exiting") == 1
    assert roles.count("boarding") == 2
    for i, role in enumerate(roles):
        if role == "exiting":
            assert np.all(state.h_status[:, i] == GONE)
            assert np.all(state.h_pos[:, i, 1] < -1.3)  # left through the open lobby side
        else:
            assert np.all(state.h_status[:, i] == ARRIVED)
            assert np.all(state.h_pos[:, i, 1] > -0.1)
            assert np.all(side * state.h_pos[:, i, 0] > -0.1)
    assert not state.collided.any()


def test_social_force_config():
    assert SocialForceConfig.preset("paper") == SocialForceConfig()
    crowd = SocialForceConfig.preset("crowdnav")
    assert crowd.b_human == 1.0
    assert crowd.a_human == 2.0
    assert crowd.a_robot == 0.0  # CrowdNav++: robot.visible = False
    params = SocialForceConfig().as_array()
    assert params.shape == (14,)
    assert params[0] == 0.5  # tau
    assert params[12] == params[3]  # unset: a standing robot repels like a moving one
    assert SocialForceConfig.preset("standing-robot").as_array()[12] == 2.0
    with pytest.raises(ConfigError) as exc:
        SocialForceConfig.preset("nope")
    assert_house_message(str(exc.value), "preset")
    with pytest.raises(ConfigError) as exc:
        SocialForceConfig(tau=0.0)
    assert_house_message(str(exc.value), "tau")
