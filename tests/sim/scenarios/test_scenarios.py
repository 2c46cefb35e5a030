"""Scenarios as data: elevator co-boarding, static study, validation and seeded sampling."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pioneer.errors import ConfigError, DataError, ScenarioError
from pioneer.sim import (
    ARRIVED,
    WALKING,
    ElevatorLayout,
    HumanSpec,
    Region,
    ScenarioConfig,
    StaticStudyLayout,
    elevator_scenario,
    get_scenario,
    sample_state,
    scenario_names,
    static_study_scenario,
)
from pioneer_testutils import assert_house_message, states_equal, wall_distances

ELEVATOR_NAMES = ["hr-rl", "hl-rr", "hr-rl-r03", "hl-rr-r03"]


def test_scenario_names():
    assert scenario_names() == sorted(
        ["hl-rr", "hl-rr-r03", "hr-rl", "hr-rl-r03", "hr-rl-compact", "hl-rr-compact", "static"]
    )
    for name in scenario_names():
        assert get_scenario(name).name == name
    assert get_scenario("  HR-RL ").name == "hr-rl"


def test_unknown_scenario_names_field_and_lists_names():
    with pytest.raises(ScenarioError) as exc:
        get_scenario("elevator-9000")
    msg = str(exc.value)
    assert_house_message(msg, "scenario", "elevator-9000")
    for name in scenario_names():
        assert name in msg
    assert isinstance(exc.value, ConfigError)  # ScenarioError is a ConfigError


def test_compact_elevator_geometry_matches_spec():
    """The compact world (the earlier default); the paper world: test_paper_world."""
    cfg = get_scenario("hr-rl-compact")
    walls = np.asarray(cfg.walls)
    assert cfg.bounds == (-2.0, 2.0, -1.3, 2.7)
    # Door gap x ∈ [−0.9, 0.9] on y = 0; cabin x ∈ [−1.25, 1.25], y ∈ [0, 2.7].
    assert (-2.0, 0.0, -0.9, 0.0) in cfg.walls
    assert (0.9, 0.0, 2.0, 0.0) in cfg.walls
    assert (-1.25, 2.7, 1.25, 2.7) in cfg.walls
    # Nothing blocks the door line or the open lobby side.
    door = wall_distances(np.column_stack([np.linspace(-0.85, 0.85, 35), np.zeros(35)]), walls)
    assert door.min() > 0.04
    far = wall_distances(np.column_stack([np.linspace(-1.9, 1.9, 39), np.full(39, -1.3)]), walls)
    assert far.min() > 0.09
    roles = [h.role for h in cfg.humans]
    assert sorted(roles) == ["boarding", "boarding", "exiting"]
    assert all(h.radius == 0.6 for h in cfg.humans)
    assert all(h.radius == 0.3 for h in get_scenario("hr-rl-r03").humans)


@pytest.mark.parametrize(("name", "side"), [("hr-rl", 1.0), ("hl-rr", -1.0)])
def test_goal_and_spots_on_the_right_sides(name, side):
    cfg = get_scenario(name)
    # The robot's goal is in the opposite half of the cabin to the boarders' spots.
    assert side * cfg.robot_goal.x[1] < 0
    assert cfg.robot_goal.y[0] > 0
    for h in cfg.humans:
        if h.role == "boarding":
            assert side * h.goal.center[0] > 0
            assert h.goal.center[1] > 0
    for seed in range(20):
        state = sample_state(cfg, np.random.default_rng(seed))
        assert side * state.goal[0, 0] < 0
        assert 0.0 < state.goal[0, 1] < 2.7
        assert abs(state.robot[0, 2] - math.pi / 2) <= 0.15 + 1e-12


def test_mirror_images():
    right, left = get_scenario("hr-rl"), get_scenario("hl-rr")

    def segments(walls, sign=1.0):
        return {frozenset({(sign * x1, y1), (sign * x2, y2)}) for x1, y1, x2, y2 in walls}

    assert segments(right.walls, -1.0) == segments(left.walls)
    assert right.robot_goal.mirrored() == left.robot_goal
    for hr, hl in zip(right.humans, left.humans, strict=True):
        assert hr.role == hl.role
        if hr.role == "boarding":
            assert hr.goal.mirrored() == hl.goal


@pytest.mark.parametrize("name", [*ELEVATOR_NAMES, "static"])
def test_sampled_states_are_collision_free_and_seeded(name):
    cfg = get_scenario(name)
    walls = np.asarray(cfg.walls, dtype=float)
    gap = cfg.min_start_gap
    r_r = cfg.sim.robot.radius
    starts = []
    for seed in range(30):
        state = sample_state(cfg, np.random.default_rng(seed))
        assert state.batch_size == 1
        pos, rad = state.h_pos[0], state.h_radius[0]
        rob = state.robot[0, :2]
        assert wall_distances(rob, walls).min() >= r_r + gap - 1e-12
        assert np.all(wall_distances(pos, walls).min(1) >= rad + gap - 1e-12)
        assert np.all(np.linalg.norm(pos - rob, axis=1) >= rad + r_r + gap - 1e-12)
        for i in range(len(pos)):
            for j in range(i):
                assert np.linalg.norm(pos[i] - pos[j]) >= rad[i] + rad[j] + gap - 1e-12
        assert state.gap[0] >= gap - 1e-12
        assert state.wall_gap[0] >= gap - 1e-12
        assert not state.collided[0] and not state.reached[0]
        assert np.all(state.h_vel == 0.0)
        assert set(state.h_vpref[0]) <= {0.0, 0.5, 0.6, 0.7}
        # Same seed → identical state.
        assert states_equal(state, sample_state(cfg, np.random.default_rng(seed)))
        starts.append(state.robot[0].copy())
    if name != "static":
        assert len({tuple(s) for s in starts}) == len(starts)  # seeds give different states
    else:  # the static study only randomises the start x
        assert len({s[0] for s in starts}) == len(starts)


def test_sampled_state_structure():
    cfg = get_scenario("hr-rl")
    state = sample_state(cfg, np.random.default_rng(4))
    roles = [h.role for h in cfg.humans]
    ex = roles.index("exiting")
    boarders = [i for i, r in enumerate(roles) if r == "boarding"]
    assert state.h_status[0].tolist() == [WALKING] * 3
    # Exiting: behind the door → in front of the door → aside → beyond the far lobby side,
    # where it is removed.
    assert state.h_n_waypoints[0, ex] == 4
    assert state.h_waypoints[0, ex, -1, 1] < -4.0
    # Boarders wait for the exiting passenger; the second boarder waits for the first.
    assert state.h_wait_for[0, boarders[0], ex] == 1
    assert state.h_wait_for[0, boarders[1], boarders[0]] == 1
    assert state.h_wait_for[0, ex].sum() == 0
    # … until the passenger is out of the door (heads for waypoint 2, the point aside) and
    # the first boarder is in it (heads for waypoint 1, just inside the cabin).
    assert state.h_release[0].tolist() == [1, 1, 2]
    assert state.h_reacts[0].all()
    assert np.all((state.h_delay[0, boarders] >= 0.5) & (state.h_delay[0, boarders] <= 1.5))
    np.testing.assert_array_equal(state.h_home, state.h_pos)
    np.testing.assert_array_equal(state.start[0], state.robot[0, :2])


def test_static_study_scenario():
    cfg = static_study_scenario()
    assert cfg.bounds == (-2.0, 2.0, -3.0, 3.0)
    state = sample_state(cfg, np.random.default_rng(0))
    assert state.h_status[0, 0] == ARRIVED  # static human: an obstacle from t = 0
    np.testing.assert_array_equal(state.h_pos[0, 0], [0.0, 0.0])
    np.testing.assert_array_equal(state.goal[0], [0.0, 2.4])
    assert state.robot[0, 1] == -2.4
    assert abs(state.robot[0, 0]) <= 0.3
    assert state.robot[0, 2] == math.pi / 2
    wide = static_study_scenario(StaticStudyLayout(width=6.0, human_radius=0.3))
    assert wide.bounds[:2] == (-3.0, 3.0)
    assert wide.humans[0].radius == 0.3
    with pytest.raises(ConfigError) as exc:
        StaticStudyLayout(width=-1.0)
    assert_house_message(str(exc.value), "width")


@pytest.mark.parametrize(
    "layout",
    [
        ElevatorLayout.compact().replace(n_boarding=4, n_exiting=2, human_radius=0.3),
        ElevatorLayout.compact().replace(door_width=1.2, human_radius=0.3),
        ElevatorLayout.compact().replace(
            cabin_width=3.0, cabin_depth=3.5, lobby_width=5.0, lobby_depth=2.0
        ),
        ElevatorLayout(n_boarding=0, n_exiting=0),
        ElevatorLayout(n_boarding=1, boarders_queue=False, human_side="left"),
        ElevatorLayout(n_boarding=3, boarder_y=(-4.4, -2.7), human_radius=0.5),
        ElevatorLayout(door_width=1.4, lobby_width=5.0, cabin_width=3.0),
    ],
)
def test_layout_variants_are_configuration(layout):
    cfg = elevator_scenario(layout)
    assert len(cfg.humans) == layout.n_boarding + layout.n_exiting
    state = sample_state(cfg, np.random.default_rng(1))
    assert state.n_humans == len(cfg.humans)
    door = [w for w in cfg.walls if w[1] == 0.0 and w[3] == 0.0]
    inner = sorted(abs(x) for w in door for x in (w[0], w[2]))[:2]
    assert inner == pytest.approx([layout.door_width / 2] * 2)


def test_elevator_layout_negative_door_width():
    with pytest.raises(ConfigError) as exc:
        ElevatorLayout(door_width=-1.0)
    assert_house_message(str(exc.value), "door_width", "-1.0")


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"door_width": 3.0}, "door_width"),  # wider than the cabin
        ({"cabin_width": 5.0}, "cabin_width"),  # wider than the lobby
        ({"human_side": "up"}, "human_side"),
        ({"n_boarding": -1}, "n_boarding"),
        ({"n_exiting": 1.5}, "n_exiting"),
        ({"human_radius": 0.0}, "human_radius"),
        ({"margin": -0.1}, "margin"),
        ({"cabin_depth": math.inf}, "cabin_depth"),
    ],
)
def test_elevator_layout_validation(kwargs, field):
    with pytest.raises(ConfigError) as exc:
        ElevatorLayout(**kwargs)
    assert_house_message(str(exc.value), field)


def test_door_narrower_than_robot():
    with pytest.raises(ScenarioError) as exc:
        elevator_scenario(ElevatorLayout(door_width=0.5))
    assert_house_message(str(exc.value), "door_width")


def _room_walls():
    return ((-3, -3, 3, -3), (3, -3, 3, 3), (3, 3, -3, 3), (-3, 3, -3, -3))


def _scenario(humans, robot_start=None, **kw):
    return ScenarioConfig(
        name="custom",
        walls=_room_walls(),
        bounds=(-3, 3, -3, 3),
        robot_start=robot_start or Region(x=(-0.5, 0.5), y=(-2.0, -2.0)),
        robot_goal=Region(x=(0.0, 0.0), y=(2.0, 2.0)),
        robot_heading=(0.0, 0.0),
        humans=tuple(humans),
        **kw,
    )


def test_human_start_inside_wall_is_rejected():
    inside = HumanSpec(
        role="walking",
        start=Region(x=(2.8, 3.2), y=(-0.2, 0.2)),  # straddles the wall x = 3
        goal=Region(x=(0.0, 0.0), y=(0.0, 0.0)),
    )
    with pytest.raises(ScenarioError) as exc:
        _scenario([inside])
    assert_house_message(str(exc.value), "humans[0].start")


def test_second_human_start_inside_wall_names_its_index():
    ok = HumanSpec(role="a", start=Region(x=(0, 0), y=(0, 0)), goal=Region(x=(1, 1), y=(1, 1)))
    bad = HumanSpec(role="b", start=Region(x=(-3, -3), y=(0, 0)), goal=Region(x=(1, 1), y=(1, 1)))
    with pytest.raises(ScenarioError) as exc:
        _scenario([ok, bad])
    assert_house_message(str(exc.value), "humans[1].start")


def test_robot_start_inside_wall_is_rejected():
    with pytest.raises(ScenarioError) as exc:
        _scenario([], robot_start=Region(x=(3.0, 3.0), y=(0.0, 0.0)))
    assert_house_message(str(exc.value), "robot_start")


def test_invalid_wait_for_is_rejected():
    h = HumanSpec(
        role="a", start=Region(x=(0, 0), y=(0, 0)), goal=Region(x=(1, 1), y=(1, 1)), wait_for=(0,)
    )
    with pytest.raises(ScenarioError) as exc:
        _scenario([h])
    assert_house_message(str(exc.value), "humans[0].wait_for")


def test_bad_bounds_and_regions():
    with pytest.raises(ScenarioError) as exc:
        ScenarioConfig(
            name="x",
            walls=(),
            bounds=(1, -1, 0, 1),
            robot_start=Region(x=(0, 0), y=(0, 0)),
            robot_goal=Region(x=(0, 0), y=(0, 0)),
            robot_heading=(0, 0),
            humans=(),
        )
    assert_house_message(str(exc.value), "bounds")
    with pytest.raises(ConfigError) as exc:
        Region(x=(1.0, 0.0), y=(0.0, 0.0))
    assert_house_message(str(exc.value), "Region.x")
    with pytest.raises(ConfigError) as exc:
        HumanSpec(
            role="a",
            start=Region(x=(0, 0), y=(0, 0)),
            goal=Region(x=(0, 0), y=(0, 0)),
            v_pref_choices=(),
        )
    assert_house_message(str(exc.value), "v_pref_choices")


def test_impossible_placement_raises():
    # Two 1 m humans pinned to the same point: every draw overlaps.
    h = HumanSpec(
        role="a", start=Region(x=(0, 0), y=(0, 0)), goal=Region(x=(1, 1), y=(1, 1)), radius=1.0
    )
    cfg = _scenario([h, h])
    with pytest.raises(ScenarioError) as exc:
        sample_state(cfg, np.random.default_rng(0))
    assert_house_message(str(exc.value), "initial state")


@settings(max_examples=60, deadline=None)
@given(
    x=st.tuples(st.floats(-5, 5), st.floats(0, 3)),
    y=st.tuples(st.floats(-5, 5), st.floats(0, 3)),
    seed=st.integers(0, 2**32 - 1),
)
def test_region_sample_and_mirror(x, y, seed):
    reg = Region(x=(x[0], x[0] + x[1]), y=(y[0], y[0] + y[1]))
    p = reg.sample(np.random.default_rng(seed))
    assert reg.x[0] <= p[0] <= reg.x[1]
    assert reg.y[0] <= p[1] <= reg.y[1]
    m = reg.mirrored()
    assert m.x == (-reg.x[1], -reg.x[0])
    assert m.y == reg.y
    assert m.mirrored() == reg
    np.testing.assert_allclose(m.center, [-reg.center[0], reg.center[1]])


def test_scenario_config_round_trips_through_dict():
    for name in scenario_names():
        cfg = get_scenario(name)
        again = ScenarioConfig.from_dict(cfg.to_dict())
        assert again == cfg
        assert states_equal(
            sample_state(cfg, np.random.default_rng(3)),
            sample_state(again, np.random.default_rng(3)),
        )


# ------------------------------------------------------------------ user-registered variants
def test_a_registered_variant_is_reachable_by_name_and_runs(scenario_registry):
    from pioneer.envs.env import NavEnv

    sc = scenario_registry  # leave no trace for other tests
    deep = ElevatorLayout(lobby_depth=2.8)
    sc.register_scenario("hr-rl-deep", lambda: elevator_scenario(deep, name="hr-rl-deep"))
    assert "hr-rl-deep" in sc.scenario_names()
    cfg = sc.get_scenario("HR-RL-Deep ")
    assert cfg.name == "hr-rl-deep" and cfg.bounds[2] == pytest.approx(-2.8)
    rng = np.random.default_rng(3)
    start_y = [sample_state(cfg, rng).robot[0, 1] for _ in range(20)]
    assert min(start_y) < -1.3  # beyond the default lobby's far side: the variant is in use
    env = NavEnv("hr-rl-deep")
    obs, info = env.reset(seed=1)
    for _ in range(5):
        obs, _, _, _, info = env.step(np.array([0.3, 0.0], dtype=np.float32))
    assert obs.shape == (29,) and info["event"] is None


def test_registering_a_builtin_name_or_a_non_scenario_is_refused(scenario_registry):
    sc = scenario_registry
    with pytest.raises(ScenarioError) as err:
        sc.register_scenario("hr-rl", lambda: elevator_scenario())
    assert_house_message(str(err.value), "hr-rl", "rename")
    with pytest.raises(ScenarioError) as err:
        sc.register_scenario("odd", lambda: ElevatorLayout())  # type: ignore[arg-type, return-value]
    assert_house_message(str(err.value), "ScenarioConfig", "ElevatorLayout")
    assert "odd" not in sc.scenario_names()


def test_a_layout_that_cannot_place_its_bodies_is_refused_at_registration(scenario_registry):
    """Three boarders do not fit the default 1.3 m lobby: refused up front, not mid-run."""
    sc = scenario_registry
    crowded = ElevatorLayout(n_boarding=3)
    with pytest.raises(ScenarioError) as err:
        sc.register_scenario("crowded", lambda: elevator_scenario(crowded, name="crowded"))
    assert "scenario 'crowded': start state for seed 0 (of 50 checked)" in str(err.value)
    assert "crowded" not in sc.scenario_names()


# --------------------------------------------------------------------------------------------
# Scenario files (pioneer.scenarios/1) and PIONEER_SCENARIOS

VARIANTS = {
    "format": "pioneer.scenarios/1",
    "scenarios": {
        "hr-rl-deep": {"elevator": {"human_side": "right", "lobby_depth": 2.8}},
        "static-wide": {"static": {"width": 5.0}, "sim": {"time_limit": 40.0}},
    },
}


@pytest.fixture
def clean_registry(scenario_registry):
    """Scenario registry and PIONEER_SCENARIOS restored after the test."""
    return scenario_registry


def _write(tmp_path, data, name="variants.json"):
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return path


def test_scenario_file_registers_its_variants(clean_registry, tmp_path):
    sc = clean_registry
    names = sc.load_scenario_file(_write(tmp_path, VARIANTS))
    assert names == ["hr-rl-deep", "static-wide"]
    deep = sc.get_scenario("hr-rl-deep")
    want = elevator_scenario(ElevatorLayout(lobby_depth=2.8)).replace(name="hr-rl-deep")
    assert deep == want
    wide = sc.get_scenario("static-wide")
    assert wide.name == "static-wide" and wide.sim.time_limit == 40.0
    assert wide.bounds[1] - wide.bounds[0] == pytest.approx(5.0)
    assert get_scenario("static").sim.time_limit != 40.0  # the built-in is untouched


def test_environment_variable_loads_files_on_demand(clean_registry, tmp_path, monkeypatch):
    sc = clean_registry
    monkeypatch.setenv(sc.SCENARIOS_ENV, str(_write(tmp_path, VARIANTS)))
    assert "static-wide" in sc.scenario_names()
    assert sc.get_scenario("hr-rl-deep").bounds[2] == pytest.approx(-2.8)


@pytest.mark.parametrize(
    ("content", "needles"),
    [
        ("{not json", ("valid JSON",)),
        ({"format": "other", "scenarios": {}}, ("pioneer.scenarios/1",)),
        ({"format": "pioneer.scenarios/1", "scenarios": {}}, ("non-empty",)),
        (
            {"format": "pioneer.scenarios/1", "scenarios": {"x": {"lobby": {}}}},
            ("exactly one of", "lobby"),
        ),
        (
            {"format": "pioneer.scenarios/1", "scenarios": {"x": {"elevator": {}, "static": {}}}},
            ("exactly one of",),
        ),
        (
            {"format": "pioneer.scenarios/1", "scenarios": {"x": {"elevator": {"depth": 2}}}},
            ("'x'", "depth", "misspelled"),
        ),
        (
            {
                "format": "pioneer.scenarios/1",
                "scenarios": {"x": {"elevator": {"lobby_depth": -1}}},
            },
            ("'x'", "lobby_depth"),
        ),
        (
            {"format": "pioneer.scenarios/1", "scenarios": {"hr-rl": {"elevator": {}}}},
            ("hr-rl", "rename"),
        ),
        (
            {"format": "pioneer.scenarios/1", "scenarios": {"x": {"elevator": {}, "base": "hq"}}},
            ("'x'", "base", "hq"),
        ),
    ],
)
def test_bad_scenario_files_are_refused_with_a_house_message(
    clean_registry, tmp_path, content, needles
):
    """A file's structure, names and bases are checked when it is loaded (a refused file
    registers nothing); a variant's layout when it is first used."""
    sc = clean_registry
    before = sc.scenario_names()
    try:
        names = sc.load_scenario_file(_write(tmp_path, content))
    except ScenarioError as exc:
        message = str(exc)
        assert sc.scenario_names() == before
    else:
        with pytest.raises(ScenarioError) as err:
            sc.get_scenario(names[0])
        message = str(err.value)
    assert_house_message(message, *needles)


