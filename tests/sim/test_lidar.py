"""LiDAR: the numba ray caster against a brute-force reference, the 29-D observation and the
real laser-scan adapter (paper §III-A)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pioneer.errors import ConfigError, DataError
from pioneer.sim import get_scenario, sample_state, step
from pioneer.sim.geometry import ray_circle, ray_segment
from pioneer.sim.lidar import (
    OBS_DIM,
    LidarConfig,
    beam_angles,
    cast_rays,
    cast_rays_into,
    observation_from_ranges,
    observation_from_scan,
    observation_names,
    ray_dtype,
    resample_scan,
)
from pioneer.sim.world import goal_bearing, observe, scan
from pioneer_testutils import (
    assert_house_message,
    concat_states,
    make_state,
    room_world,
    sector_minima,
)

PI32 = float(np.float32(np.pi))
CFG = LidarConfig()

# --------------------------------------------------------------------------------------------
# Brute-force reference caster (plain Python floats, first principles)

# Thresholds below which a configuration is numerically ambiguous (a tiny change of the ray
# direction flips hit/miss or moves the hit a lot); such beams are not compared.
_EPS_PARALLEL = 1e-5  # sin of the incidence angle
_EPS_END = 1e-7  # segment parameter near 0 or 1
_EPS_T = 1e-9  # hit right at the origin
_EPS_GRAZE = 1e-4  # relative half-chord of a circle hit
_EPS_INSIDE = 1e-6  # relative distance of the origin to a circle boundary


def ref_ray_segment(ox, oy, dx, dy, seg):
    """Solve o + t·d = a + s·(b − a) for (t, s) by Cramer's rule. Returns (t or inf, ambiguous)."""
    x1, y1, x2, y2 = seg
    ex, ey = x2 - x1, y2 - y1
    # [dx  −ex] [t]   [x1 − ox]
    # [dy  −ey] [s] = [y1 − oy]
    det = dx * (-ey) - (-ex) * dy
    rx, ry = x1 - ox, y1 - oy
    if det == 0.0:
        return math.inf, False  # parallel (or a zero-length segment): never a hit
    length = math.hypot(ex, ey)
    t = (rx * (-ey) - (-ex) * ry) / det
    s = (dx * ry - dy * rx) / det
    ambiguous = (
        abs(det) < _EPS_PARALLEL * length
        or abs(s) < _EPS_END
        or abs(s - 1.0) < _EPS_END
        or abs(t) < _EPS_T
    )
    hit = t >= 0.0 and 0.0 <= s <= 1.0
    return (t if hit else math.inf), ambiguous


def ref_ray_circle(ox, oy, dx, dy, cx, cy, r):
    """|o + t·d − c|² = r² via the perpendicular foot of c on the ray. Returns (t, ambiguous)."""
    wx, wy = cx - ox, cy - oy
    dist2 = wx * wx + wy * wy
    if dist2 <= r * r:
        ambiguous = abs(math.sqrt(dist2) - r) < _EPS_INSIDE * max(1.0, r)
        return 0.0, ambiguous  # the sensor is inside the body
    tc = wx * dx + wy * dy  # along-ray coordinate of the centre
    h2 = dist2 - tc * tc  # squared distance of the centre from the ray's line
    disc = r * r - h2
    scale = max(1.0, math.sqrt(dist2))
    ambiguous = (
        abs(math.sqrt(dist2) - r) < _EPS_INSIDE * scale
        or abs(disc) < (_EPS_GRAZE * scale) ** 2
        or abs(tc) < _EPS_GRAZE * scale
    )
    if disc < 0.0 or tc <= 0.0:
        return math.inf, ambiguous
    return tc - math.sqrt(disc), ambiguous


def ref_cast(poses, circles, walls, n_beams, max_range):
    """Reference ranges (P, G) and a mask of beams that are well-conditioned."""
    p_count = poses.shape[0]
    out = np.full((p_count, n_beams), max_range)
    ok = np.ones((p_count, n_beams), dtype=bool)
    for p in range(p_count):
        ox, oy, th = (float(v) for v in poses[p])
        for b in range(n_beams):
            a = th + 2.0 * math.pi * b / n_beams
            dx, dy = math.cos(a), math.sin(a)
            best = max_range
            for seg in walls:
                t, amb = ref_ray_segment(ox, oy, dx, dy, [float(v) for v in seg])
                ok[p, b] &= not amb
                best = min(best, t)
            for cx, cy, r in circles[p]:
                if r <= 0.0:
                    continue
                t, amb = ref_ray_circle(ox, oy, dx, dy, float(cx), float(cy), float(r))
                ok[p, b] &= not amb
                best = min(best, t)
            out[p, b] = best
    return out, ok


