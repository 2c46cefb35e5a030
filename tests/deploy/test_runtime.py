"""The robot runtime's scan health, unseen-direction rule and command clipping, on the shipped
HR-RL compact student exported to ONNX; and the blind-sector study's scanner."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pioneer.data import shipped_demos, shipped_student
from pioneer.deploy import STOP_REASONS, OnnxStudentPolicy, RuntimeConfig, StudentRuntime
from pioneer.envs.env import NavEnv
from pioneer.errors import ConfigError, DataError
from pioneer.experiments.blind_sector import ScannerPolicy, scanner_message
from pioneer.laser import (
    DEFAULT_UNSEEN,
    LidarConfig,
    beam_angles,
    observation_from_scan,
    read_scan,
)
from pioneer.learn import export_onnx
from pioneer.learn.models import load_student
from pioneer.limits import OMEGA_MAX, V_MAX, V_MIN
from pioneer.reward.dataset import Dataset
from pioneer.sim.robot import RobotConfig
from pioneer_testutils import assert_house_message

torch.set_num_threads(1)

N = 360
INC = 2 * math.pi / N
GOAL = (2.0, 0.5)  # [m] robot frame


@pytest.fixture(scope="module")
def onnx_path(tmp_path_factory) -> Path:
    """The shipped HR-RL compact MDN, exported."""
    model = load_student(shipped_student("hr-rl-compact"))
    return export_onnx(model, tmp_path_factory.mktemp("rt") / "student.onnx")


@pytest.fixture(scope="module")
def rt(onnx_path) -> StudentRuntime:
    return StudentRuntime(onnx_path)


def room_scan(seed: int = 0) -> np.ndarray:
    """A plausible full 360° scan [m]: returns between 0.4 and 4 m, a few no-returns."""
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.4, 4.0, N)
    r[rng.random(N) < 0.1] = np.inf
    return r


# ------------------------------------------------------------------------------ stops
@pytest.mark.parametrize(
    ("ranges", "reason"),
    [
        (np.full(N, np.nan), "invalid"),
        (np.full(N, np.inf), "invalid"),
        (np.zeros(N), "invalid"),  # all below range_min
        (np.full(N, 0.05), "invalid"),
        (np.full(N, -np.inf), "invalid"),
    ],
    ids=["all-nan", "all-inf", "all-zero", "below-range-min", "all-minus-inf"],
)
def test_a_dead_sensor_stops_the_robot(rt, ranges, reason):
    d = rt.step(ranges, -math.pi, INC, 10.0, GOAL, range_min=0.1, age_s=0.05)
    assert (d.v, d.omega) == (0.0, 0.0)
    assert d.stop_reason == reason and d.stopped
    assert math.isnan(d.aleatoric) and math.isnan(d.epistemic)
    assert d.age_s == 0.05


def test_an_empty_room_differs_from_a_dead_sensor(rt):
    """The same all-inf scan as a dead sensor's, but one wall return: the student drives."""
    r = np.full(N, np.inf)
    r[10] = 3.0
    d = rt.step(r, -math.pi, INC, 10.0, GOAL, age_s=0.0)
    assert d.stop_reason is None and d.valid_share == 1.0
    assert d.v > 0.0


@pytest.mark.parametrize("age", [0.51, 3.0, -0.6, math.nan, math.inf])
def test_a_stale_scan_stops_the_robot(rt, age):
    d = rt.step(room_scan(), -math.pi, INC, 10.0, GOAL, age_s=age)
    assert (d.v, d.omega) == (0.0, 0.0) and d.stop_reason == "stale"
    assert d.valid_share == 1.0 and d.coverage_rad == pytest.approx(2 * math.pi)
    assert d.age_s == age or (math.isnan(age) and math.isnan(d.age_s))


def test_the_age_limit_is_configurable_and_inclusive(onnx_path):
    rt = StudentRuntime(onnx_path, config=RuntimeConfig(max_age_s=0.2))
    assert rt.step(room_scan(), -math.pi, INC, 10.0, GOAL, age_s=0.2).stop_reason is None
    assert rt.step(room_scan(), -math.pi, INC, 10.0, GOAL, age_s=-0.05).stop_reason is None
    assert rt.step(room_scan(), -math.pi, INC, 10.0, GOAL, age_s=0.25).stop_reason == "stale"
    assert RuntimeConfig().max_age_s == 0.5
    # Without an age the age is not checked, and reported as NaN.
    d = rt.step(room_scan(), -math.pi, INC, 10.0, GOAL)
    assert d.stop_reason is None and math.isnan(d.age_s)


