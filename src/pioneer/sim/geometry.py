"""Geometric primitives (numba kernels): point–segment distance, swept distances, rays.

All kernels work on float64 scalars or small arrays and are compiled with ``cache=True`` so
the first import of a fresh checkout pays the compile once. Segments are rows
``(x1, y1, x2, y2)`` [m]; circles are a centre ``(cx, cy)`` and a radius [m].
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "closest_point_on_segment",
    "norm2d",
    "point_segment_distance",
    "ray_circle",
    "ray_segment",
    "segment_segment_distance",
    "swept_point_distance",
    "wall_offsets",
]


@njit(cache=True, inline="always")
def norm2d(x: float, y: float) -> float:
    """‖(x, y)‖ by a plain square root (math.hypot's overflow care costs ~4× in hot loops)."""
    return math.sqrt(x * x + y * y)


@njit(cache=True, inline="always")
def closest_point_on_segment(
    px: float, py: float, x1: float, y1: float, x2: float, y2: float
) -> tuple[float, float]:
    """Closest point to ``(px, py)`` on the segment ``(x1, y1)–(x2, y2)``.

    Branch-free (a select, not an early return), so that a loop over many segments or
    copies vectorises: a point segment (‖e‖ = 0) takes s = 0, and x1 + 0 · e is x1."""
    ex = x2 - x1
    ey = y2 - y1
    ll = ex * ex + ey * ey
    s = ((px - x1) * ex + (py - y1) * ey) / ll if ll > 0.0 else 0.0
    s = min(1.0, max(0.0, s))
    return x1 + s * ex, y1 + s * ey


@njit(cache=True, inline="always")
def wall_offsets(px: float, py: float, wall_tab: np.ndarray, out: np.ndarray) -> None:
    """Offset and distance from ``(px, py)`` to the closest point of every wall, into ``out``.

    ``wall_tab`` is ``World.wall_table`` (rows x1, y1, ex, ey, ‖e‖², padded with far point
    walls); ``out`` is ``(3, M')``: x and y of point − closest point, and its length [m]. The
    same operations as ``closest_point_on_segment`` + ``norm2d``, so the same bits, but
    branch-free on contiguous rows, so LLVM vectorises the loop.
    """
    for w in range(wall_tab.shape[1]):
        ex = wall_tab[2, w]
        ey = wall_tab[3, w]
        s = ((px - wall_tab[0, w]) * ex + (py - wall_tab[1, w]) * ey) / wall_tab[4, w]
        s = min(1.0, max(0.0, s))
        dx = px - (wall_tab[0, w] + s * ex)
        dy = py - (wall_tab[1, w] + s * ey)
        out[0, w] = dx
        out[1, w] = dy
        out[2, w] = norm2d(dx, dy)


@njit(cache=True, inline="always")
def point_segment_distance(
    px: float, py: float, x1: float, y1: float, x2: float, y2: float
) -> float:
    """Euclidean distance [m] from a point to a segment."""
    cx, cy = closest_point_on_segment(px, py, x1, y1, x2, y2)
    return norm2d(px - cx, py - cy)


@njit(cache=True, inline="always")
def _cross(ax: float, ay: float, bx: float, by: float) -> float:
    return ax * by - ay * bx


@njit(cache=True, inline="always", error_model="numpy")
def segment_segment_distance(
    ax1: float,
    ay1: float,
    ax2: float,
    ay2: float,
    bx1: float,
    by1: float,
    bx2: float,
    by2: float,
) -> float:
    """Minimum distance [m] between two segments (0 if they intersect).

    Branch-free, so that it vectorises over copies (:mod:`pioneer.sim.kernel_simd`): parallel
    segments (denominator 0) give t, u of ±inf or nan, which no interval test passes."""
    rx = ax2 - ax1
    ry = ay2 - ay1
    sx = bx2 - bx1
    sy = by2 - by1
    denom = _cross(rx, ry, sx, sy)
    qx = bx1 - ax1
    qy = by1 - ay1
    t = _cross(qx, qy, sx, sy) / denom
    u = _cross(qx, qy, rx, ry) / denom
    cross = (denom != 0.0) & (t >= 0.0) & (t <= 1.0) & (u >= 0.0) & (u <= 1.0)
    d = point_segment_distance(ax1, ay1, bx1, by1, bx2, by2)
    d = min(d, point_segment_distance(ax2, ay2, bx1, by1, bx2, by2))
    d = min(d, point_segment_distance(bx1, by1, ax1, ay1, ax2, ay2))
    d = min(d, point_segment_distance(bx2, by2, ax1, ay1, ax2, ay2))
    return 0.0 if cross else d


@njit(cache=True, inline="always")
def swept_point_distance(dx0: float, dy0: float, dx1: float, dy1: float) -> float:
    """Minimum over s ∈ [0, 1] of ‖d0 + s (d1 − d0)‖: the closest approach of two points
    that both move linearly over one interval, given their offsets at its start and end."""
    ex = dx1 - dx0
    ey = dy1 - dy0
    ll = ex * ex + ey * ey
    if ll <= 0.0:
        return norm2d(dx0, dy0)
    s = -(dx0 * ex + dy0 * ey) / ll
    s = min(1.0, max(0.0, s))
    return norm2d(dx0 + s * ex, dy0 + s * ey)


@njit(cache=True, inline="always")
def ray_segment(
    ox: float, oy: float, dx: float, dy: float, x1: float, y1: float, x2: float, y2: float
) -> float:
    """Distance along the unit ray ``o + t d`` (t ≥ 0) to the segment, or ``inf``."""
    ex = x2 - x1
    ey = y2 - y1
    denom = dx * ey - dy * ex
    if denom == 0.0:
        return np.inf
    wx = x1 - ox
    wy = y1 - oy
    t = (wx * ey - wy * ex) / denom
    s = (wx * dy - wy * dx) / denom
    if t >= 0.0 and 0.0 <= s <= 1.0:
        return t
    return np.inf


@njit(cache=True, inline="always")
def ray_circle(ox: float, oy: float, dx: float, dy: float, cx: float, cy: float, r: float) -> float:
    """Distance along the unit ray ``o + t d`` (t ≥ 0) to a circle's boundary, or ``inf``.

    A ray that starts inside the circle returns 0 (the sensor is inside an obstacle)."""
    wx = cx - ox
    wy = cy - oy
    c = wx * wx + wy * wy - r * r
    if c <= 0.0:
        return 0.0
    b = wx * dx + wy * dy
    if b <= 0.0:
        return np.inf
    disc = b * b - c
    if disc < 0.0:
        return np.inf
    return b - math.sqrt(disc)