def check_against_reference(poses, circles, walls, n_beams, max_range):
    got = cast_rays(poses, circles, walls, n_beams, max_range)
    ref, ok = ref_cast(poses, circles, walls, n_beams, max_range)
    assert got.shape == (poses.shape[0], n_beams)
    assert np.all(got >= 0.0)
    assert np.all(got <= max_range)
    np.testing.assert_allclose(got[ok], ref[ok], rtol=1e-9, atol=1e-9)
    return ok


coord = st.floats(-8.0, 8.0, allow_nan=False, allow_subnormal=False)
angle = st.floats(-4.0, 4.0, allow_nan=False, allow_subnormal=False)


@st.composite
def caster_inputs(draw):
    p = draw(st.integers(1, 3))
    c = draw(st.integers(0, 3))
    m = draw(st.integers(0, 5))
    poses = np.array([[draw(coord), draw(coord), draw(angle)] for _ in range(p)])
    radius = st.floats(-0.5, 3.0, allow_nan=False, allow_subnormal=False)
    circles = np.array(
        [[[draw(coord), draw(coord), draw(radius)] for _ in range(c)] for _ in range(p)]
    ).reshape(p, c, 3)
    walls = np.array([[draw(coord) for _ in range(4)] for _ in range(m)]).reshape(m, 4)
    n_beams = draw(st.integers(1, 48))
    max_range = draw(st.floats(0.1, 25.0, allow_nan=False))
    return poses, circles, walls, n_beams, max_range


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(caster_inputs())
def test_cast_rays_matches_brute_force(inputs):
    check_against_reference(*inputs)


