"""Unicycle robot: exact integration, angle wrapping, command validation and clipping."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pioneer.errors import CommandError, ConfigError
from pioneer.sim.robot import (
    RobotConfig,
    clip_command,
    integrate_unicycle,
    validate_command,
    wrap_angle,
)
from pioneer_testutils import angle_diff, assert_house_message

PROP = settings(max_examples=80, deadline=None)
pos = st.floats(-20.0, 20.0, allow_nan=False, allow_subnormal=False)
heading = st.floats(-math.pi, math.pi, allow_nan=False, allow_subnormal=False)
speed = st.floats(0.0, 0.8, allow_nan=False, allow_subnormal=False)
omega = st.floats(-0.4 * math.pi, 0.4 * math.pi, allow_nan=False, allow_subnormal=False)
duration = st.floats(0.0, 3.0, allow_nan=False, allow_subnormal=False)


def rk4_unicycle(x, y, th, v, w, h, n=2000):
    """Reference: classical Runge–Kutta on ṗx = v cos θ, ṗy = v sin θ, θ̇ = ω."""

    def f(s):
        return np.array([v * math.cos(s[2]), v * math.sin(s[2]), w])

    s = np.array([x, y, th], dtype=float)
    dt = h / n
    for _ in range(n):
        k1 = f(s)
        k2 = f(s + dt / 2 * k1)
        k3 = f(s + dt / 2 * k2)
        k4 = f(s + dt * k3)
        s = s + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return s


# --------------------------------------------------------------------------------------------
# wrap_angle


@pytest.mark.parametrize(
    ("a", "expected"),
    [
        (0.0, 0.0),
        (math.pi, math.pi),
        (-math.pi, math.pi),  # −π maps to +π: the interval is (−π, π]
        (3 * math.pi, math.pi),
        (-3 * math.pi, math.pi),
        (2 * math.pi, 0.0),
        (1.5 * math.pi, -0.5 * math.pi),
        (-1.5 * math.pi, 0.5 * math.pi),
    ],
)
def test_wrap_angle_known_values(a, expected):
    assert wrap_angle(a) == pytest.approx(expected, abs=1e-12)


@PROP
@given(st.floats(-1e4, 1e4, allow_nan=False, allow_subnormal=False))
def test_wrap_angle_range_and_congruence(a):
    w = wrap_angle(a)
    assert -math.pi <= w <= math.pi
    assert angle_diff(w, a) < 1e-9
    assert wrap_angle(w) == pytest.approx(w, abs=1e-12)  # idempotent


def test_wrap_angle_never_returns_minus_pi():
    a = float(np.nextafter(math.pi, 4.0))  # π + 1 ulp, e.g. atan2(+0, −1) − (−1e−16)
    assert wrap_angle(a) > -math.pi


# --------------------------------------------------------------------------------------------
# integrate_unicycle


def test_straight_line_when_omega_is_zero():
    x, y, th = integrate_unicycle(1.0, 2.0, math.pi / 6, 0.8, 0.0, 2.5)
    assert x == pytest.approx(1.0 + 2.0 * math.cos(math.pi / 6), abs=1e-12)
    assert y == pytest.approx(2.0 + 2.0 * math.sin(math.pi / 6), abs=1e-12)
    assert th == math.pi / 6


@pytest.mark.parametrize("w", [1e-12, 3e-9, 1e-6, 2e-4])
def test_tiny_omega_is_continuous_with_straight_line(w):
    straight = integrate_unicycle(0.0, 0.0, 0.3, 0.7, 0.0, 1.0)
    turning = integrate_unicycle(0.0, 0.0, 0.3, 0.7, w, 1.0)
    # The arc deviates from the line by about v·h²·ω/2; nothing else (no cancellation error).
    assert np.allclose(straight[:2], turning[:2], atol=0.7 * w / 2 + 1e-15)


def test_full_circle_returns_to_start():
    v, w = 0.5, 0.4 * math.pi
    period = 2 * math.pi / w
    x, y, th = integrate_unicycle(1.0, -2.0, 0.7, v, w, period)
    assert x == pytest.approx(1.0, abs=1e-9)
    assert y == pytest.approx(-2.0, abs=1e-9)
    assert angle_diff(th, 0.7) < 1e-9


def test_half_circle_displacement_is_diameter():
    v, w = 0.6, 0.3
    x, y, th = integrate_unicycle(0.0, 0.0, 0.0, v, w, math.pi / w)
    # Heading 0, turning left: the centre is at (0, v/ω); half a turn later we are at (0, 2v/ω).
    assert x == pytest.approx(0.0, abs=1e-9)
    assert y == pytest.approx(2 * v / w, abs=1e-9)
    assert abs(th) == pytest.approx(math.pi, abs=1e-9)


@PROP
@given(pos, pos, heading, speed, omega, duration)
def test_integration_matches_rk4(x, y, th, v, w, h):
    got = integrate_unicycle(x, y, th, v, w, h)
    ref = rk4_unicycle(x, y, th, v, w, h, n=200)
    assert got[0] == pytest.approx(ref[0], abs=1e-7)
    assert got[1] == pytest.approx(ref[1], abs=1e-7)
    assert angle_diff(got[2], ref[2]) < 1e-9
    assert -math.pi < got[2] <= math.pi


@PROP
@given(pos, pos, heading, speed, omega, duration, duration)
def test_integration_composes(x, y, th, v, w, h1, h2):
    """Exact integration: h1 then h2 equals h1 + h2 (a 0.3 s rollout = three 0.1 s steps)."""
    a = integrate_unicycle(*integrate_unicycle(x, y, th, v, w, h1), v, w, h2)
    b = integrate_unicycle(x, y, th, v, w, h1 + h2)
    assert a[0] == pytest.approx(b[0], abs=1e-9)
    assert a[1] == pytest.approx(b[1], abs=1e-9)
    assert angle_diff(a[2], b[2]) < 1e-9


@PROP
@given(pos, pos, heading, speed, omega, duration)
def test_speed_is_preserved_along_arc(x, y, th, v, w, h):
    """The chord is never longer than the arc v·h, and equals it for a straight line."""
    x1, y1, _ = integrate_unicycle(x, y, th, v, w, h)
    chord = math.hypot(x1 - x, y1 - y)
    assert chord <= v * h + 1e-9
    if abs(w * h) < 1e-6:
        assert chord == pytest.approx(v * h, abs=1e-6)


# --------------------------------------------------------------------------------------------
# commands


def test_validate_command_accepts_single_and_batch():
    assert validate_command([0.1, 0.2], 1).shape == (1, 2)
    assert validate_command(np.zeros((4, 2)), 4).shape == (4, 2)
    assert validate_command(np.zeros((4, 2)), 4).dtype == np.float64


@pytest.mark.parametrize(
    ("u", "batch"),
    [
        ([0.1, math.nan], 1),
        ([math.inf, 0.0], 1),
        (np.zeros(3), 1),
        (np.zeros((2, 2)), 3),
        ([0.1, 0.2], 2),
    ],
)
def test_validate_command_rejects(u, batch):
    with pytest.raises(CommandError) as exc:
        validate_command(u, batch)
    assert_house_message(str(exc.value), "command")


def test_clip_command_limits():
    cfg = RobotConfig()
    u = np.array([[-1.0, -5.0], [0.4, 0.1], [3.0, 5.0]])
    c = clip_command(u, cfg)
    assert np.array_equal(c[0], [0.0, -0.4 * math.pi])
    assert np.array_equal(c[1], [0.4, 0.1])
    assert np.array_equal(c[2], [0.8, 0.4 * math.pi])


def test_robot_config_validation():
    with pytest.raises(ConfigError) as exc:
        RobotConfig(radius=0.0)
    assert_house_message(str(exc.value), "radius")
    with pytest.raises(ConfigError) as exc:
        RobotConfig(v_min=0.5, v_max=0.2)
    assert_house_message(str(exc.value), "v_min")
    assert np.array_equal(RobotConfig().command_low, [0.0, -0.4 * math.pi])
    assert np.array_equal(RobotConfig().command_high, [0.8, 0.4 * math.pi])