def test_a_variant_is_checked_when_first_used_and_a_missing_file_is_named(clean_registry, tmp_path):
    """A file of many variants costs its parse: a variant's layout and the placement of its
    start states are checked when it is first used, and the error names the file and it."""
    sc = clean_registry
    data = {
        "format": "pioneer.scenarios/1",
        "scenarios": {
            "good": {"elevator": {}},
            "bad": {"elevator": {"door_width": 9.0}},
            "tight": {"elevator": {"n_boarding": 3, "lobby_depth": 2.0}},
            "short": {"static": {"length": 5.0}},  # start row 0.1 m off the wall
        },
    }
    sc.load_scenario_file(_write(tmp_path, data))
    assert sc.get_scenario("good").name == "good"
    with pytest.raises(ScenarioError) as err:
        sc.get_scenario("bad")
    assert_house_message(str(err.value), "variants.json", "'bad'", "door_width")
    with pytest.raises(ScenarioError) as err:  # fits for most start states, not for all
        sc.get_scenario("tight")
    assert_house_message(str(err.value), "'tight'", "seed", "collision-free")
    with pytest.raises(ScenarioError) as err:
        sc.get_scenario("short")
    assert_house_message(str(err.value), "variants.json", "'short'", "robot_start")
    with pytest.raises(ScenarioError) as err:
        sc.load_scenario_file(tmp_path / "missing.json")
    assert_house_message(str(err.value), "missing.json", "path")