@pytest.mark.parametrize(("share", "stops"), [(0.1, True), (0.45, True), (0.5, False)])
def test_a_sparse_scan_stops_the_robot(rt, share, stops):
    r = room_scan(1)
    bad = np.random.default_rng(2).permutation(N)[: round((1 - share) * N)]
    r[bad] = np.nan
    d = rt.step(r, -math.pi, INC, 10.0, GOAL, age_s=0.0)
    assert d.valid_share == pytest.approx(share)
    assert d.stopped is stops
    if stops:
        assert (d.v, d.omega, d.stop_reason) == (0.0, 0.0, "sparse")


def test_stop_reasons_are_checked_in_order(rt):
    """An all-NaN scan is also sparse, and stale here: the first reason is reported."""
    d = rt.step(np.full(N, np.nan), -math.pi, INC, 10.0, GOAL, age_s=9.0)
    assert d.stop_reason == "invalid" == STOP_REASONS[0]
    r = room_scan()
    r[: int(0.9 * N)] = np.nan
    assert rt.step(r, -math.pi, INC, 10.0, GOAL, age_s=9.0).stop_reason == "sparse"


def test_a_malformed_message_is_an_error_not_a_stop(rt):
    with pytest.raises(DataError) as err:
        rt.step([], -math.pi, INC, 10.0, GOAL, age_s=0.0)
    assert_house_message(str(err.value), "scan.ranges")
    with pytest.raises(DataError):
        rt.step(room_scan(), -math.pi, 0.0, 10.0, GOAL, age_s=0.0)


# ------------------------------------------------------------------------------ clipping
def test_commands_leave_clipped_to_the_robot_limits(onnx_path):
    """Raw graph actions (the shipped student's on the shipped demos, and on scans) clipped:
    the defaults are the simulated robot's, and tight limits clip both ways."""
    assert (
        RobotConfig().v_min,
        RobotConfig().v_max,
        RobotConfig().omega_max,
    ) == (V_MIN, V_MAX, OMEGA_MAX)
    rng = np.random.default_rng(0)  # the student's own world's demos, and odd scans
    odd = np.concatenate([rng.uniform(0.3, 5, (300, 26)), rng.uniform(-np.pi, np.pi, (300, 3))], 1)
    obs = np.concatenate([Dataset.load(shipped_demos("hr-rl-compact")).obs[::3], odd])
    obs = obs.astype(np.float32)
    for cfg in (RuntimeConfig(), RuntimeConfig(v_min=0.05, v_max=0.1, omega_max=0.05)):
        rt = StudentRuntime(onnx_path, config=cfg)
        raw, _, _ = rt.raw_outputs(obs)
        assert (raw[:, 0] < 0.0).any()  # the student does ask to reverse
        got = np.array([[d.v, d.omega] for d in map(rt.from_observation, obs)])
        want = np.clip(raw, [cfg.v_min, -cfg.omega_max], [cfg.v_max, cfg.omega_max])
        np.testing.assert_array_equal(got, want.astype(np.float64))
        assert (got[:, 0] >= cfg.v_min).all() and (np.abs(got[:, 1]) <= cfg.omega_max).all()
    tight = StudentRuntime(onnx_path, config=RuntimeConfig(v_max=0.01, omega_max=0.01))
    for seed in range(5):
        d = tight.step(room_scan(seed), -math.pi, INC, 10.0, GOAL, age_s=0.0)
        assert 0.0 <= d.v <= 0.01 and abs(d.omega) <= 0.01


def test_runtime_config_refuses_bad_values():
    for bad in (
        {"max_age_s": 0.0},
        {"min_valid_share": 1.5},
        {"unseen": "guess"},
        {"v_min": 1.0},
        {"omega_max": -1.0},
    ):
        with pytest.raises(ConfigError) as err:
            RuntimeConfig(**bad)
        assert_house_message(str(err.value), next(iter(bad)))


# ------------------------------------------------------------------------------ regression
def test_a_full_valid_scan_decides_as_before(rt):
    """With every direction seen, the unseen rule is moot: the observation is the one of the
    earlier rule (max_range) bit for bit, and the command is the graph's action (clipped)."""
    for seed in range(10):
        r = room_scan(seed)
        d = rt.step(r, -math.pi, INC, 10.0, GOAL, range_min=0.1, age_s=0.02)
        before = observation_from_scan(r, -math.pi, INC, 10.0, GOAL, None, 0.1, "max_range")
        np.testing.assert_array_equal(
            observation_from_scan(r, -math.pi, INC, 10.0, GOAL, None, 0.1), before
        )
        raw, ale, epi = rt.raw_outputs(before[None])
        v = min(max(float(raw[0, 0]), V_MIN), V_MAX)
        assert (d.v, d.omega) == (v, float(raw[0, 1]))
        assert (d.aleatoric, d.epistemic) == (float(ale[0]), float(epi[0]))
        assert d.stop_reason is None and d.valid_share == 1.0 and d.age_s == 0.02
        assert d.coverage_rad == pytest.approx(2 * math.pi)


