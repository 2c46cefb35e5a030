"""The synthetic static study (paper §V-A, Fig. 3), as a reproducible function.

(a) reward fitted on the positive demos only, (b) on positives and negatives, (c) the learned
reward combined with the rule terms, with trajectories of the lookahead teacher using the
(x, y) density reward.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pioneer.control.teacher import LookaheadTeacher
from pioneer.errors import DataError, expect
from pioneer.eval.episode import run_episode
from pioneer.io import output_dir, output_dir_kind
from pioneer.reward.dataset import Dataset
from pioneer.reward.density import DensityConfig, DensityReward
from pioneer.reward.features import feature_map
from pioneer.reward.rules import adaptive_weights, goal_term
from pioneer.sim.scenarios import get_scenario
from pioneer.sim.world import State, observe

__all__ = ["run_static_study"]


def run_static_study(
    demos: Dataset, out_dir: str | Path, n_trajectories: int = 6
) -> dict[str, Any]:
    """Fit the two rewards, draw the three panels into ``out_dir/static_study.png`` (created
    only when the study has run: refused demos leave nothing behind)."""
    _check_demos(demos)
    output_dir_kind(out_dir)
    out = Path(out_dir)
    fm = feature_map("xy")
    z, g = fm.from_dataset(demos), demos.gamma
    pos = g > 0
    # Maps over (x, y) in metres want a finer length than the default (about 0.3 m here).
    cfg = DensityConfig(length_scale_factor=0.25)
    m_pos = DensityReward(cfg).fit(z[pos], g[pos], list(fm.names))
    m_all = DensityReward(cfg).fit(z, g, list(fm.names))
    scen = get_scenario("static")
    world = scen.world()
    xmin, xmax, ymin, ymax = scen.bounds
    gx = np.linspace(xmin, xmax, 81)
    gy = np.linspace(ymin, ymax, 121)
    xx, yy = np.meshgrid(gx, gy)
    pts = np.stack([xx.ravel(), yy.ravel()], axis=1)
    r_pos = m_pos(pts).reshape(xx.shape)
    r_all = m_all(pts).reshape(xx.shape)
    # Combined map: the teacher's score of a rollout ending at each grid point (heading +y).
    st = _grid_states(scen, pts)
    obs = observe(world, st)
    d_goal = np.linalg.norm(st.goal - pts, axis=1)
    d_total = float(np.linalg.norm(st.goal[0] - st.start[0]))
    a_den, a_goal, a_obs = adaptive_weights(d_goal, d_total)
    r_obs = np.tanh(obs[:, 24:26].min(axis=1).astype(np.float64))
    combined = (a_den * m_all(pts) + a_goal * goal_term(d_goal, d_total) + a_obs * r_obs).reshape(
        xx.shape
    )
    teacher = LookaheadTeacher(density=m_all, features="xy", name="teacher-xy")
    trajs, events = [], []
    for seed in range(n_trajectories):
        rec, tr = run_episode(scen, teacher, seed, record=True)
        assert tr is not None
        trajs.append(tr.robot[:, :2])
        events.append(rec.event)
    from pioneer.viz.study import plot_static_study

    output_dir(out)
    human = st.h_pos[0, 0]
    plot_static_study(
        world,
        human,
        float(st.h_radius[0, 0]),
        [
            ("(a) learned reward, positive demos", r_pos),
            ("(b) learned reward, positive + negative", r_all),
            ("(c) learned + rule-based, teacher trajectories", combined),
        ],
        gx,
        gy,
        z[pos],
        z[~pos],
        trajs,
        out / "static_study.png",
    )
    hx = np.linalg.norm(pts - human, axis=1) < float(st.h_radius[0, 0]) + 0.3
    summary = {
        "figure": str(out / "static_study.png"),
        "reward_near_human_pos_only": float(r_pos.ravel()[hx].mean()),
        "reward_near_human_pos_neg": float(r_all.ravel()[hx].mean()),
        "teacher_events": events,
        "teacher_side": ["right" if np.mean(t[:, 0]) > 0 else "left" for t in trajs],
    }
    return summary


def _check_demos(demos: Dataset) -> None:
    """Demonstrations of the static study, positive and negative (Fig. 3 contrasts them)."""
    from pioneer.reward.features import default_feature_map

    if default_feature_map(demos.scenarios) != "xy":
        raise DataError(
            expect(
                "static-study demos",
                "demonstrations of the static scenario",
                sorted(set(demos.scenarios)),
                "pass the static study's dataset (pioneer demos generate --scenario static)",
            )
        )
    lacking = demos.one_sided()
    if lacking is not None:
        raise DataError(
            expect(
                "static-study demos",
                "positive and negative samples (Fig. 3 contrasts them)",
                lacking,
                "add demonstrations of the other kind",
            )
        )


def _grid_states(scen: Any, pts: np.ndarray) -> State:
    from pioneer.sim.scenarios import sample_state

    s0 = sample_state(scen, np.random.default_rng(0)).repeat(pts.shape[0])
    s0.robot[:, :2] = pts
    s0.robot[:, 2] = np.pi / 2
    return s0
