"""pioneer.laser (numpy, robot side) against the simulator's numba observation and a
brute-force resampling oracle, and its import hygiene."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pioneer import laser
from pioneer.laser import DEFAULT_UNSEEN, UNSEEN_RULES, LidarConfig, resample_scan, wrap_angles
from pioneer.sim.lidar import observation_from_ranges
from pioneer.sim.robot import wrap_angle

CONFIGS = [
    LidarConfig(),
    LidarConfig(n_beams=36, group_size=4, n_nearest=3),
    LidarConfig(n_beams=8, group_size=1, n_nearest=8),
]


@st.composite
def beams_and_bearing(draw):
    cfg = draw(st.sampled_from(CONFIGS))
    # few distinct values, so equal ranges (ties for the nearest beams) are common
    levels = draw(st.lists(st.floats(0.0, 6.0), min_size=1, max_size=4))
    beams = np.array(
        draw(st.lists(st.sampled_from(levels), min_size=cfg.n_beams, max_size=cfg.n_beams))
    )
    bearing = draw(st.one_of(st.floats(-20.0, 20.0), st.sampled_from([math.pi, -math.pi, 0.0])))
    return cfg, beams, bearing


@settings(max_examples=300, deadline=None)
@given(beams_and_bearing())
def test_observation_equals_numba_kernel_bit_for_bit(case):
    cfg, beams, bearing = case
    got = laser._observation_one(beams, bearing, cfg)
    want = observation_from_ranges(beams, bearing, cfg)
    assert got.dtype == np.float32 and got.shape == (cfg.obs_dim,)
    np.testing.assert_array_equal(got, want)


@settings(max_examples=300, deadline=None)
@given(st.floats(-1e3, 1e3))
def test_wrap_angles_equals_scalar_kernel(a):
    assert float(wrap_angles(a)) == wrap_angle(a)
    assert -math.pi < float(wrap_angles(a)) <= math.pi


def oracle_resample(r, amin, inc, range_max, cfg, range_min=0.0, unseen="obstacle"):
    """Each target beam reads the nearest valid source beam within the tolerance, by brute
    force over every source beam. Exact ties go to the source in the first search window
    (around the target's position u + k·period, k = 0, −1, 1, 2, …) that holds it, then to
    the lower index. A target beam without one reads 0 (``obstacle``), ``max_range``, or
    (``nearest``) the shorter range of the circularly nearest target beams that have one."""
    r = np.asarray(r, dtype=float)
    if inc < 0:
        r = r[::-1]
        amin, inc = amin + inc * (r.size - 1), -inc
    tol = max(math.pi / cfg.n_beams, 0.5 * inc) + 1e-9
    w = math.ceil(tol / inc) + 1
    out = np.full(cfg.n_beams, cfg.max_range if unseen == "max_range" else 0.0)
    seen = np.zeros(cfg.n_beams, dtype=bool)
    for t in range(cfg.n_beams):
        a = 2.0 * math.pi * t / cfg.n_beams
        u = ((a - amin) % (2.0 * math.pi)) / inc
        period = 2.0 * math.pi / inc
        turns = [0, -1, *range(1, math.ceil(r.size / period) + 1)]
        starts = [math.floor(u if k == 0 else u + k * period) - w for k in turns]
        best = (math.inf, len(turns), 0)
        for s, x in enumerate(r):
            no_return = x == math.inf or (math.isfinite(x) and x > range_max)
            if not ((math.isfinite(x) and x >= range_min) or no_return):
                continue
            d = abs(wrap_angle(a - (amin + s * inc)))
            window = next((i for i, c in enumerate(starts) if c <= s <= c + 2 * w + 1), len(turns))
            key = (d, window, s)
            if d <= tol and key < best:
                best = key
                seen[t] = True
                out[t] = cfg.max_range if no_return else min(x, cfg.max_range)
    if unseen == "nearest" and seen.any():
        g = cfg.n_beams
        filled = out.copy()
        for t in np.flatnonzero(~seen):
            dist = {s: min(abs(t - s), g - abs(t - s)) for s in np.flatnonzero(seen)}
            closest = min(dist.values())
            filled[t] = min(out[s] for s, dd in dist.items() if dd == closest)
        out = filled
    return out


@st.composite
def scans(draw):
    n = draw(st.integers(1, 250))
    inc = draw(st.one_of(st.floats(0.002, 0.3), st.sampled_from([2 * math.pi / max(n, 1)])))
    inc = -inc if draw(st.booleans()) else inc
    amin = draw(st.floats(-4.0, 4.0))
    r = np.array(
        draw(
            st.lists(
                st.one_of(st.floats(-1.0, 10.0), st.sampled_from([math.nan, math.inf, -math.inf])),
                min_size=n,
                max_size=n,
            )
        )
    )
    return r, amin, inc, draw(st.sampled_from([5.0, 6.0])), draw(st.sampled_from([0.0, 0.1]))


@settings(max_examples=100, deadline=None)
@given(scans(), st.sampled_from(UNSEEN_RULES))
def test_resample_matches_brute_force(scan, unseen):
    r, amin, inc, rmax, rmin = scan
    cfg = LidarConfig()
    np.testing.assert_array_equal(
        resample_scan(r, amin, inc, rmax, cfg, rmin, unseen),
        oracle_resample(r, amin, inc, rmax, cfg, rmin, unseen),
    )
    if unseen == DEFAULT_UNSEEN:
        np.testing.assert_array_equal(
            resample_scan(r, amin, inc, rmax, cfg, rmin),
            oracle_resample(r, amin, inc, rmax, cfg, rmin),
        )


def test_resample_scan_of_more_than_one_turn_sees_the_second_pass():
    """27 beams 0.25 rad apart cover 6.75 rad: the last one (6.5 rad ≡ 0.217 rad) is the
    nearest source of target beam 2 (0.175 rad), nearer than beam 1 (0.25 rad)."""
    r = np.zeros(27)
    r[-1] = 1.0
    out = resample_scan(r, 0.0, 0.25, 5.0, LidarConfig())
    assert out[2] == 1.0
    assert out[1] == 0.0  # 0.087 rad: beam 0 (0.087 away) beats beam 26 (0.13 away)


def test_resample_is_reentrant_across_geometries():
    """The per-geometry table cache never leaks one scan's geometry into another's."""
    cfg = LidarConfig()
    rng = np.random.default_rng(0)
    scans = [(rng.uniform(0.2, 5, n), a, 2 * math.pi / n) for n, a in ((360, -math.pi), (720, 0.3))]
    first = [resample_scan(r, a, i, 6.0, cfg) for r, a, i in scans]
    again = [resample_scan(r, a, i, 6.0, cfg) for r, a, i in reversed(scans)][::-1]
    for x, y in zip(first, again, strict=True):
        np.testing.assert_array_equal(x, y)


def test_import_loads_neither_numba_nor_the_simulator():
    code = (
        "import sys, pioneer.laser, pioneer.deploy; "
        "print(sorted(m for m in ('numba', 'pioneer.sim', 'torch') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
