"""``pioneer calibrate``: statistics of a world beside the paper's evidence (docs/calibration.md).

The paper does not publish its world, only numbers that constrain it (paper §V-B
and Tables I–IV; docs/calibration.md derives what they imply). This module measures the same
numbers in ours, on **validation** seeds (:mod:`pioneer.seeds`), so the world's free
parameters — start regions, human timing, human–robot reaction — are chosen by world
statistics and never by the method comparisons of Tables I–III.

Per episode seed, three runs from the same initial state:
1. the teacher (paper reward: density fitted on the shipped demos + rule terms);
2. a careless go-to-goal driver that ignores people (the demonstrations' negatives);
3. the humans alone: the robot is moved far out of the map and stands still.

Statistics per scenario (the keys of ``calibration.json``):

- ``teacher_path_length_m``, ``teacher_time_s``: mean over the teacher's successes;
- ``teacher_risky_frame_share``: share of the teacher's decision frames whose distance from
  the robot's centre to the nearest human's *surface* is ≤ 0.8 m (the paper's "clearance",
  what the LiDAR feature d₁ measures); ``…_gap``: the same with the surface gap (docs/simulator.md);
- ``risky_at_start_share``: share of episodes whose initial state is risky (no band);
- ``humans_alone_done_share``: every human arrived or left within the time limit, no robot;
- ``careless_collision_share``: share of careless episodes that end in a collision;
- ``human_deflection_m``: per episode the largest distance of a human, while the teacher
  drives, from the path the same human walks without a robot; the mean over episodes.

Each row of ``episodes.jsonl`` names what drove it in ``made_by``, as the evaluation's records
do (:func:`pioneer.eval.harness.made_by`: the driver's resolved parameters and the hashes of
the files it loads).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.config import MAX_EPISODES, check_count, default
from pioneer.errors import ConfigError, expect
from pioneer.eval.episode import RISKY_DISTANCE_M
from pioneer.io import output_dir, to_json, write_text_atomic
from pioneer.progress import progress_bar
from pioneer.seeds import validation_seed
from pioneer.sim.world import clearance

__all__ = ["BANDS", "RISKY_CLEARANCE", "calibrate", "episode_statistics", "summarize_world"]

RISKY_CLEARANCE = RISKY_DISTANCE_M  # [m] the paper's safe/risky threshold (Table IV)
ROBOT_AWAY = 1.0e3  # [m] where the robot stands when the humans walk alone
# The paper's evidence as bands (paper §V-B, Tables I–IV; docs/calibration.md).
BANDS: dict[str, tuple[float, float]] = {
    "teacher_path_length_m": (3.4, 4.1),  # paper 3.74 (HR-RL), 3.88 (HL-RR)
    "teacher_time_s": (10.0, 15.0),  # paper 12.24, 12.94
    "teacher_risky_frame_share": (0.03, 0.12),  # paper 8.1 %, 4.6 % (student frames)
    "humans_alone_done_share": (0.99, 1.0),
    "careless_collision_share": (0.30, 1.0),
}


def _paper(scenario: str) -> dict[str, float]:
    """The paper's teacher PL and TT (Table I) and risky frame share (§V-B.2) of ``scenario``."""
    from pioneer.eval.tables import PAPER as TABLES
    from pioneer.eval.uncertainty import PAPER_TABLE_IV

    _, tt, pl = TABLES[("I", scenario, "teacher-paper")]
    iv = PAPER_TABLE_IV[scenario]
    share = iv["frames_risky"] / (iv["frames_risky"] + iv["frames_safe"])
    return {"teacher_path_length_m": pl, "teacher_time_s": tt, "risky_share": share}


