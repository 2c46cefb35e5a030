"""``pioneer reproduce``: the paper's tables and figures from the shipped demonstrations.

Steps (each output is written atomically; the evaluation resumes if interrupted):
1. fit the density reward of each elevator scenario on its shipped demos → ``models/``;
2. evaluate the teacher, its three ablations and the baselines (paper Tables I–II) on HR-RL
   and HL-RR;
3. write ``summary.json``, ``summary.md`` and ``summary.csv`` (our rows beside the paper's);
4. the static-study figure (paper Fig. 3), a trajectory plot and a GIF per scenario;
5. ``index.md``, a report that links everything.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pioneer.errors import ConfigError, expect
from pioneer.eval.harness import PolicySpec, episode_seed, evaluate
from pioneer.eval.metrics import summarize
from pioneer.eval.report import write_summary
from pioneer.io import write_text_atomic

__all__ = ["PROFILES", "Profile", "reproduce"]


@dataclasses.dataclass(frozen=True)
class Profile:
    """How much to run."""

    seeds: int
    trials: int


PROFILES = {"quick": Profile(seeds=2, trials=10), "paper": Profile(seeds=5, trials=100)}
SCENARIOS = ("hr-rl", "hl-rr")
TEACHERS = ("teacher", "teacher-no-density", "teacher-no-goal", "teacher-no-obstacle")
BASELINES = ("cvar-bf",)  # paper Table I; CrowdNav++ joins when it is trained


def fit_models(out: Path, scenarios: Sequence[str]) -> dict[str, str]:
    """Fit and save the reward of every scenario; returns the model paths."""
    from pioneer.control.teacher import default_reward

    paths = {}
    for sc in scenarios:
        p = out / "models" / f"{sc}.reward.npz"
        if not p.exists():
            default_reward(sc).save(p)
        paths[sc] = str(p)
    return paths


def reproduce(
    profile: str = "quick",
    out_dir: str | Path = "out/reproduce",
    workers: int | None = None,
    progress: bool = True,
    extra_policies: Sequence[PolicySpec] = (),
) -> dict[str, Any]:
    """Run the whole pipeline; returns a small summary (paths and headline numbers)."""
    if profile not in PROFILES:
        raise ConfigError(
            expect("profile", f"one of {sorted(PROFILES)}", profile, "use quick or paper")
        )
    prof = PROFILES[profile]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    fit_models(out, SCENARIOS)
    reward_tpl = str(out / "models" / "{scenario}.reward.npz")
    policies = [PolicySpec.make(name, reward=reward_tpl) for name in TEACHERS]
    extra = [PolicySpec.make(name) for name in BASELINES] + list(extra_policies)
    policies += extra
    records = evaluate(
        SCENARIOS, policies, prof.seeds, prof.trials, out / "eval", workers, progress=progress
    )
    summary = summarize(records)
    md = write_summary(
        out,
        summary,
        [
            (
                "I",
                "Table I — navigation performance (ours: mean ± 95% CI over seeds)",
                SCENARIOS,
                ["teacher", *[p.row for p in extra]],
            ),
            ("II", "Table II — ablation of the reward terms", SCENARIOS, list(TEACHERS)),
        ],
    )
    figures = _figures(out, reward_tpl)
    elapsed = time.perf_counter() - t0
    write_text_atomic(out / "index.md", _index(profile, prof, md, figures, elapsed, len(records)))
    head = {
        k: summary[f"{k}/teacher"]["success_rate"]["mean"]
        for k in SCENARIOS
        if f"{k}/teacher" in summary
    }
    return {
        "out": str(out),
        "episodes": len(records),
        "teacher_success_rate": head,
        "elapsed_s": elapsed,
    }


def _figures(out: Path, reward_tpl: str) -> dict[str, str]:
    from pioneer.control.teacher import make_teacher
    from pioneer.data import shipped_demos
    from pioneer.demos.dataset import Dataset
    from pioneer.eval.episode import run_episode
    from pioneer.reward.study import run_static_study
    from pioneer.viz import plot_trajectory, render_frame, save_gif

    figs: dict[str, str] = {}
    study = run_static_study(Dataset.load(shipped_demos("static")), out / "figures")
    figs["static study (paper Fig. 3)"] = "figures/static_study.png"
    for sc in SCENARIOS:
        teacher = make_teacher(sc, reward=reward_tpl.format(scenario=sc))
        seed = episode_seed(sc, 0, 0)
        rec, tr = run_episode(sc, teacher, seed, record=True)
        assert tr is not None
        png = out / "figures" / f"{sc}-teacher.png"
        plot_trajectory(
            tr.world, tr.states, png, title=f"{sc} · teacher · {rec.event} in {rec.time_s:.1f} s"
        )
        robot = tr.robot
        frames = [
            render_frame(tr.world, s, trail=robot[: k + 1, :2], size=360)
            for k, s in enumerate(tr.states)
        ]
        save_gif(frames, out / "figures" / f"{sc}-teacher.gif", fps=10)
        figs[f"{sc} trajectory"] = f"figures/{sc}-teacher.png"
        figs[f"{sc} animation"] = f"figures/{sc}-teacher.gif"
    figs["_study"] = json.dumps({k: v for k, v in study.items() if k != "figure"})
    return figs


def _index(
    profile: str, prof: Profile, tables: str, figs: dict[str, str], elapsed: float, n: int
) -> str:
    study = json.loads(figs.pop("_study"))
    lines = [
        "# PioneeR — reproduction report",
        "",
        f"Profile `{profile}`: {prof.seeds} seeds × {prof.trials} trials per scenario and "
        f"policy ({n} episodes), {elapsed / 60:.1f} min. "
        f"Command: `pioneer reproduce --profile {profile}`.",
        "",
        "Per-episode records: [eval/episodes.jsonl](eval/episodes.jsonl); all metrics with "
        "95% confidence intervals: [summary.json](summary.json); tables as CSV: "
        "[summary.csv](summary.csv).",
        "",
        tables,
        "## Figures",
        "",
    ]
    for title, rel in figs.items():
        lines += [f"### {title}", "", f"![{title}]({rel})", ""]
    pos_only, pos_neg = study["reward_near_human_pos_only"], study["reward_near_human_pos_neg"]
    lines += [
        "Static study: mean learned reward within 0.9 m of the human, positives only "
        f"{pos_only:.2f} → with negatives {pos_neg:.2f}; "
        f"teacher trajectories: {', '.join(study['teacher_side'])}.",
        "",
    ]
    return "\n".join(lines)