# ------------------------------------------------------------------------------ unseen rule
@st.composite
def partial_scans(draw):
    """A scan of field of view 10°–350° with 0.1°–5° between beams (either direction), some
    invalid beams, the rest returns or no-returns."""
    fov = math.radians(draw(st.floats(10.0, 350.0)))
    inc = math.radians(draw(st.floats(0.1, 5.0)))
    n = max(1, int(fov / inc))
    amin = draw(st.floats(-4.0, 4.0))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.2, 8.0, n)
    r[rng.random(n) < draw(st.floats(0.0, 0.5))] = np.inf
    r[rng.random(n) < draw(st.floats(0.0, 0.3))] = np.nan
    if draw(st.booleans()):  # clockwise
        return r[::-1].copy(), amin + inc * (n - 1), -inc, amin, inc
    return r, amin, inc, amin, inc


@settings(max_examples=200, deadline=None)
@given(partial_scans())
def test_the_default_never_reports_unobserved_free_space(scan):
    """Under the default rule, a direction of the simulator's 72 with no beam of the scan
    within half a spacing (2.5°) never reads free space (max range), nor any range."""
    r, amin, inc, ccw_min, ccw_inc = scan
    cfg = LidarConfig()
    reading = read_scan(r, amin, inc, 6.0, cfg)
    assert DEFAULT_UNSEEN == "obstacle"
    # Brute force: the angular distance of every target direction to every beam.
    beams_at = ccw_min + ccw_inc * np.arange(r.size)
    d = np.abs(np.angle(np.exp(1j * (beam_angles(72)[:, None] - beams_at[None, :]))))
    no_beam = (d > math.pi / 72 + 1e-6).all(axis=1)
    assert not reading.seen[no_beam].any()
    assert (reading.beams[~reading.seen] == 0.0).all()
    assert not (reading.beams[no_beam] >= cfg.max_range).any()
    assert reading.coverage_rad == pytest.approx(reading.seen.sum() * 2 * math.pi / 72)


def test_270_degree_scanner_under_each_rule():
    cfg = LidarConfig()
    beams = np.linspace(1.0, 4.0, 72)
    beams[40] = 5.0  # free space seen at 200°: no, behind: unseen by a 270° scanner
    beams[26] = 5.0  # no return at 130°, seen: free space observed
    ranges, amin, inc = scanner_message(beams, math.radians(270), 5.0)
    assert ranges.size == 55 and amin == pytest.approx(-math.radians(135))
    assert ranges[26 + 27] == np.inf
    rear = np.abs(beam_angles(72)) > math.radians(135) + 1e-9  # 17 beams
    got = {
        u: read_scan(ranges, amin, inc, 5.0, cfg, unseen=u)
        for u in ("obstacle", "nearest", "max_range")
    }
    for u, reading in got.items():
        np.testing.assert_array_equal(reading.seen, ~rear)
        np.testing.assert_array_equal(reading.beams[~rear], beams[~rear])
        assert reading.coverage_rad == pytest.approx(math.radians(275)), u
    assert (got["obstacle"].beams[rear] == 0.0).all()
    assert (got["max_range"].beams[rear] == 5.0).all()
    # nearest: beams 28–36 take beam 27's range, 37–44 beam 45's; beam 36 is a tie (9 each
    # way) and takes the shorter.
    near = got["nearest"].beams
    assert (near[28:36] == beams[27]).all() and (near[37:45] == beams[45]).all()
    assert near[36] == min(beams[27], beams[45])
    with pytest.raises(ConfigError) as err:
        read_scan(ranges, amin, inc, 5.0, cfg, unseen="guess")
    assert_house_message(str(err.value), "unseen", "obstacle")


# ------------------------------------------------------------------------------ the study
def test_scanner_policy_with_a_full_scanner_is_the_student(onnx_path):
    """Through the simulator's scan as a LaserScan, the runtime acts exactly as the student
    on the environment's observation (clipped as the environment clips)."""
    env = NavEnv("hr-rl-compact")  # the student's world, with its heading-first sectors
    rt = StudentRuntime(onnx_path, lidar=env.world.sim.lidar)
    scanner = ScannerPolicy(rt, 2 * math.pi, "full")
    student = OnnxStudentPolicy(rt)
    obs, info = env.reset(seed=3)
    scanner.reset(info, np.random.default_rng(0))
    for _ in range(30):
        u = scanner.act(obs, info)
        np.testing.assert_array_equal(u, student.act(obs, info))
        obs, _, term, trunc, info = env.step(u)
        if term or trunc:
            break
    assert scanner.stops == {}