def _path_distance(points: NDArray[np.float64], path: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distance of every point ``(T, 2)`` to the polyline ``path`` ``(P, 2)``."""
    if len(path) == 1:
        return np.linalg.norm(points - path[0], axis=1)
    a, b = path[:-1], path[1:]
    e = b - a
    ll = np.maximum(np.einsum("ij,ij->i", e, e), 1e-18)
    rel = points[:, None, :] - a[None]
    s = np.clip(np.einsum("tij,ij->ti", rel, e) / ll, 0.0, 1.0)
    closest = a[None] + s[..., None] * e[None]
    return np.linalg.norm(points[:, None, :] - closest, axis=2).min(axis=1)


def _humans_alone(world: Any, state0: Any, time_limit: float) -> tuple[bool, list[Any]]:
    """Step the humans of ``state0`` with the robot far away; done = nobody still walking."""
    from pioneer.sim.humans import WALKING
    from pioneer.sim.world import step

    s = state0.copy()
    s.robot[0, :2] = ROBOT_AWAY
    s.goal[0] = ROBOT_AWAY + 10.0
    states = [s]
    zero = np.zeros((1, 2))
    while s.t[0] < time_limit - 1e-9:
        s = step(world, s, zero)
        states.append(s)
        if not np.any(s.h_status[0] == WALKING):
            return True, states
    return False, states


def episode_statistics(task: tuple[str, int, str]) -> dict[str, Any]:
    """The three runs of one validation episode (a picklable task for the worker pool):
    ``(scenario, seed, driver)``, the driver a policy name (``teacher-paper-evade`` by default)."""
    from pioneer.control.registry import build_policy
    from pioneer.demos.scripted import CarelessDriver
    from pioneer.eval.episode import run_episode
    from pioneer.sim.humans import GONE
    from pioneer.sim.scenarios import get_scenario

    scenario, seed, driver = task
    cfg = get_scenario(scenario)
    # 1. teacher (or another driver)
    rec, traj = run_episode(cfg, build_policy(driver, scenario), seed, record=True)
    assert traj is not None
    states = traj.states
    state0 = states[0]
    decision = states[:-1]  # the state each command was chosen in
    r_r = cfg.sim.robot.radius
    surf = np.array([float(clearance(s, r_r)[0]) for s in decision])
    # 2. careless driver, same seed
    c_event = run_episode(cfg, CarelessDriver(), seed)[0].event
    # 3. humans alone, same initial state
    done, alone = _humans_alone(traj.world, state0, cfg.sim.time_limit)
    deflection = 0.0
    for i in range(state0.n_humans):
        ref = np.array([s.h_pos[0, i] for s in alone if s.h_status[0, i] != GONE])
        pts = np.array([s.h_pos[0, i] for s in states if s.h_status[0, i] != GONE])
        if len(ref) and len(pts):
            deflection = max(deflection, float(_path_distance(pts, ref).max()))
    return {
        "scenario": scenario,
        "seed": seed,
        "teacher_event": rec.event,
        "teacher_time_s": float(states[-1].t[0]),
        "teacher_path_length_m": float(states[-1].path_length[0]),
        "risky_frames": int(np.sum(surf <= RISKY_CLEARANCE)),
        "risky_frames_gap": int(np.sum(surf - r_r <= RISKY_CLEARANCE)),
        "frames": len(decision),
        "risky_at_start": bool(surf[0] <= RISKY_CLEARANCE),
        "start_clearance_m": float(surf[0]),
        "careless_event": c_event,
        "humans_alone_done": done,
        "humans_alone_time_s": float(alone[-1].t[0]),
        "human_deflection_m": deflection,
    }


def summarize_world(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The statistics of one scenario's episodes, with the paper's bands and a verdict."""
    ok = [r for r in rows if r["teacher_event"] == "success"]
    frames = sum(r["frames"] for r in rows)
    stats: dict[str, Any] = {
        "episodes": len(rows),
        "teacher_success_share": len(ok) / len(rows),
        "teacher_path_length_m": float(np.mean([r["teacher_path_length_m"] for r in ok]))
        if ok
        else math.nan,
        "teacher_time_s": float(np.mean([r["teacher_time_s"] for r in ok])) if ok else math.nan,
        "teacher_risky_frame_share": sum(r["risky_frames"] for r in rows) / frames,
        "teacher_risky_frame_share_gap": sum(r["risky_frames_gap"] for r in rows) / frames,
        "teacher_risky_time_per_episode_s": float(
            np.mean([r["risky_frames"] * r["teacher_time_s"] / r["frames"] for r in rows])
        ),
        "risky_at_start_share": float(np.mean([r["risky_at_start"] for r in rows])),
        "humans_alone_done_share": float(np.mean([r["humans_alone_done"] for r in rows])),
        "humans_alone_time_s": float(np.mean([r["humans_alone_time_s"] for r in rows])),
        "careless_collision_share": float(
            np.mean([r["careless_event"] == "collision" for r in rows])
        ),
        "human_deflection_m": float(np.mean([r["human_deflection_m"] for r in rows])),
    }
    stats["within_band"] = {
        k: bool(lo <= stats[k] <= hi) for k, (lo, hi) in BANDS.items() if k in stats
    }
    return stats


def _run(
    tasks: list[tuple[str, int, str]], workers: int, progress: bool
) -> Iterator[dict[str, Any]]:
    bar = progress_bar(total=len(tasks), desc="calibrate", unit="episode", enabled=progress)
    if workers <= 1:
        for t in tasks:
            yield episode_statistics(t)
            bar.update()
    else:
        from pioneer.eval.harness import _worker_init
        from pioneer.parallel import bounded_map, spawn_pool

        with spawn_pool(workers, _worker_init) as pool:
            for r in bounded_map(pool, episode_statistics, tasks, 4 * workers):
                yield r
                bar.update()
    bar.close()


def calibrate(
    scenarios: Sequence[str],
    episodes: int = 100,
    out_dir: str | Path | None = None,
    workers: int | None = None,
    progress: bool = True,
    driver: str = "teacher-paper-evade",
) -> dict[str, Any]:
    """Measure the world statistics of ``scenarios`` on ``episodes`` validation seeds each;
    write ``out_dir/calibration.json`` (and per-episode rows) if given. ``driver`` is the
    policy whose statistics are the ``teacher_*`` keys: by default the paper's teacher (no
    soft margins) with our evade fallback, the driver the world was measured with, whose TT
    and PL the bands compare with the paper's; e.g.
    ``teacher-no-density``."""
    from pioneer.control.registry import check_parts, policy_factory
    from pioneer.eval.harness import PolicySpec, made_by
    from pioneer.sim.scenarios import get_scenario, pin_scenario

    if episodes < 1:
        fix = f"use e.g. {default(calibrate, 'episodes')}"
        raise ConfigError(expect("--episodes", "an integer >= 1", episodes, fix))
    check_count(
        "episodes (scenarios × --episodes)",
        len(set(scenarios)) * episodes,
        MAX_EPISODES,
        "ask for fewer --episodes",
    )
    names = [get_scenario(s).name for s in scenarios]  # unknown names fail here, at once
    policy_factory(driver)  # an unknown driver fails here, at once
    for s in names:  # and one without its parts in a scenario (a student without a shipped one)
        check_parts(driver, s, {})
    made = {s: made_by(PolicySpec.make(driver), s) for s in names}  # files hashed before use
    tasks = [
        (s, validation_seed("calibrate", s, k), driver) for s in names for k in range(episodes)
    ]
    n_workers = workers if workers is not None else min(len(tasks), os.cpu_count() or 1)
    out = output_dir(out_dir) if out_dir is not None else None  # refuse a bad --out first
    t0 = time.perf_counter()
    rows = sorted(_run(tasks, n_workers, progress), key=lambda r: (r["scenario"], r["seed"]))
    result: dict[str, Any] = {
        "format": "pioneer.calibration/1",
        "seeds": "validation (pioneer.seeds.validation_seed('calibrate', scenario, k))",
        "driver": driver,
        "risky_clearance_m": RISKY_CLEARANCE,
        "bands": {k: list(v) for k, v in BANDS.items()},
        "paper": {s: _paper(s) for s in names if s in ("hr-rl", "hl-rr")},
        "scenarios": {},
    }
    for s in names:
        result["scenarios"][s] = {
            **summarize_world([r for r in rows if r["scenario"] == s]),
            "definition": pin_scenario(s, None, "calibrate"),
        }
    result["elapsed_s"] = time.perf_counter() - t0
    if out is not None:
        write_text_atomic(out / "calibration.json", to_json(result, indent=2))
        lines = [to_json({**r, "made_by": made[r["scenario"]]}) + "\n" for r in rows]
        write_text_atomic(out / "episodes.jsonl", "".join(lines))
    return result
