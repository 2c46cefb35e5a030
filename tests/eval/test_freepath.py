"""The shortest free path of a disc among walls, on maps with a known answer."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pioneer.eval.freepath import free_space, segment_distances, shortest_free_path
from pioneer.sim.scenarios import get_scenario
from pioneer_testutils import wall_distances

R = 0.3  # [m]


def _around_a_corner(start, corner, goal, r):
    """Length of the path from ``start`` tangent to the circle of radius ``r`` about
    ``corner``, along it and tangent to ``goal`` (both at the same distance from the corner,
    the arc on the far side from the straight line)."""
    d = math.dist(start, corner)
    tangent = math.sqrt(d * d - r * r)
    a = np.subtract(start, corner)
    b = np.subtract(goal, corner)
    between = math.acos(float(a @ b) / (np.linalg.norm(a) * np.linalg.norm(b)))
    arc = 2 * math.pi - between - 2 * math.acos(r / d)
    return 2 * tangent + r * arc, arc


def test_no_walls_no_detour():
    p = shortest_free_path(free_space(np.zeros((0, 4)), R), (0.0, 0.0), (3.0, 4.0))
    assert p.length == pytest.approx(5.0)
    assert p.points.tolist() == [[0.0, 0.0], [3.0, 4.0]]
    assert p.turning(math.atan2(4, 3)) == pytest.approx(0.0)
    assert p.turning(0.0) == pytest.approx(math.atan2(4, 3))


def test_around_the_end_of_a_single_wall():
    """A wall x = 0, y ∈ [−1, 1] between (−2, 0) and (2, 0): tangent, arc of radius r about
    the end point (0, 1), tangent."""
    exact, arc = _around_a_corner((-2.0, 0.0), (0.0, 1.0), (2.0, 0.0), R)
    p = shortest_free_path(free_space([(0.0, -1.0, 0.0, 1.0)], R), (-2.0, 0.0), (2.0, 0.0))
    assert exact == pytest.approx(4.790634, abs=1e-6)  # worked out by hand
    assert exact <= p.length <= exact * (1 + 1e-3)  # the 32-gon's corners cut no corner
    # the path turns by the arc's angle (first piece to last piece)
    d0 = p.points[1] - p.points[0]
    assert p.turning(math.atan2(d0[1], d0[0])) == pytest.approx(arc, rel=2e-2)
    walls = np.array([(0.0, -1.0, 0.0, 1.0)])
    clear = segment_distances(p.points[:-1], p.points[1:], walls).min()
    assert clear >= R - 1e-9  # every piece keeps the radius from the wall


def test_through_a_door():
    """A wall along y = 0 with a 1 m door at x ∈ [−0.5, 0.5]; from (−2, −1) to (−2, 1) the
    disc rounds the door's left jamb (−0.5, 0), not the wall's far end (−10, 0)."""
    walls = [(-10.0, 0.0, -0.5, 0.0), (0.5, 0.0, 10.0, 0.0)]
    exact, _ = _around_a_corner((-2.0, -1.0), (-0.5, 0.0), (-2.0, 1.0), R)
    p = shortest_free_path(free_space(walls, R), (-2.0, -1.0), (-2.0, 1.0))
    assert exact <= p.length <= exact * (1 + 1e-3)
    # a door narrower than the disc is shut: around the wall's far end instead
    narrow = [(-10.0, 0.0, -0.25, 0.0), (0.25, 0.0, 10.0, 0.0)]
    around, _ = _around_a_corner((-2.0, -1.0), (-10.0, 0.0), (-2.0, 1.0), R)
    q = shortest_free_path(free_space(narrow, R), (-2.0, -1.0), (-2.0, 1.0))
    assert around <= q.length <= around * (1 + 1e-3)


def test_an_enclosed_goal_cannot_be_reached():
    box = [(1, -1, 3, -1), (3, -1, 3, 1), (3, 1, 1, 1), (1, 1, 1, -1)]
    p = shortest_free_path(free_space(box, R), (-2.0, 0.0), (2.0, 0.0))
    assert p.length == math.inf and p.points.shape == (0, 2)


def test_segment_distances_against_a_dense_sampling():
    rng = np.random.default_rng(0)
    walls = rng.uniform(-2, 2, size=(6, 4))
    p0, p1 = rng.uniform(-2, 2, size=(40, 2)), rng.uniform(-2, 2, size=(40, 2))
    got = segment_distances(p0, p1, walls)
    s = np.linspace(0.0, 1.0, 2001)[:, None, None]
    pts = p0[None] + s * (p1 - p0)[None]  # (S, K, 2)
    dense = wall_distances(pts, walls).min(axis=0)  # (K, M)
    assert np.all(got <= dense + 1e-12)
    assert np.allclose(got, dense, atol=2e-3)


def test_the_elevator_graph_is_built_once_and_answers_fast():
    sc = get_scenario("hr-rl")
    space = free_space(sc.walls, sc.sim.robot.radius)
    assert free_space(sc.walls, sc.sim.robot.radius) is space  # cached
    assert space.nodes.shape[0] > 0
    walls = np.asarray(sc.walls, dtype=float)
    assert wall_distances(space.nodes, walls).min() >= sc.sim.robot.radius - 1e-9
    start, goal = sc.robot_start.center, sc.robot_goal.center
    p = shortest_free_path(space, start, goal)
    assert math.dist(start, goal) <= p.length < 1.5 * math.dist(start, goal)