def random_scenes(seed: int, count: int):
    """Seeded random scenes: (poses, circles, walls, max_range), up to 3 poses, 5 circles and
    7 walls each."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        p, c, m = rng.integers(1, 4), rng.integers(0, 6), rng.integers(0, 8)
        poses = np.column_stack([rng.uniform(-4, 4, (p, 2)), rng.uniform(-np.pi, np.pi, p)])
        circles = np.concatenate(
            [rng.uniform(-5, 5, (p, c, 2)), rng.uniform(-0.3, 1.2, (p, c, 1))], axis=-1
        )
        yield poses, circles, rng.uniform(-6, 6, (m, 4)), float(rng.uniform(2, 12))


def test_cast_rays_matches_brute_force_on_random_scenes():
    """Seeded random scenes: almost every beam is well-conditioned and must match."""
    total = compared = 0
    for poses, circles, walls, max_range in random_scenes(7, 25):
        ok = check_against_reference(poses, circles, walls, 72, max_range)
        total += ok.size
        compared += int(ok.sum())
    assert compared >= 0.98 * total


def scalar_cast(poses, circles, walls, n_beams, max_range):
    """The caster composed from the scalar primitives, beam by beam (the vectorised kernel must
    equal it bit for bit, including which hit wins)."""
    out = np.empty((poses.shape[0], n_beams))
    for p, (ox, oy, th) in enumerate(poses):
        ct, st_ = math.cos(th), math.sin(th)
        for b in range(n_beams):
            a = 2.0 * math.pi * b / n_beams
            ca, sa = math.cos(a), math.sin(a)
            dx, dy = ct * ca - st_ * sa, st_ * ca + ct * sa
            best = max_range
            for x1, y1, x2, y2 in walls:
                t = ray_segment(ox, oy, dx, dy, x1, y1, x2, y2)
                best = t if t < best else best
            for cx, cy, r in circles[p]:
                if r > 0.0:
                    t = ray_circle(ox, oy, dx, dy, cx, cy, r)
                    best = t if t < best else best
            out[p, b] = best
    return out


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(caster_inputs())
def test_cast_rays_bit_identical_to_scalar_primitives(inputs):
    got = cast_rays(*inputs)
    ref = scalar_cast(*inputs)
    assert np.array_equal(got.view(np.int64), ref.view(np.int64))


def test_cast_rays_bit_identical_on_elevator_poses():
    """Axis-aligned walls, rays through wall corners and humans touching the robot."""
    scenario = get_scenario("hr-rl")
    rng = np.random.default_rng(11)
    state = sample_state(scenario, rng)
    walls = scenario.world().walls
    lo, hi = walls[:, :2].min(axis=0), walls[:, :2].max(axis=0)
    poses = np.column_stack(
        [rng.uniform(lo, hi, (200, 2)), rng.choice(np.linspace(-np.pi, np.pi, 9), 200)]
    )
    poses[:20, :2] = walls[np.arange(20) % len(walls), :2]  # on wall end points
    one = np.concatenate([state.h_pos[0], state.h_radius[0][:, None]], axis=-1)
    circles = np.ascontiguousarray(np.broadcast_to(one, (200, *one.shape)))
    circles[20:40, 0, :2] = poses[20:40, :2]  # the sensor inside a human
    got = cast_rays(poses, circles, walls, 72, 5.0)
    assert np.array_equal(
        got.view(np.int64), scalar_cast(poses, circles, walls, 72, 5.0).view(np.int64)
    )


def test_cast_rays_square_room_exact():
    walls = np.array([(-2, -2, 2, -2), (2, -2, 2, 2), (2, 2, -2, 2), (-2, 2, -2, -2)], float)
    r = cast_rays(np.zeros((1, 3)), np.zeros((1, 0, 3)), walls, 8, 10.0)[0]
    straight = r[[0, 2, 4, 6]]
    diagonal = r[[1, 3, 5, 7]]
    np.testing.assert_allclose(straight, 2.0, atol=1e-12)
    np.testing.assert_allclose(diagonal, 2.0 * math.sqrt(2.0), atol=1e-12)


def test_cast_rays_conventions():
    walls = np.zeros((0, 4))
    pose = np.array([[0.0, 0.0, 0.0]])
    # Capped at max_range when nothing is hit.
    assert np.all(cast_rays(pose, np.zeros((1, 0, 3)), walls, 12, 3.5) == 3.5)
    # Circle straight ahead at 2 m (surface at 1.5 m): beam 0 reads 1.5; beam 6 (behind) caps.
    circ = np.array([[[2.0, 0.0, 0.5]]])
    r = cast_rays(pose, circ, walls, 12, 5.0)[0]
    assert r[0] == pytest.approx(1.5, abs=1e-12)
    assert r[6] == 5.0
    # Hits farther than max_range are capped.
    assert cast_rays(pose, circ, walls, 12, 1.0)[0, 0] == 1.0
    # A ray starting inside a circle reads 0 in every direction.
    inside = np.array([[[0.1, -0.1, 0.5]]])
    assert np.all(cast_rays(pose, inside, walls, 12, 5.0) == 0.0)
    # A radius <= 0 means the circle is absent.
    absent = np.array([[[0.1, -0.1, 0.0], [2.0, 0.0, -1.0]]])
    assert np.all(cast_rays(pose, absent, walls, 12, 5.0) == 5.0)


def test_cast_rays_heading_rotates_beams():
    """Beam b points at heading + 2πb/G, counter-clockwise."""
    walls = np.array([(3.0, -10.0, 3.0, 10.0)])  # wall x = 3
    for k, th in enumerate([0.0, math.pi / 2, math.pi, -math.pi / 2]):
        r = cast_rays(np.array([[0.0, 0.0, th]]), np.zeros((1, 0, 3)), walls, 4, 9.0)[0]
        # The beam pointing along +x is the one with (th + 2πb/4) ≡ 0, i.e. b = −k mod 4.
        b = (-k) % 4
        assert r[b] == pytest.approx(3.0, abs=1e-9)
        assert np.sum(r < 9.0) == 1


def test_cast_rays_circles_are_per_pose():
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    circles = np.array([[[2.0, 0.0, 0.5]], [[2.0, 0.0, 0.0]]])
    r = cast_rays(poses, circles, np.zeros((0, 4)), 4, 5.0)
    assert r[0, 0] == pytest.approx(1.5)
    assert r[1, 0] == 5.0


# --------------------------------------------------------------------------------------------
# The precision of the beam loops (cast_rays_into; the teacher's float32 rays)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(caster_inputs())
def test_cast_rays_into_float64_is_cast_rays_bit_for_bit(inputs):
    poses, circles, walls, n_beams, max_range = inputs
    out = np.empty((poses.shape[0], n_beams))
    got = cast_rays_into(poses, circles, walls, max_range, out)
    assert got is out
    assert np.array_equal(got.view(np.int64), cast_rays(*inputs).view(np.int64))


def test_cast_rays_into_float32_matches_brute_force():
    """Float32 beam loops on seeded random scenes: every well-conditioned beam within 1e-4 m
    of the reference (float32 keeps ~7 digits of ranges up to 12 m; the compared beams are
    at most ~100× ill-conditioned), conventions kept (capped, never negative)."""
    compared = 0
    for poses, circles, walls, max_range in random_scenes(7, 25):
        out = np.empty((poses.shape[0], 72), dtype=ray_dtype("float32"))
        got = cast_rays_into(poses, circles, walls, max_range, out)
        assert got.dtype == np.float32
        assert np.all((got >= 0.0) & (got <= np.float32(max_range)))
        ref, ok = ref_cast(poses, circles, walls, 72, max_range)
        np.testing.assert_allclose(got[ok], ref[ok], rtol=0.0, atol=1e-4)
        compared += int(ok.sum())
    assert compared > 3000


def test_ray_precision_is_checked():
    assert ray_dtype("float64") is np.float64
    with pytest.raises(ConfigError) as err:
        ray_dtype("float16")  # type: ignore[arg-type]
    assert_house_message(str(err.value), "float16", "float32")


def test_observation_from_float32_ranges_is_that_of_the_same_values_in_float64():
    """The observation kernel's float32 specialisation (the teacher's float32 rays) gives
    exactly what the float64 one gives for the same values, nearest-beam ties included."""
    rng = np.random.default_rng(5)
    ranges = rng.uniform(0.0, 5.0, (200, 72)).astype(np.float32)
    ranges[:, 7] = ranges[:, 50]  # ties between the nearest beams
    bearing = rng.uniform(-4.0, 4.0, 200)
    got = observation_from_ranges(ranges, bearing, CFG)
    want = observation_from_ranges(ranges.astype(np.float64), bearing, CFG)
    assert np.array_equal(got, want)


# --------------------------------------------------------------------------------------------
# Observation from ranges


def test_observation_names_and_config():
    names = observation_names()
    assert len(names) == OBS_DIM == CFG.obs_dim == 29
    assert names[:2] == ["r_1", "r_2"]
    assert names[23:] == ["r_24", "d_1", "d_2", "phi_1", "phi_2", "phi_goal"]
    assert CFG.n_sectors == 24


def test_beam_angles_wrapped():
    a = beam_angles(72)
    assert a[0] == 0.0
    assert a[36] == pytest.approx(math.pi)  # +π, not −π
    assert a[37] == pytest.approx(-math.pi + 2 * math.pi / 72)
    assert np.all((a > -math.pi) & (a <= math.pi))


def test_observation_from_ranges_hand_built():
    ranges = np.linspace(4.9, 1.0, 72)  # strictly decreasing: the last beams are nearest
    ranges[10] = 0.5
    ranges[40] = 0.7
    obs = observation_from_ranges(ranges, 0.25, CFG)
    assert obs.shape == (29,)
    assert obs.dtype == np.float32
    np.testing.assert_array_equal(obs[:24], sector_minima(ranges).astype(np.float32))
    assert obs[24] == np.float32(0.5)
    assert obs[25] == np.float32(0.7)
    assert obs[26] == np.float32(2 * math.pi * 10 / 72)
    assert obs[27] == np.float32(2 * math.pi * 40 / 72 - 2 * math.pi)  # 200° → −160°
    assert obs[28] == np.float32(0.25)


def test_observation_ties_keep_lowest_beam_index():
    ranges = np.full(72, 3.0)
    ranges[[50, 5, 60]] = 1.0
    obs = observation_from_ranges(ranges, 0.0, CFG)
    assert obs[24] == obs[25] == np.float32(1.0)
    assert obs[26] == np.float32(2 * math.pi * 5 / 72)
    assert obs[27] == np.float32(2 * math.pi * 50 / 72 - 2 * math.pi)


@pytest.mark.parametrize(
    ("bearing", "expected"),
    [
        (0.0, 0.0),
        (math.pi, math.pi),
        (-math.pi, math.pi),
        (1.5 * math.pi, -0.5 * math.pi),
        (-1.5 * math.pi, 0.5 * math.pi),
        (7.0, 7.0 - 2 * math.pi),
    ],
)
def test_observation_wraps_goal_bearing(bearing, expected):
    obs = observation_from_ranges(np.full(72, 2.0), bearing, CFG)
    assert obs[28] == pytest.approx(expected, abs=1e-6)


def test_observation_from_ranges_batched_and_bad_shape():
    rng = np.random.default_rng(3)
    ranges = rng.uniform(0.1, 5.0, (6, 72))
    bearings = rng.uniform(-10, 10, 6)
    batch = observation_from_ranges(ranges, bearings, CFG)
    assert batch.shape == (6, 29)
    for i in range(6):
        np.testing.assert_array_equal(
            batch[i], observation_from_ranges(ranges[i], bearings[i], CFG)
        )
    with pytest.raises(DataError) as exc:
        observation_from_ranges(np.ones(70), 0.0, CFG)
    assert_house_message(str(exc.value), "ranges")


def test_lidar_config_validation():
    with pytest.raises(ConfigError) as exc:
        LidarConfig(n_beams=70, group_size=3)
    assert_house_message(str(exc.value), "n_beams")
    with pytest.raises(ConfigError):
        LidarConfig(max_range=0.0)
    with pytest.raises(ConfigError):
        LidarConfig(n_nearest=0)
    small = LidarConfig(n_beams=36, group_size=4, n_nearest=3)
    assert small.obs_dim == 9 + 6 + 1
    assert observation_from_ranges(np.ones(36), 0.0, small).shape == (small.obs_dim,)


# --------------------------------------------------------------------------------------------
# observe(world, state) invariants


def _scenario_batch(name, seeds, n_steps, rng):
    cfg = get_scenario(name)
    world = cfg.world()
    state = concat_states([sample_state(cfg, np.random.default_rng(s)) for s in seeds])
    lo, hi = cfg.sim.robot.command_low, cfg.sim.robot.command_high
    states = [state]
    for _ in range(n_steps):
        state = step(world, state, rng.uniform(lo, hi, (state.batch_size, 2)))
        states.append(state)
    return world, states


def check_observation_invariants(world, state):
    obs = observe(world, state)
    ranges = scan(world, state)
    b = state.batch_size
    max_range = world.sim.lidar.max_range
    assert obs.shape == (b, 29)
    assert obs.dtype == np.float32
    assert np.all(np.isfinite(obs))
    assert np.all(obs[:, :26] >= 0.0)
    assert np.all(obs[:, :26] <= max_range)
    angles = obs[:, 26:]
    assert np.all(angles[:, :2] > -math.pi)  # beam angles: −175° … +180°
    assert np.all(angles <= PI32)
    assert np.all(angles[:, 2] >= -PI32)  # float32 rounding: (−π, π] becomes [−π32, π32]
    # Sector minima.
    np.testing.assert_array_equal(obs[:, :24], sector_minima(ranges).astype(np.float32))
    # Two nearest raw beams, sorted.
    two = np.sort(ranges, axis=1)[:, :2].astype(np.float32)
    np.testing.assert_array_equal(obs[:, 24:26], two)
    assert np.all(obs[:, 24] <= obs[:, 25])
    # Their angles point at beams that really have those ranges.
    for i in range(b):
        for k in range(2):
            beam = round(float(obs[i, 26 + k]) / (2 * math.pi / 72)) % 72
            assert np.float32(ranges[i, beam]) == obs[i, 24 + k]
    # Goal bearing.
    d = state.goal - state.robot[:, :2]
    expected = np.arctan2(d[:, 1], d[:, 0]) - state.robot[:, 2]
    diff = np.abs((obs[:, 28] - expected + np.pi) % (2 * np.pi) - np.pi)
    assert np.all(diff < 1e-5)
    return obs


@pytest.mark.parametrize("name", ["hr-rl", "hl-rr", "static", "hr-rl-r03"])
def test_observe_invariants_along_random_rollouts(name):
    rng = np.random.default_rng(11)
    world, states = _scenario_batch(name, range(6), 40, rng)
    for s in states[::4]:
        check_observation_invariants(world, s)


def test_observe_invariants_random_poses():
    """Robot poses anywhere, including outside the walls and inside humans."""
    rng = np.random.default_rng(5)
    cfg = get_scenario("hr-rl")
    world = cfg.world()
    base = sample_state(cfg, np.random.default_rng(0)).repeat(200)
    base.robot[:] = np.column_stack(
        [rng.uniform(-3, 3, 200), rng.uniform(-2.5, 3.5, 200), rng.uniform(-7, 7, 200)]
    )
    obs = check_observation_invariants(world, base)
    # Some robot centres end up inside a human: all beams and both nearest read 0.
    inside = (np.linalg.norm(base.h_pos - base.robot[:, None, :2], axis=-1) < base.h_radius).any(1)
    assert inside.any()
    assert np.all(obs[inside, :26] == 0.0)


@pytest.mark.parametrize(
    ("heading", "goal", "expected"),
    [
        (0.0, (0.0, 1.0), math.pi / 2),
        (0.0, (1.0, 0.0), 0.0),
        (0.0, (0.0, -1.0), -math.pi / 2),
        (0.0, (-1.0, 0.0), math.pi),  # behind → +π, not −π
        (math.pi / 2, (0.0, -2.0), math.pi),  # behind with a rotated heading
        (math.pi / 2, (1.0, 0.0), -math.pi / 2),
        (-3.0, (1.0, 1.0), math.pi / 4 + 3.0 - 2 * math.pi),
    ],
)
def test_goal_bearing_known_poses(heading, goal, expected):
    world = room_world(10.0, 10.0)
    state = make_state((0.0, 0.0, heading), goal=goal)
    obs = observe(world, state)[0]
    assert obs[28] == pytest.approx(expected, abs=1e-6)
    assert obs[28] > -math.pi
    assert goal_bearing(state)[0] == pytest.approx(expected, abs=1e-9) or (
        abs(goal_bearing(state)[0] - expected) == pytest.approx(2 * math.pi)
    )


def test_goal_straight_behind_with_tiny_negative_heading_reads_plus_pi():
    world = room_world(5.0, 5.0)
    state = make_state((0.0, 0.0, -float(np.spacing(np.pi))), goal=(-1.0, 0.0))
    obs = observe(world, state)[0]
    assert obs[28] == PI32


def test_observe_in_known_room():
    """Robot at (1, 0) facing +x in the 4 × 6 static room with no humans."""
    world = room_world(2.0, 3.0)
    state = make_state((1.0, 0.0, 0.0), goal=(0.0, 2.0))
    obs = observe(world, state)[0]
    assert obs[24] == pytest.approx(1.0)  # wall at x = 2, straight ahead
    assert obs[26] == 0.0
    assert obs[0] == pytest.approx(1.0)
    assert obs[25] == pytest.approx(1.0 / math.cos(math.radians(5)), abs=1e-6)
    assert abs(obs[27]) == pytest.approx(math.radians(5), abs=1e-6)


def test_scan_noise_needs_rng_and_stays_in_range():
    from pioneer.sim.world import SimConfig

    world = room_world(2.0, 3.0, sim=SimConfig(lidar=LidarConfig(noise_std=0.2)))
    state = make_state((1.5, 2.5, 0.3)).repeat(8)
    with pytest.raises(ConfigError):
        scan(world, state)
    a = scan(world, state, np.random.default_rng(1))
    b = scan(world, state, np.random.default_rng(1))
    c = scan(world, state, np.random.default_rng(2))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    assert np.all((a >= 0) & (a <= 5.0))


# --------------------------------------------------------------------------------------------
# Real laser-scan adapter


def _scene(seed=3):
    cfg = get_scenario("hr-rl-compact")  # the scene these tolerances were set on …
    sim = dataclasses.replace(cfg.sim, lidar=CFG)  # … observed with the default layout
    cfg = dataclasses.replace(cfg, sim=sim)
    world = cfg.world()
    state = sample_state(cfg, np.random.default_rng(seed))
    # Walk a little so humans spread out and the scan has structure.
    for _ in range(15):
        state = step(world, state, [0.3, 0.2])
    return world, state


def _circles(state):
    return np.concatenate(
        [state.h_pos, np.where(state.humans_present, state.h_radius, 0.0)[..., None]], axis=-1
    )


def _goal_robot_frame(state):
    x, y, th = state.robot[0]
    dx, dy = state.goal[0] - (x, y)
    return np.array([math.cos(th) * dx + math.sin(th) * dy, -math.sin(th) * dx + math.cos(th) * dy])


def _fine_scan(world, state, n, offset=0.0):
    """A scan of ``n`` beams starting at angle ``offset`` relative to the heading."""
    pose = state.robot.copy()
    pose[0, 2] += offset
    return cast_rays(pose, _circles(state), world.walls, n, world.sim.lidar.max_range)[0]


def assert_obs_match(got, ref, atol):
    np.testing.assert_allclose(got[:26], ref[:26], atol=atol)
    if abs(float(ref[24]) - float(ref[25])) > 2 * atol:
        np.testing.assert_allclose(got[26:28], ref[26:28], atol=1e-6)
    else:  # near-tie of the two nearest beams: their order may swap
        np.testing.assert_allclose(np.sort(got[26:28]), np.sort(ref[26:28]), atol=1e-6)
    assert got[28] == pytest.approx(float(ref[28]), abs=1e-6)


@pytest.mark.parametrize("seed", [0, 3, 8])
def test_scan_adapter_aligned_720_with_nan_and_inf(seed):
    world, state = _scene(seed)
    direct = observe(world, state)[0]
    n = 720
    ranges = _fine_scan(world, state, n)
    # Corrupt beams that are not the nearest source of any of the 72 target beams.
    bad = np.array([3, 4, 17, 101, 255, 256, 257, 444, 719])
    assert np.all(bad % 10 != 0)
    corrupted = ranges.copy()
    corrupted[bad[::2]] = np.nan
    corrupted[bad[1::2]] = np.inf
    goal = _goal_robot_frame(state)
    obs = observation_from_scan(corrupted, 0.0, 2 * math.pi / n, 5.0, goal)
    assert obs.shape == (29,)
    assert obs.dtype == np.float32
    assert_obs_match(obs, direct, atol=1e-5)
    # The beam angles are exact when the scans are aligned.
    assert np.all(np.isin(obs[26:28], beam_angles(72).astype(np.float32)))


@pytest.mark.parametrize("seed", [0, 3])
def test_scan_adapter_minus_pi_1440(seed):
    world, state = _scene(seed)
    direct = observe(world, state)[0]
    n = 1440
    ranges = _fine_scan(world, state, n, offset=-math.pi)
    ranges[[1, 2, 3, 999, 1001, 1439]] = [np.nan, np.inf, np.nan, np.inf, np.nan, np.inf]
    obs = observation_from_scan(ranges, -math.pi, 2 * math.pi / n, 5.0, _goal_robot_frame(state))
    assert_obs_match(obs, direct, atol=1e-5)


def test_scan_adapter_reversed_scan_is_identical():
    world, state = _scene(5)
    n = 720
    inc = 2 * math.pi / n
    ranges = _fine_scan(world, state, n)
    ranges[[7, 33]] = np.nan
    goal = _goal_robot_frame(state)
    forward = observation_from_scan(ranges, 0.0, inc, 5.0, goal)
    backward = observation_from_scan(ranges[::-1].copy(), (n - 1) * inc, -inc, 5.0, goal)
    np.testing.assert_array_equal(forward, backward)
    # Also for a scan that does not start at the heading.
    ranges2 = _fine_scan(world, state, n, offset=-math.pi)
    f2 = observation_from_scan(ranges2, -math.pi, inc, 5.0, goal)
    b2 = observation_from_scan(ranges2[::-1].copy(), -math.pi + (n - 1) * inc, -inc, 5.0, goal)
    np.testing.assert_array_equal(f2, b2)


def test_scan_adapter_unaligned_takes_nearest_source_beam():
    """With a scan offset by a tenth of its spacing every target reads its nearest source."""
    world, state = _scene(3)
    n = 720
    inc = 2 * math.pi / n
    offset = 0.1 * inc
    ranges = _fine_scan(world, state, n, offset=offset)
    got = resample_scan(ranges, offset, inc, 5.0, CFG)
    # The nearest source of target t is source 10·t, at heading + 2πt/72 + offset.
    expected = _fine_scan(world, state, 72, offset=offset)
    np.testing.assert_allclose(got, expected, atol=1e-9)
    # And the observation is within resampling tolerance of the direct one.
    obs = observation_from_scan(ranges, offset, inc, 5.0, _goal_robot_frame(state))
    assert_obs_match(obs, observe(world, state)[0], atol=0.05)


def test_scan_adapter_corrupted_target_source_uses_neighbour():
    world, state = _scene(3)
    n = 720
    inc = 2 * math.pi / n
    ranges = _fine_scan(world, state, n)
    r = ranges.copy()
    r[100] = np.nan  # the source of target 10: the next valid beam within tolerance is used
    got = resample_scan(r, 0.0, inc, 5.0, CFG)
    assert got[10] in (ranges[99], ranges[101])
    r[100] = np.inf  # no return → max range
    assert resample_scan(r, 0.0, inc, 5.0, CFG)[10] == 5.0
    r[100] = 7.5  # above range_max → no return → max range
    assert resample_scan(r, 0.0, inc, 6.0, CFG)[10] == 5.0
    r[100] = 0.01  # below range_min → invalid → a neighbour
    assert resample_scan(r, 0.0, inc, 5.0, CFG, range_min=0.05)[10] in (ranges[99], ranges[101])


def test_scan_adapter_coarse_scan_and_partial_coverage():
    # A 36-beam scan (10° spacing): target beams take their nearest source within 5°.
    src = np.arange(36, dtype=float) * 0.1 + 0.2
    out = resample_scan(src, 0.0, 2 * math.pi / 36, 10.0, CFG)
    assert out.shape == (72,)
    np.testing.assert_allclose(out[::2], src)
    # A 180° scan in front (−90°..+90°): beams behind are unseen, an obstacle at the robot by
    # default, max range under the optimistic rule.
    half = np.full(181, 2.0)
    angles = beam_angles(72)
    out = resample_scan(half, -math.pi / 2, math.pi / 180, 10.0, CFG)
    assert np.all(out[np.abs(angles) <= math.pi / 2 + 1e-9] == 2.0)
    assert np.all(out[np.abs(angles) > math.pi / 2 + 0.1] == 0.0)
    out = resample_scan(half, -math.pi / 2, math.pi / 180, 10.0, CFG, unseen="max_range")
    assert np.all(out[np.abs(angles) > math.pi / 2 + 0.1] == 5.0)


@pytest.mark.parametrize(("unseen", "value"), [("obstacle", 0.0), ("max_range", 5.0)])
def test_scan_adapter_all_nan_reads_the_unseen_fill(unseen, value):
    nan = np.full(360, np.nan)
    obs = observation_from_scan(nan, -math.pi, 2 * math.pi / 360, 10.0, (1, 0), None, 0.0, unseen)
    assert np.all(obs[:26] == value)
    # Ties keep the lowest beam index: beams 0 and 1.
    assert obs[26] == 0.0
    assert obs[27] == np.float32(2 * math.pi / 72)
    assert obs[28] == 0.0


def test_scan_adapter_values_capped_and_list_input():
    obs = observation_from_scan([30.0] * 72, 0.0, 2 * math.pi / 72, 40.0, (0.0, -2.0))
    assert np.all(obs[:26] == 5.0)
    assert obs[28] == pytest.approx(-math.pi / 2)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"ranges": []}, "scan.ranges"),
        ({"angle_increment": 0.0}, "scan.angle_increment"),
        ({"angle_increment": math.nan}, "scan.angle_increment"),
        ({"angle_increment": math.inf}, "scan.angle_increment"),
        ({"angle_min": math.nan}, "angle_min"),
        ({"range_max": 0.0}, "range_max"),
        ({"goal_xy_robot": (1.0, math.nan)}, "goal_xy_robot"),
        ({"goal_xy_robot": (1.0, 2.0, 3.0)}, "goal_xy_robot"),
    ],
)
def test_scan_adapter_bad_inputs(kwargs, field):
    args = {
        "ranges": np.ones(360),
        "angle_min": 0.0,
        "angle_increment": 2 * math.pi / 360,
        "range_max": 10.0,
        "goal_xy_robot": (1.0, 0.0),
    }
    args.update(kwargs)
    with pytest.raises(DataError) as exc:
        observation_from_scan(**args)
    assert_house_message(str(exc.value), field)


# --------------------------------------------------------------------------------------------
# Mirror symmetry (the centred sector layout)


def _mirror_state(state):
    """The state mirrored x → −x: positions, velocities and waypoints negate x, the heading
    θ becomes π − θ. The paper world's walls are symmetric, so the world is its own mirror."""

    def flip(a):
        a = a.copy()
        a[..., 0] = -a[..., 0]
        return a

    robot = flip(state.robot)
    robot[:, 2] = np.pi - state.robot[:, 2]
    return dataclasses.replace(
        state,
        robot=robot,
        goal=flip(state.goal),
        start=flip(state.start),
        h_pos=flip(state.h_pos),
        h_vel=flip(state.h_vel),
        h_waypoints=flip(state.h_waypoints),
        h_home=flip(state.h_home),
    )


