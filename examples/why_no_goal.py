"""Why the teacher without its goal term times out (docs/results.md, "Why no-goal times out").

    python examples/why_no_goal.py OUT [--episodes 40] [--policy teacher-no-goal]

runs the policy (a registered teacher without R_goal) on HR-RL validation episodes, and for
every decision keeps what the teacher's score was made of (its ``last`` decision): the
adaptive density weight α_den of the chosen candidate, the weighted density and obstacle
terms, and the robot's distance to the goal. Prints, per outcome, the episodes' count, the
distance to the goal at the end, the least distance reached and the chosen candidates' mean
α_den over the last 5 s; plots the first two timed-out episodes with
:func:`pioneer.viz.plot_trajectory` into ``OUT/no-goal-timeout-K.png``.

With the goal term removed, eq. 13 leaves R = α_den R_den + R_obs, and α_den = 1 + cos(π(1 − r))
(eq. 18; r = the rollout's final distance to the goal over the start–goal distance) grows from
0 at the goal to 2 at the start's distance: where the density is positive, a candidate that
ends farther from the goal scores more, and near the goal only the clearance term is left.
"""

from __future__ import annotations

import argparse
import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from pioneer.control.registry import build_policy
from pioneer.eval.episode import run_episode
from pioneer.seeds import validation_seed
from pioneer.viz import plot_trajectory

SCENARIO = "hr-rl"
LAST_S = 5.0  # [s] the window of the end of an episode


class Recorder:
    """The teacher, keeping each decision's α_den and weighted terms (a :class:`Policy`)."""

    def __init__(self, teacher: Any) -> None:
        self.teacher = teacher
        self.name = teacher.name
        self.rows: list[dict[str, float]] = []

    def reset(self, info: Any, rng: np.random.Generator) -> None:
        """Reset the teacher and forget the decisions."""
        self.rows = []
        self.teacher.reset(info, rng)

    def act(self, obs: np.ndarray, info: Any) -> np.ndarray:
        """The teacher's command; its decision's terms kept."""
        u = self.teacher.act(obs, info)
        d = self.teacher.last
        raw, den = d.raw_terms.get("density", 0.0), d.terms.get("density", math.nan)
        self.rows.append(
            {
                "alpha_den": den / raw if abs(raw) > 1e-12 else math.nan,
                "density": den,
                "obstacle": d.terms.get("obstacle", math.nan),
                "feasible": d.n_feasible,
            }
        )
        return u


def _mean(values: list[float]) -> float:
    """The mean of the finite ``values`` (NaN when there is none)."""
    finite = [v for v in values if math.isfinite(v)]
    return float(np.mean(finite)) if finite else math.nan


def main() -> None:
    """Run, print the table, plot two timed-out episodes."""
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--episodes", type=int, default=40)
    parser.add_argument("--policy", default="teacher-no-goal")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    policy = Recorder(build_policy(args.policy, SCENARIO))
    by_event: dict[str, list[dict[str, float]]] = defaultdict(list)
    plotted = 0
    for k in range(args.episodes):
        seed = validation_seed("why-no-goal", SCENARIO, k)
        rec, tr = run_episode(SCENARIO, policy, seed, record=True)
        assert tr is not None
        goal = tr.states[0].goal[0]
        dist = np.array([np.hypot(*(s.robot[0, :2] - goal)) for s in tr.states])
        start = float(dist[0])
        steps = max(1, round(LAST_S / (rec.time_s / max(len(policy.rows), 1))))
        tail = [r["alpha_den"] for r in policy.rows[-steps:] if math.isfinite(r["alpha_den"])]
        by_event[rec.event].append(
            {
                "end": float(dist[-1]),
                "least": float(dist.min()),
                "start": start,
                "alpha_tail": float(np.mean(tail)) if tail else math.nan,
                "density_tail": _mean([r["density"] for r in policy.rows[-steps:]]),
                "obstacle_tail": _mean([r["obstacle"] for r in policy.rows[-steps:]]),
            }
        )
        if rec.event == "timeout" and plotted < 2:
            plotted += 1
            png = args.out / f"no-goal-timeout-{plotted}.png"
            title = f"{args.policy} · {SCENARIO} validation episode {k} · timeout"
            plot_trajectory(tr.world, tr.states, png, title=title)
            print(f"wrote {png}")
    print(
        "| outcome | episodes | distance to goal at the end (m) | least distance (m) | "
        "start distance (m) | α_den, last 5 s | α_den·R_den, last 5 s | R_obs, last 5 s |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for event, rows in sorted(by_event.items()):

        def mean(key: str, rows: list[dict[str, float]] = rows) -> float:
            return _mean([r[key] for r in rows])

        print(
            f"| {event} | {len(rows)} | {mean('end'):.2f} | {mean('least'):.2f} | "
            f"{mean('start'):.2f} | {mean('alpha_tail'):.2f} | {mean('density_tail'):.3f} | "
            f"{mean('obstacle_tail'):.3f} |"
        )


if __name__ == "__main__":
    main()
