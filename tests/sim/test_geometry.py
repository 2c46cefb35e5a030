"""Geometric kernels against first-principles references (pure Python floats)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pioneer.sim.geometry import (
    closest_point_on_segment,
    point_segment_distance,
    ray_circle,
    ray_segment,
    segment_segment_distance,
    swept_point_distance,
    wall_offsets,
)
from pioneer.sim.world import WALL_LANES, wall_soa

coord = st.floats(-10.0, 10.0, allow_nan=False, allow_infinity=False, allow_subnormal=False)
PROP = settings(max_examples=80, deadline=None)


def ref_point_segment(px, py, x1, y1, x2, y2):
    """Distance from a point to a segment: minimise the quadratic |a + s e − p|² over [0, 1]."""
    ex, ey = x2 - x1, y2 - y1
    ll = ex * ex + ey * ey
    cands = [0.0, 1.0]
    if ll > 0:
        s = ((px - x1) * ex + (py - y1) * ey) / ll
        if 0.0 < s < 1.0:
            cands.append(s)
    return min(math.hypot(x1 + s * ex - px, y1 + s * ey - py) for s in cands)


def orient(ax, ay, bx, by, cx, cy):
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


def segments_cross(a, b):
    """Strict proper crossing of two segments (orientation test)."""
    o1 = orient(*a[:2], *a[2:], *b[:2])
    o2 = orient(*a[:2], *a[2:], *b[2:])
    o3 = orient(*b[:2], *b[2:], *a[:2])
    o4 = orient(*b[:2], *b[2:], *a[2:])
    return o1 * o2 < 0 and o3 * o4 < 0


def ref_segment_segment(a, b):
    if segments_cross(a, b):
        return 0.0
    return min(
        ref_point_segment(*a[:2], *b),
        ref_point_segment(*a[2:], *b),
        ref_point_segment(*b[:2], *a),
        ref_point_segment(*b[2:], *a),
    )


# --------------------------------------------------------------------------------------------
# point / segment


def test_closest_point_on_segment_known_values():
    assert closest_point_on_segment(0.5, 3.0, 0.0, 0.0, 1.0, 0.0) == pytest.approx((0.5, 0.0))
    assert closest_point_on_segment(-2.0, 1.0, 0.0, 0.0, 1.0, 0.0) == pytest.approx((0.0, 0.0))
    assert closest_point_on_segment(5.0, -1.0, 0.0, 0.0, 1.0, 0.0) == pytest.approx((1.0, 0.0))
    # A degenerate segment is its single point.
    assert closest_point_on_segment(3.0, 4.0, 1.0, 1.0, 1.0, 1.0) == (1.0, 1.0)


def test_point_segment_distance_known_values():
    assert point_segment_distance(0.0, 2.0, -1.0, 0.0, 1.0, 0.0) == pytest.approx(2.0)
    assert point_segment_distance(4.0, 4.0, -1.0, 0.0, 1.0, 0.0) == pytest.approx(5.0)
    assert point_segment_distance(0.3, 0.0, -1.0, 0.0, 1.0, 0.0) == pytest.approx(0.0, abs=1e-15)


@PROP
@given(coord, coord, coord, coord, coord, coord)
def test_point_segment_distance_matches_reference(px, py, x1, y1, x2, y2):
    got = point_segment_distance(px, py, x1, y1, x2, y2)
    ref = ref_point_segment(px, py, x1, y1, x2, y2)
    assert got == pytest.approx(ref, rel=1e-9, abs=1e-9)
    cx, cy = closest_point_on_segment(px, py, x1, y1, x2, y2)
    # The closest point is on the segment (inside its bounding box) and realises the distance.
    assert min(x1, x2) - 1e-9 <= cx <= max(x1, x2) + 1e-9
    assert min(y1, y2) - 1e-9 <= cy <= max(y1, y2) + 1e-9
    assert math.hypot(px - cx, py - cy) == pytest.approx(ref, rel=1e-9, abs=1e-9)


# --------------------------------------------------------------------------------------------
# segment / segment


@PROP
@given(
    st.lists(st.tuples(coord, coord, coord, coord), min_size=0, max_size=9),
    coord,
    coord,
    st.booleans(),
)
def test_wall_offsets_equal_the_scalar_primitive_bit_for_bit(walls, px, py, point_wall):
    """The padded wall table + vectorised loop give closest_point_on_segment's exact bits."""
    if point_wall and walls:  # a degenerate (point-like) wall
        walls[0] = (walls[0][0], walls[0][1], walls[0][0], walls[0][1])
    arr = np.asarray(walls, dtype=np.float64).reshape(-1, 4)
    table = wall_soa(arr)
    assert table.shape[1] % WALL_LANES == 0 and table.shape[1] >= max(1, len(walls))
    out = np.full((3, table.shape[1]), np.nan)
    wall_offsets(px, py, table, out)
    for k, (x1, y1, x2, y2) in enumerate(walls):
        cx, cy = closest_point_on_segment(px, py, x1, y1, x2, y2)
        assert out[0, k] == px - cx and out[1, k] == py - cy
        assert out[2, k] == point_segment_distance(px, py, x1, y1, x2, y2)
    # the padding walls are never in range of a force and never the nearest wall
    assert np.all(out[2, len(walls) :] > 1e11)


