"""Whether the robot still has a way to its goal among people standing where they are.

A timeout has two very different causes: a policy that hesitated while a way was open, and a
world that closed every way — in the elevator, boarders who filled the cabin's door while the
robot gave way to them. :func:`way_open` tells them apart on one state: people are frozen
where they stand (those who left the map ignored), and the robot's centre may occupy every
point at least r_r from each wall and at least r_r + r_h from each person (touching allowed,
no margin: the most generous reading). The way is open when the robot's position and the
goal region (within the goal tolerance of the goal) lie in one connected piece of that free
space.

The free space is rasterised on a square grid (``cell``, 1 cm by default) over the walls'
bounding box grown to hold the robot, its goal and a border of free cells, and its pieces are
labelled with face-connectivity (``scipy.ndimage.label``). A grid cell is free when its centre
is, so a passage's width is resolved to one cell: a gap within ``cell`` of the robot's
diameter may be read either way. The bounding box's border is open space, as in
:mod:`pioneer.eval.freepath` (the scenarios' walls close every way that matters).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

__all__ = ["CELL_M", "way_open"]

F64 = NDArray[np.float64]

CELL_M = 0.01  # [m] the grid's cell: the resolution of a passage's width


def _distance_to_segments(x: F64, y: F64, walls: F64) -> F64:
    """Least distance from the points ``(x, y)`` (any equal shapes) to the segments."""
    out = np.full(x.shape, np.inf)
    for x1, y1, x2, y2 in walls:
        dx, dy = x2 - x1, y2 - y1
        ll = dx * dx + dy * dy
        t = np.clip(((x - x1) * dx + (y - y1) * dy) / (ll if ll > 0.0 else 1.0), 0.0, 1.0)
        np.minimum(out, np.hypot(x - x1 - t * dx, y - y1 - t * dy), out=out)
    return out


@functools.lru_cache(maxsize=8)
def _grid(
    key: tuple[float, ...],
    radius: float,
    lo: tuple[float, float],
    hi: tuple[float, float],
    cell: float,
) -> tuple[F64, F64, NDArray[np.bool_]]:
    """The grid's cell centres and where the walls leave the robot's centre free (cached:
    the walls do not move)."""
    xs = np.arange(lo[0], hi[0] + cell, cell)
    ys = np.arange(lo[1], hi[1] + cell, cell)
    x, y = np.meshgrid(xs, ys, indexing="ij")
    free = _distance_to_segments(x, y, np.asarray(key, dtype=np.float64).reshape(-1, 4))
    out = (x, y, free >= radius)
    for a in out:
        a.setflags(write=False)
    return out


def _span(lo: float, hi: float, origin: float, cell: float, n: int) -> tuple[int, int]:
    """The grid indices ``[i0, i1)`` whose cell centres may lie in ``[lo, hi]``."""
    i0 = max(int(np.floor((lo - origin) / cell)), 0)
    return i0, min(int(np.ceil((hi - origin) / cell)) + 1, n)


def way_open(
    walls: F64 | Sequence[Sequence[float]],
    robot_radius: float,
    robot: F64 | Sequence[float],
    goal: F64 | Sequence[float],
    goal_tolerance: float,
    people: F64 | Sequence[Sequence[float]],
    people_radii: F64 | Sequence[float],
    cell: float = CELL_M,
) -> bool:
    """Whether the robot's centre at ``robot`` [m] can reach within ``goal_tolerance`` of
    ``goal`` keeping ``robot_radius`` from every wall segment ``(x1, y1, x2, y2)`` and
    ``robot_radius`` + r_h from every person at ``people`` (``(N, 2)``, radii ``(N,)``)."""
    w = np.asarray(walls, dtype=np.float64).reshape(-1, 4)
    p = np.asarray(people, dtype=np.float64).reshape(-1, 2)
    r_h = np.asarray(people_radii, dtype=np.float64).reshape(-1)
    s = np.asarray(robot, dtype=np.float64).reshape(2)
    g = np.asarray(goal, dtype=np.float64).reshape(2)
    pad = 2.0 * robot_radius + goal_tolerance + 2.0 * cell
    # the walls' box grown by the pad, in whole metres so that one grid serves a scenario
    # (grown further only for a robot or goal outside it)
    pts = np.vstack([w[:, :2], w[:, 2:]]) if w.shape[0] else np.vstack([s, g])
    lo = np.floor(np.minimum(pts.min(axis=0) - pad, np.minimum(s, g) - pad))
    hi = np.ceil(np.maximum(pts.max(axis=0) + pad, np.maximum(s, g) + pad))
    key = tuple(map(float, w.ravel()))
    x, y, walls_free = _grid(
        key,
        float(robot_radius),
        (float(lo[0]), float(lo[1])),
        (float(hi[0]), float(hi[1])),
        float(cell),
    )
    free = walls_free.copy()
    x0, y0 = x[0, 0], y[0, 0]
    for (cx, cy), rh in zip(p, r_h, strict=True):  # each person's window of the grid only
        reach = robot_radius + rh
        i0, i1 = _span(cx - reach, cx + reach, x0, cell, x.shape[0])
        j0, j1 = _span(cy - reach, cy + reach, y0, cell, x.shape[1])
        if i0 < i1 and j0 < j1:
            win = (slice(i0, i1), slice(j0, j1))
            free[win] &= np.hypot(x[win] - cx, y[win] - cy) >= reach
    labels, _ = ndimage.label(free)

    def pieces(c: F64, within: float) -> set[int]:
        i0, i1 = _span(c[0] - within, c[0] + within, x0, cell, x.shape[0])
        j0, j1 = _span(c[1] - within, c[1] + within, y0, cell, x.shape[1])
        win = (slice(i0, i1), slice(j0, j1))
        near = (np.hypot(x[win] - c[0], y[win] - c[1]) <= within) & free[win]
        return set(np.unique(labels[win][near]).tolist()) - {0}

    # the robot's piece: the free cells within a cell's diagonal of its centre (its own cell
    # may read as blocked by rounding when it stands touching a person or a wall)
    return bool(pieces(s, 1.5 * cell) & pieces(g, goal_tolerance))