def test_a_variant_with_a_base_uses_the_shipped_demos_and_students_of_it(clean_registry, tmp_path):
    from pioneer.data import base_scenario, shipped_demos, shipped_student
    from pioneer.reward.recipe import default_features

    sc = clean_registry
    data = {
        "format": "pioneer.scenarios/1",
        "scenarios": {
            "deep": {"elevator": {"human_side": "left", "lobby_depth": 2.8}, "base": "HL-RR"},
            "wide-room": {"static": {"width": 5.0}, "base": "static"},
            "alone": {"elevator": {}},
        },
    }
    sc.load_scenario_file(_write(tmp_path, data))
    assert sc.scenario_base("deep") == "hl-rr" and base_scenario("deep") == "hl-rr"
    assert shipped_student("deep", "mlp") == shipped_student("hl-rr", "mlp")
    assert shipped_demos("wide-room") == shipped_demos("static")
    assert default_features("wide-room") == "xy" and default_features("deep") == "obs_action"
    assert sc.scenario_base("alone") == "alone" and base_scenario("hr-rl-r03") == "hr-rl"
    with pytest.raises(DataError):
        shipped_student("alone")
    with pytest.raises(ScenarioError) as err:
        sc.register_scenario("other", lambda: elevator_scenario(), base="deep")
    assert_house_message(str(err.value), "base", "deep")


