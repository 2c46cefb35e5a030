"""The shortest free path of the robot, a disc of radius r, from its start to its goal among
the walls: the reference length of SPL and path efficiency (docs/metrics.md).

A disc of radius r avoids a wall segment exactly when its centre stays at least r from the
segment, i.e. outside the segment's *capsule* (the segment grown by r). A shortest path among
capsules is made of straight pieces tangent to the discs of radius r around the walls' end
points and of arcs around those end points. Each such disc is replaced by the regular
``sides``-gon circumscribed about it (its edges touch the disc); the nodes of a visibility
graph are the corners of those polygons that keep the clearance r from every wall, and its
edges the straight pieces between nodes that keep it too. The shortest path in that graph is
at least the true shortest free path (each of its pieces is free) and at most the shortest
path around the polygons, which is longer than the true one only along the arcs, by a factor
1/cos(π/sides) at most (≈ 0.5 % on the arcs for 32 sides, far less on a whole path).

The graph of a map (walls, radius) is built once and cached, with its all-pairs shortest
paths (``scipy.sparse.csgraph``), so one episode's start and goal cost only their visibility
to the nodes and a minimum over node pairs. Open map sides are open: the path may leave the
map's bounds (the scenarios' walls close every way that matters).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.sparse.csgraph import shortest_path

__all__ = ["FreePath", "FreeSpace", "free_space", "segment_distances", "shortest_free_path"]

F64 = NDArray[np.float64]

SIDES = 32  # corners of the polygon around each wall end point
_TOL = 1e-9  # [m] a piece touching a capsule (a polygon edge) counts as free


def _point_segment(p: F64, a: F64, b: F64) -> F64:
    """Distances ``(K, M)`` from points ``p (K, 2)`` to segments ``a → b`` (each ``(M, 2)``)."""
    e = b - a  # (M, 2)
    ll = np.einsum("ij,ij->i", e, e)
    d = p[:, None, :] - a[None, :, :]  # (K, M, 2)
    s = np.clip(np.einsum("kmj,mj->km", d, e) / np.where(ll > 0.0, ll, 1.0), 0.0, 1.0)
    q = d - s[..., None] * e[None, :, :]
    return np.sqrt(np.einsum("kmj,kmj->km", q, q))


def _point_to_pieces(p: F64, a: F64, b: F64) -> F64:
    """Distances ``(K, M)`` from points ``p (M, 2)`` to pieces ``a → b`` (each ``(K, 2)``)."""
    e = b - a  # (K, 2)
    ll = np.einsum("ij,ij->i", e, e)
    d = p[None, :, :] - a[:, None, :]  # (K, M, 2)
    s = np.clip(np.einsum("kmj,kj->km", d, e) / np.where(ll > 0.0, ll, 1.0)[:, None], 0.0, 1.0)
    q = d - s[..., None] * e[:, None, :]
    return np.sqrt(np.einsum("kmj,kmj->km", q, q))


def segment_distances(p0: F64, p1: F64, walls: F64) -> F64:
    """Least distances ``(K, M)`` between pieces ``p0 → p1`` (each ``(K, 2)``) and wall
    segments ``walls (M, 4)``: 0 where they cross, else the least of the four end-point-to-
    segment distances."""
    a, b = walls[:, :2], walls[:, 2:]
    d = np.minimum(_point_segment(p0, a, b), _point_segment(p1, a, b))
    d = np.minimum(d, np.minimum(_point_to_pieces(a, p0, p1), _point_to_pieces(b, p0, p1)))

    def cross(o: F64, u: F64, v: F64) -> F64:  # z of (u − o) × (v − o), broadcast (K, M)
        return (u[..., 0] - o[..., 0]) * (v[..., 1] - o[..., 1]) - (u[..., 1] - o[..., 1]) * (
            v[..., 0] - o[..., 0]
        )

    q0, q1 = p0[:, None, :], p1[:, None, :]
    wa, wb = a[None, :, :], b[None, :, :]
    d1, d2 = cross(q0, q1, wa), cross(q0, q1, wb)
    d3, d4 = cross(wa, wb, q0), cross(wa, wb, q1)
    crossing = (d1 * d2 < 0.0) & (d3 * d4 < 0.0)
    return np.where(crossing, 0.0, d)


def _free(p0: F64, p1: F64, walls: F64, clearance: F64 | float) -> NDArray[np.bool_]:
    """Which pieces ``p0 → p1`` keep ``clearance`` (per piece or one value) from every wall."""
    if walls.shape[0] == 0:
        return np.ones(p0.shape[0], dtype=np.bool_)
    out = np.empty(p0.shape[0], dtype=np.bool_)
    clear = np.broadcast_to(np.asarray(clearance, dtype=np.float64), (p0.shape[0],))
    for lo in range(0, p0.shape[0], 4096):  # bounded memory: (chunk, M, 2) temporaries
        hi = lo + 4096
        d = segment_distances(p0[lo:hi], p1[lo:hi], walls)
        out[lo:hi] = d.min(axis=1) >= clear[lo:hi] - _TOL
    return out


@dataclasses.dataclass(frozen=True, eq=False)
class FreeSpace:
    """The visibility graph of a map for a disc of ``radius``: its free ``nodes``, the
    shortest path lengths between them and their predecessors (all pairs)."""

    walls: F64  # (M, 4) [m]
    radius: float  # [m]
    nodes: F64  # (V, 2) [m]
    dist: F64  # (V, V) [m] shortest path lengths between nodes (inf: not connected)
    pred: NDArray[np.int32]  # (V, V) predecessor of j on the shortest path from i (−9999: none)


@dataclasses.dataclass(frozen=True)
class FreePath:
    """A shortest free path: its length and its corners from start to goal."""

    length: float  # [m] (inf: the goal cannot be reached)
    points: F64  # (P, 2) [m] start, the corners passed, goal (empty when unreachable)

    def turning(self, heading: float) -> float:
        """The least rotation [rad] to follow the path from ``heading``: turning to its first
        piece, then at each corner (Σ of absolute turning angles)."""
        if self.points.shape[0] < 2:
            return 0.0
        d = np.diff(self.points, axis=0)
        keep = np.hypot(d[:, 0], d[:, 1]) > 1e-12
        angles = np.arctan2(d[keep, 1], d[keep, 0])
        if angles.size == 0:
            return 0.0
        turns = np.diff(np.concatenate([[heading], angles]))
        return float(np.abs(np.angle(np.exp(1j * turns))).sum())


def free_space(
    walls: F64 | Sequence[Sequence[float]], radius: float, sides: int = SIDES
) -> FreeSpace:
    """The (cached) visibility graph of ``walls`` for a disc of ``radius`` [m]."""
    w = np.ascontiguousarray(walls, dtype=np.float64).reshape(-1, 4)
    key = tuple(map(float, w.ravel()))
    return _free_space(key, float(radius), int(sides))


@functools.lru_cache(maxsize=32)
def _free_space(key: tuple[float, ...], radius: float, sides: int) -> FreeSpace:
    walls = np.asarray(key, dtype=np.float64).reshape(-1, 4)
    ends = np.unique(np.concatenate([walls[:, :2], walls[:, 2:]]).round(12), axis=0)
    ring = radius / math.cos(math.pi / sides)  # circumscribed polygon: corners at this distance
    angle = 2.0 * math.pi * (np.arange(sides) + 0.5) / sides
    corners = (ends[:, None, :] + ring * np.stack([np.cos(angle), np.sin(angle)], -1)).reshape(
        -1, 2
    )
    if walls.shape[0]:
        keep = _point_segment(corners, walls[:, :2], walls[:, 2:]).min(axis=1) >= radius - _TOL
        corners = corners[keep]
    n = corners.shape[0]
    i, j = np.triu_indices(n, k=1)
    free = _free(corners[i], corners[j], walls, radius)
    length = np.hypot(*(corners[j[free]] - corners[i[free]]).T)
    graph = np.zeros((n, n))
    graph[i[free], j[free]] = length
    graph[j[free], i[free]] = length
    dist, pred = shortest_path(graph, method="D", directed=False, return_predecessors=True)
    for arr in (walls, corners, dist, pred):
        arr.setflags(write=False)
    return FreeSpace(walls, radius, corners, dist, pred)


def _wall_clearance(p: F64, walls: F64) -> float:
    if walls.shape[0] == 0:
        return math.inf
    return float(_point_segment(p[None, :], walls[:, :2], walls[:, 2:]).min())


def shortest_free_path(space: FreeSpace, start: F64, goal: F64) -> FreePath:
    """The shortest path of the disc's centre from ``start`` to ``goal`` [m] keeping the
    clearance ``space.radius`` from every wall (a start or goal nearer a wall than that —
    placed by hand — only needs to keep its own clearance on its first or last piece)."""
    s = np.asarray(start, dtype=np.float64).reshape(2)
    g = np.asarray(goal, dtype=np.float64).reshape(2)
    walls, nodes, r = space.walls, space.nodes, space.radius
    clear_s = min(r, _wall_clearance(s, walls))
    clear_g = min(r, _wall_clearance(g, walls))
    direct = math.hypot(*(g - s))
    if _free(s[None], g[None], walls, min(clear_s, clear_g))[0]:
        return FreePath(direct, np.stack([s, g]))
    n = nodes.shape[0]
    if n == 0:
        return FreePath(math.inf, np.empty((0, 2)))
    from_s = _free(np.repeat(s[None], n, 0), nodes, walls, clear_s)
    to_g = _free(nodes, np.repeat(g[None], n, 0), walls, clear_g)
    a = np.where(from_s, np.hypot(*(nodes - s).T), math.inf)  # start → node i
    b = np.where(to_g, np.hypot(*(nodes - g).T), math.inf)  # node j → goal
    total = a[:, None] + space.dist + b[None, :]
    k = int(np.argmin(total))
    best = float(total.flat[k])
    if not math.isfinite(best):
        return FreePath(math.inf, np.empty((0, 2)))
    i, j = divmod(k, n)
    chain = [j]
    while chain[-1] != i:
        chain.append(int(space.pred[i, chain[-1]]))
    return FreePath(best, np.vstack([s, nodes[chain[::-1]], g]))
