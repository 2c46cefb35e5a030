"""Initial states drawn from a scenario's regions with a seeded generator, overlaps rejected."""

from __future__ import annotations

import math

import numpy as np

from pioneer.errors import ScenarioError, expect
from pioneer.sim.humans import ARRIVED, WALKING
from pioneer.sim.scenarios.spec import (
    MAX_TRIES,
    ScenarioConfig,
    _wall_distance,
    _wall_distances,
)
from pioneer.sim.world import State


def sample_state(cfg: ScenarioConfig, rng: np.random.Generator) -> State:
    """Draw an initial state (B = 1) from ``rng``, rejecting bodies that overlap at t = 0.

    Every draw comes from ``rng`` in a fixed order, so the same seed gives the same state.
    """
    return sample_state_counted(cfg, rng)[0]


def sample_state_counted(cfg: ScenarioConfig, rng: np.random.Generator) -> tuple[State, int]:
    """:func:`sample_state` and the number of draws it took (1 = the first placed every
    body): how tight a layout is for its start regions."""
    walls = np.asarray(cfg.walls, dtype=np.float64).reshape(-1, 4)
    r_r = cfg.sim.robot.radius
    gap = cfg.min_start_gap
    n = len(cfg.humans)
    n_wp = [len(h.waypoints) + 1 for h in cfg.humans]
    w_max = max(n_wp, default=1)
    for draws in range(1, MAX_TRIES + 1):  # noqa: B007 - returned with the state
        p_r = cfg.robot_start.sample(rng)
        heading = rng.uniform(*cfg.robot_heading)
        goal = cfg.robot_goal.sample(rng)
        pos = np.zeros((n, 2))
        wps = np.zeros((n, w_max, 2))
        vpref = np.zeros(n)
        delay = np.zeros(n)
        for i, h in enumerate(cfg.humans):
            pos[i] = h.start.sample(rng)
            g = h.goal.sample(rng)
            pts = [*h.waypoints, tuple(g)]
            wps[i, : len(pts)] = pts
            wps[i, len(pts) :] = g
            vpref[i] = h.v_pref_choices[int(rng.integers(len(h.v_pref_choices)))]
            delay[i] = rng.uniform(*h.start_delay)
        if _initial_state_ok(cfg, walls, p_r, pos, gap, r_r):
            break
    else:
        raise ScenarioError(
            expect(
                f"{cfg.name}: initial state",
                f"a collision-free placement within {MAX_TRIES} draws",
                "every draw overlapped",
                "widen the start regions or reduce radii / min_start_gap",
            )
        )
    status = np.array([ARRIVED if h.static else WALKING for h in cfg.humans], dtype=np.int8)
    state = State(
        robot=np.array([[p_r[0], p_r[1], heading]]),
        command=np.zeros((1, 2)),
        goal=goal.reshape(1, 2),
        start=p_r.reshape(1, 2).copy(),
        t=np.zeros(1),
        path_length=np.zeros(1),
        collided=np.zeros(1, dtype=np.bool_),
        reached=np.zeros(1, dtype=np.bool_),
        gap=np.array([_min_gap(p_r, pos, cfg, r_r)]),
        wall_gap=np.array([_wall_distance(p_r, walls) - r_r]),
        h_pos=pos.reshape(1, n, 2),
        h_vel=np.zeros((1, n, 2)),
        h_radius=np.array([[h.radius for h in cfg.humans]]).reshape(1, n),
        h_vpref=vpref.reshape(1, n),
        h_waypoints=wps.reshape(1, n, w_max, 2),
        h_n_waypoints=np.array([n_wp], dtype=np.int64).reshape(1, n),
        h_wp_index=np.zeros((1, n), dtype=np.int64),
        h_status=status.reshape(1, n),
        h_delay=delay.reshape(1, n),
        h_home=pos.reshape(1, n, 2).copy(),
        h_wait_for=np.array(
            [[int(j in h.wait_for) for j in range(n)] for h in cfg.humans],
            dtype=np.int64,
        ).reshape(1, n, n),
        h_release=np.array(
            [
                k if (k := h.release_waypoint) is not None else n_wp[i]
                for i, h in enumerate(cfg.humans)
            ],
            dtype=np.int64,
        ).reshape(1, n),
        h_reacts=np.array([h.reacts_to_robot for h in cfg.humans], dtype=np.bool_).reshape(1, n),
    )
    return state, draws


def _min_gap(p_r: np.ndarray, pos: np.ndarray, cfg: ScenarioConfig, r_r: float) -> float:
    if len(cfg.humans) == 0:
        return math.inf
    radii = np.array([h.radius for h in cfg.humans])
    return float(np.min(np.linalg.norm(pos - p_r, axis=1) - radii - r_r))


def _initial_state_ok(
    cfg: ScenarioConfig, walls: np.ndarray, p_r: np.ndarray, pos: np.ndarray, gap: float, r_r: float
) -> bool:
    clear = _wall_distances(np.vstack([p_r[None], pos[: len(cfg.humans)]]), walls)
    if clear[0] < r_r + gap:
        return False
    for i, h in enumerate(cfg.humans):
        if clear[1 + i] < h.radius + gap:
            return False
        if np.linalg.norm(pos[i] - p_r) < h.radius + r_r + gap:
            return False
        for j in range(i):
            if np.linalg.norm(pos[i] - pos[j]) < h.radius + cfg.humans[j].radius + gap:
                return False
    return True