def test_the_example_scenario_file_loads_and_every_variant_samples(clean_registry):
    from pathlib import Path

    from pioneer.data import shipped_student

    sc = clean_registry
    path = Path(__file__).resolve().parents[3] / "examples" / "scenarios.json"
    names = sc.load_scenario_file(path)
    assert len(names) >= 5
    for name in names:
        cfg = sc.get_scenario(name)
        for seed in range(40):  # placement must succeed for any episode seed, not just one
            sample_state(cfg, np.random.default_rng(seed))
        assert sc.scenario_base(name) in ("hr-rl", "hl-rr", "static")
        if sc.scenario_base(name) != "static":
            shipped_student(name)


def test_every_refused_variant_of_a_file_is_reported_at_once(clean_registry, tmp_path):
    sc = clean_registry
    data = {
        "format": "pioneer.scenarios/1",
        "scenarios": {
            "fine": {"elevator": {}},
            "narrow": {"lobby": {"lobby_width": 0.5}},
            "crowd": {"elevator": {"n_boarding": 2}, "base": "hq"},
        },
    }
    with pytest.raises(ScenarioError) as err:
        sc.load_scenario_file(_write(tmp_path, data))
    msg = str(err.value)
    assert "2 variants refused" in msg and "\n" not in msg
    assert_house_message(msg, "'narrow'", "lobby", "'crowd'", "hq")
    assert "'fine'" not in msg and "fine" not in sc.scenario_names()


