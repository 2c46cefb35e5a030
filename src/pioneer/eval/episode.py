"""Run one episode of a policy in a scenario and record what happened."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.envs.env import NavEnv
from pioneer.envs.episode import Episode, Step
from pioneer.envs.policy import Policy
from pioneer.eval.social import measure_episode, series_of
from pioneer.sim.scenarios import ScenarioConfig
from pioneer.sim.world import State, World, clearance

__all__ = ["RECORD_FORMAT", "RISKY_DISTANCE_M", "EpisodeRecord", "Trajectory", "run_episode"]

# The paper's safe/risky threshold (Table IV): a frame within this distance of a person is risky.
RISKY_DISTANCE_M = 0.8  # [m]

# The version of the record layout (``format`` in every record). 2: the surface-to-surface
# distance is the ``gap`` (``min_gap_m``, ``min_wall_gap_m``, frames ``gap``) and
# ``clearance`` is centre to surface (frames); 1 (no ``format``) named the gap "clearance" and
# the centre distance "surface" — :func:`pioneer.eval.records.parse_records` upgrades it.
# 3: adds ``measures`` (the social-navigation measures, docs/metrics.md) and ``series``
# (robot x, y and the nearest person's clearance per step); older records lack both.
RECORD_FORMAT = 3


@dataclasses.dataclass(frozen=True)
class Trajectory:
    """States of one episode, for plots and animations."""

    world: World
    states: list[State]  # the state after reset, then after every step (B = 1 each)

    @property
    def robot(self) -> NDArray[np.float64]:
        """Robot poses, shape ``(T, 3)``."""
        return np.stack([s.robot[0] for s in self.states])

    @property
    def humans(self) -> NDArray[np.float64]:
        """Human positions, shape ``(T, N, 2)``."""
        return np.stack([s.h_pos[0] for s in self.states])


@dataclasses.dataclass(frozen=True)
class EpisodeRecord:
    """Outcome and metrics of one episode (JSON-serialisable via ``to_dict``)."""

    scenario: str
    policy: str
    seed: int
    event: str  # "success", "collision" or "timeout"
    time_s: float
    path_length_m: float
    min_gap_m: float  # [m] least gap (surface to surface) to a human (inf if no humans)
    time_close_s: float  # [s] time with a gap below RISKY_DISTANCE_M
    steps: int
    # What the robot hit in a collision: "human", "wall" or "human and wall" (None otherwise).
    collided_with: str | None = None
    min_wall_gap_m: float = math.inf  # minimum robot–wall gap over the episode [m]
    # Per-frame series of policies that report uncertainty (students): "gap" and "clearance"
    # [m] of the state each command was chosen in (pioneer.sim.world.clearance), "aleatoric"
    # and "epistemic" [(m/s)² + (rad/s)²], and for a shield "shielded" (0/1). None for other
    # policies.
    frames: dict[str, list[float]] | None = None
    # The social-navigation measures (pioneer.eval.social.EpisodeMeasures.to_dict) and the
    # per-step series for the pictures: "x", "y" of every state and "clearance" of every step
    # [m], to the millimetre (pioneer.eval.social.series_of).
    measures: dict[str, Any] | None = None
    series: dict[str, list[float | None]] | None = None
    format: int = RECORD_FORMAT  # the record layout's version

    def to_dict(self) -> dict[str, Any]:
        """Plain dict; an infinite gap becomes ``None``; no ``frames``, ``measures`` or
        ``series`` key without them; frame values rounded to 6 significant digits (a compact
        JSON line)."""
        d = dataclasses.asdict(self)
        for key in ("min_gap_m", "min_wall_gap_m"):
            if not math.isfinite(d[key]):
                d[key] = None
        if self.frames is None:
            del d["frames"]
        else:
            d["frames"] = {k: [_compact(x) for x in v] for k, v in self.frames.items()}
        for key in ("measures", "series"):
            if d[key] is None:
                del d[key]
        return d


def _compact(x: float) -> float | None:
    """``x`` to 6 significant digits; non-finite (inf gap, NaN) → ``None``."""
    return float(f"{x:.6g}") if math.isfinite(x) else None


def _frame_series(
    policy: Policy, gap: list[float], clear: list[float]
) -> dict[str, list[float]] | None:
    """The per-frame series of a policy that reports ``uncertainty`` (one pair per step):
    ``gap`` surface to surface (docs/simulator.md), ``clearance`` from the robot's centre to
    the nearest human's surface (the paper's clearance, what d₁ measures)."""
    unc = getattr(policy, "uncertainty", None)
    if unc is None or len(unc) != len(gap):
        return None
    out = {
        "gap": gap,
        "clearance": clear,
        "aleatoric": [float(a) for a, _ in unc],
        "epistemic": [float(e) for _, e in unc],
    }
    shielded = getattr(policy, "shielded", None)
    if shielded is not None and len(shielded) == len(gap):
        out["shielded"] = [float(s) for s in shielded]
    return out


def _hit(info: Mapping[str, Any]) -> str:
    """What a collision step touched: the swept human and wall gaps of that step."""
    human, wall = info["min_gap"] < 0.0, info["wall_gap"] < 0.0
    return "human and wall" if human and wall else "wall" if wall else "human"


def run_episode(
    scenario: str | ScenarioConfig,
    policy: Policy,
    seed: int,
    record: bool = False,
    close_threshold: float = RISKY_DISTANCE_M,
) -> tuple[EpisodeRecord, Trajectory | None]:
    """Run ``policy`` for one episode seeded by ``seed``; optionally keep every state."""
    env = NavEnv(scenario)
    episode = Episode(env, policy, seed)
    states = [env.state]  # references (states are values): the measures are computed at the end
    dt = env.scenario.sim.dt
    close = 0.0
    r_r = env.scenario.sim.robot.radius
    decision_gap: list[float] = []  # of the state each command was chosen in
    decision_clear: list[float] = []
    wall_min = math.inf

    def keep(step: Step) -> None:
        nonlocal close, wall_min
        decision_gap.append(float(step.info["min_gap"]))
        decision_clear.append(float(clearance(step.info["state"], r_r)[0]))
        after = step.next_info
        wall_min = min(wall_min, float(after["wall_gap"]))
        if after["min_gap"] < close_threshold:
            close += dt
        states.append(after["state"])

    info = episode.run(keep)
    event = str(episode.event)
    hit = _hit(info) if event == "collision" else None
    rec = EpisodeRecord(
        scenario=env.scenario.name,
        policy=policy.name,
        seed=seed,
        event=event,
        time_s=info["time"],
        path_length_m=info["path_length"],
        min_gap_m=info["episode_min_gap"],
        time_close_s=close,
        steps=episode.steps,
        collided_with=hit,
        min_wall_gap_m=wall_min,
        frames=_frame_series(policy, decision_gap, decision_clear),
        measures=measure_episode(env.scenario, states, event, hit).to_dict(),
        series=series_of(states, r_r),
    )
    return rec, (Trajectory(env.world, states) if record else None)