def _segments(walls):
    """Wall segments as a set of unordered endpoint pairs (rounded to 1e-9 m)."""
    return {
        tuple(sorted(((round(x1, 9), round(y1, 9)), (round(x2, 9), round(y2, 9)))))
        for x1, y1, x2, y2 in walls.tolist()
    }


@pytest.mark.parametrize("name", ["hr-rl", "hl-rr", "static"])
def test_the_observation_of_the_mirrored_state_is_the_mirrored_observation(name):
    """observation(mirror(state)) = mirror(observation(state)): sector k ↔ (24 − k) mod 24,
    φ ↔ −φ, distances unchanged — up to float32 rounding, and to the order of two equally
    near beams."""
    from pioneer.laser import mirror_observation

    cfg = get_scenario(name)
    world = cfg.world()
    mirrored = world.walls * np.array([-1.0, 1.0, -1.0, 1.0])
    assert _segments(mirrored) == _segments(world.walls)  # the world is its own mirror image
    checked = 0
    for seed in range(6):
        state = sample_state(cfg, np.random.default_rng(seed))
        for k in range(12):
            if k:
                state = step(world, state, [0.3, 0.5 * math.sin(k + seed)])
            mirrored = _mirror_state(state)
            got = observe(world, mirrored)[0]
            want = mirror_observation(observe(world, state)[0])
            np.testing.assert_allclose(got[:26], want[:26], atol=1e-5)
            assert got[28] == pytest.approx(float(want[28]), abs=1e-5)
            # φ_1, φ_2: the same beams, unless a beam as near as d_i lies elsewhere (a tie
            # broken by beam index, which the mirror reverses): then both are nearest beams.
            beams = scan(world, mirrored)[0]
            for i in (0, 1):
                for phi in (got[26 + i], want[26 + i]):
                    b = round(float(phi) / (2 * np.pi / 72)) % 72
                    assert beams[b] == pytest.approx(float(got[24 + i]), abs=1e-5)
            checked += 1
    assert checked == 72


def test_mirroring_twice_is_the_identity_and_sector_zero_stays():
    from pioneer.laser import mirror_observation

    rng = np.random.default_rng(0)
    obs = np.concatenate(
        [rng.uniform(0, 5, (50, 26)), rng.uniform(-np.pi, np.pi, (50, 3))], axis=1
    ).astype(np.float32)
    obs[0, 26] = np.float32(np.pi)
    m = mirror_observation(obs)
    np.testing.assert_array_equal(mirror_observation(m), obs)
    np.testing.assert_array_equal(m[:, 0], obs[:, 0])  # the sector on the heading
    np.testing.assert_array_equal(m[:, 12], obs[:, 12])  # and the one behind
    np.testing.assert_array_equal(m[:, 1], obs[:, 23])
    assert m[0, 26] == np.float32(np.pi)


def test_mirroring_refuses_the_heading_first_layout():
    from pioneer.laser import mirror_observation

    with pytest.raises(ConfigError, match="centred"):
        mirror_observation(np.zeros(29), LidarConfig(sector_layout="heading_first"))