def test_a_noisy_lidar_works_for_the_teacher(clean_registry, tmp_path):
    """The teacher plans on noise-free rays (observe_states ignores the noise); the policy's
    own observation is noisy."""
    from pioneer.control.registry import build_policy
    from pioneer.eval.episode import run_episode

    sc = clean_registry
    data = {
        "format": "pioneer.scenarios/1",
        "scenarios": {"noisy": {"static": {}, "sim": {"lidar": {"noise_std": 0.05}}}},
    }
    sc.load_scenario_file(_write(tmp_path, data))
    rec, _ = run_episode("noisy", build_policy("teacher", "static"), 0)
    assert rec.event in {"success", "collision", "timeout"} and rec.steps > 0


EXAMPLES = Path(__file__).resolve().parents[3] / "examples"


@pytest.mark.parametrize("path", sorted(EXAMPLES.glob("*.json")), ids=lambda p: p.name)
def test_every_example_scenario_file_loads(clean_registry, path):
    """The shipped example files register (each variant places its bodies for the 50 start
    seeds a scenario file is checked with) and build the worlds they name."""
    names = clean_registry.load_scenario_file(path)
    assert sorted(names) == sorted(json.loads(path.read_text())["scenarios"])
    for name in names:
        assert clean_registry.get_scenario(name).name == name