def test_segment_segment_distance_known_values():
    # Crossing diagonals.
    assert segment_segment_distance(-1, -1, 1, 1, -1, 1, 1, -1) == 0.0
    # Parallel, 2 m apart.
    assert segment_segment_distance(0, 0, 1, 0, 0, 2, 1, 2) == pytest.approx(2.0)
    # T-shape just not touching.
    assert segment_segment_distance(0, 0, 0, 1, -1, 1.5, 1, 1.5) == pytest.approx(0.5)
    # Collinear, overlapping.
    assert segment_segment_distance(0, 0, 2, 0, 1, 0, 3, 0) == 0.0
    # Collinear, disjoint.
    assert segment_segment_distance(0, 0, 1, 0, 3, 0, 4, 0) == pytest.approx(2.0)


@PROP
@given(st.tuples(coord, coord, coord, coord), st.tuples(coord, coord, coord, coord))
def test_segment_segment_distance_matches_reference(a, b):
    got = segment_segment_distance(*a, *b)
    ref = ref_segment_segment(a, b)
    assert got >= 0.0
    assert got == pytest.approx(ref, rel=1e-9, abs=1e-9)
    assert got == pytest.approx(segment_segment_distance(*b, *a), rel=1e-9, abs=1e-9)


@PROP
@given(coord, coord, coord, coord, coord, coord)
def test_segment_segment_distance_of_point_segment(px, py, x1, y1, x2, y2):
    """A zero-length segment is a point."""
    got = segment_segment_distance(px, py, px, py, x1, y1, x2, y2)
    assert got == pytest.approx(ref_point_segment(px, py, x1, y1, x2, y2), rel=1e-9, abs=1e-9)


# --------------------------------------------------------------------------------------------
# swept distance of two linearly moving points


@PROP
@given(coord, coord, coord, coord)
def test_swept_point_distance_is_min_over_interval(dx0, dy0, dx1, dy1):
    got = swept_point_distance(dx0, dy0, dx1, dy1)
    # Reference: the relative offset moves on the segment d0 → d1; its distance to the origin.
    ref = ref_point_segment(0.0, 0.0, dx0, dy0, dx1, dy1)
    assert got == pytest.approx(ref, rel=1e-9, abs=1e-9)
    # Never larger than the end-point distances, never smaller than a dense sampling minimum.
    s = np.linspace(0.0, 1.0, 2001)
    dense = np.hypot(dx0 + s * (dx1 - dx0), dy0 + s * (dy1 - dy0)).min()
    assert got <= min(math.hypot(dx0, dy0), math.hypot(dx1, dy1)) + 1e-12
    assert got <= dense + 1e-12
    assert dense - got <= math.hypot(dx1 - dx0, dy1 - dy0) / 2000 + 1e-12


def test_swept_point_distance_detects_pass_through():
    # Starts 1 m below, ends 1 m above: passes exactly through the origin.
    assert swept_point_distance(0.0, -1.0, 0.0, 1.0) == 0.0
    # Both ends 1 m away, closest approach 0.25 m halfway.
    assert swept_point_distance(-1.0, 0.25, 1.0, 0.25) == pytest.approx(0.25)
    # No relative motion.
    assert swept_point_distance(3.0, 4.0, 3.0, 4.0) == pytest.approx(5.0)


# --------------------------------------------------------------------------------------------
# rays


def test_ray_segment_known_values():
    # Ray along +x hits the vertical segment x = 2.
    assert ray_segment(0.0, 0.0, 1.0, 0.0, 2.0, -1.0, 2.0, 1.0) == pytest.approx(2.0)
    # Pointing away.
    assert ray_segment(0.0, 0.0, -1.0, 0.0, 2.0, -1.0, 2.0, 1.0) == math.inf
    # Passing beside the segment.
    assert ray_segment(0.0, 0.0, 1.0, 0.0, 2.0, 0.5, 2.0, 1.0) == math.inf
    # Parallel.
    assert ray_segment(0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 5.0, 1.0) == math.inf
    # Hitting an end point exactly counts.
    assert ray_segment(0.0, 0.0, 1.0, 0.0, 2.0, 0.0, 2.0, 1.0) == pytest.approx(2.0)


def test_ray_circle_known_values():
    assert ray_circle(0.0, 0.0, 1.0, 0.0, 3.0, 0.0, 1.0) == pytest.approx(2.0)
    assert ray_circle(0.0, 0.0, -1.0, 0.0, 3.0, 0.0, 1.0) == math.inf
    assert ray_circle(0.0, 0.0, 0.0, 1.0, 3.0, 0.0, 1.0) == math.inf
    # Starting inside: 0 whatever the direction.
    assert ray_circle(0.0, 0.0, 0.0, -1.0, 0.2, 0.1, 1.0) == 0.0
    # Tangent ray touches.
    assert ray_circle(0.0, 0.0, 1.0, 0.0, 3.0, 1.0, 1.0) == pytest.approx(3.0)