def test_the_exiting_passenger_example_changes_only_the_exiting_passenger(clean_registry):
    clean_registry.load_scenario_file(EXAMPLES / "exiting_passenger.json")
    base = get_scenario("hr-rl")

    def exiting(name: str) -> list:
        return [h for h in get_scenario(name).humans if h.role == "exiting"]

    assert exiting("hr-exit-none") == []
    late, early, paper = exiting("hr-exit-late"), exiting("hr-exit-early"), exiting("hr-rl")
    assert late[0].start.y[0] > paper[0].start.y[1]  # starts deeper than the paper's 0.9–1.5 m
    assert early[0].start.y[1] == pytest.approx(paper[0].start.y[0])  # … or nearer the door
    for name in ("hr-exit-late", "hr-exit-early"):
        world = get_scenario(name)
        assert world.walls == base.walls
        assert [h for h in world.humans if h.role == "boarding"] == [
            h for h in base.humans if h.role == "boarding"
        ]


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.sampled_from(["hr-rl", "hl-rr", "static"]))
def test_the_batched_wall_distances_are_the_single_ones_bit_for_bit(seed: int, name: str) -> None:
    # the start-state check measures all bodies at once; it must decide exactly as one at a time
    from pioneer.sim.scenarios.spec import _wall_distance, _wall_distances

    walls = get_scenario(name).world().walls
    pts = np.random.default_rng(seed).uniform(-4.0, 4.0, (7, 2))
    batched = _wall_distances(pts, walls)
    np.testing.assert_array_equal(batched, [_wall_distance(p, walls) for p in pts])
    np.testing.assert_allclose(batched, wall_distances(pts, walls).min(-1), rtol=1e-12)
    assert np.all(np.isinf(_wall_distances(pts, walls[:0])))
