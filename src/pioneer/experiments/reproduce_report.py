"""The report of ``pioneer reproduce``: Tables III over the DAgger seeds and IV (the MDN's
uncertainty, safe vs risky frames), the social-navigation tables and figures, where the time
went, the static study, trajectory plots and GIFs, and ``index.md`` linking everything. It
reads the evaluation's records and summary; :mod:`pioneer.experiments.reproduce` runs them."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pioneer.data import STUDENT_SEEDS
from pioneer.errors import DataError, expect
from pioneer.eval.episode import RISKY_DISTANCE_M
from pioneer.eval.harness import episode_seed
from pioneer.experiments.reproduce_plan import (
    PAPER_ROWS,
    SCENARIOS,
    UNCERTAINTY_KEY,
    Profile,
    seed_row,
)
from pioneer.experiments.timing import row_times
from pioneer.io import to_json, write_text_atomic

__all__ = [
    "figures",
    "index_page",
    "seed_table",
    "social_figures",
    "social_tables",
    "table_iv",
    "time_table",
]


def time_table(records: Sequence[dict[str, Any]], workers: int) -> str:
    """Markdown: where the episodes' time went, the paper's rows apart from the extra ones."""
    times = row_times(records)
    lines = [
        "## Where the time went",
        "",
        "| row | part | episodes | run time [CPU-min] | per episode [s] |",
        "|---|---|---|---|---|",
    ]
    total = {"paper": 0.0, "extra": 0.0}
    for row, (n, sec) in times.items():
        part = "paper" if row in PAPER_ROWS else "extra"
        total[part] += sec
        lines.append(f"| {row} | {part} | {n} | {sec / 60:.1f} | {sec / max(n, 1):.3f} |")
    lines += [
        "",
        f"The paper's rows (Tables I–IV) ran {total['paper'] / 60:.1f} CPU-min, the extra rows "
        f"{total['extra'] / 60:.1f} CPU-min: ≈ {total['paper'] / 60 / workers:.1f} and "
        f"{total['extra'] / 60 / workers:.1f} min of wall time on {workers} worker(s).",
        "",
    ]
    return "\n".join(lines)


def table_iv(out: Path, records: Sequence[dict[str, Any]]) -> str:
    """Safe/risky uncertainty analysis of the MDN student: ``uncertainty.json``, the histogram
    figure, and Table IV as Markdown. A frame is risky when the distance from the robot's
    centre to the nearest human's surface (the paper's clearance, what d₁ measures) is ≤ 0.8 m;
    beside it, the threshold at the quantile that gives the paper's risky share."""
    from pioneer.eval.uncertainty import (
        PAPER_TABLE_IV,
        frame_arrays,
        safe_risky,
        table_iv_markdown,
    )
    from pioneer.viz.student import plot_uncertainty_histogram

    results: dict[str, dict[str, Any]] = {}
    matched: dict[str, dict[str, Any]] = {}
    hist: dict[str, dict[str, Any]] = {}
    for sc in SCENARIOS:
        recs = [r for r in records if r["scenario"] == sc and r["policy"] == "student-mdn"]
        fr = frame_arrays(recs, "clearance")
        if fr["distance"].size == 0:
            continue
        results[sc] = safe_risky(recs, RISKY_DISTANCE_M, "clearance")
        p = PAPER_TABLE_IV[sc]
        share = p["frames_risky"] / (p["frames_risky"] + p["frames_safe"])
        finite = fr["distance"][np.isfinite(fr["distance"])]
        thr = float(np.quantile(finite, share)) if finite.size else RISKY_DISTANCE_M
        matched[sc] = safe_risky(recs, thr, "clearance")
        risky = fr["distance"] <= thr
        for name in ("aleatoric", "epistemic"):
            hist[f"{sc} {name} (risky: centre → surface ≤ {thr:.2f} m)"] = {
                "safe": fr[name][~risky],
                "risky": fr[name][risky],
            }
    if not results:
        return ""
    write_text_atomic(
        out / "uncertainty.json",
        to_json({UNCERTAINTY_KEY: results, "paper_risky_share": matched}, indent=2),
    )
    plot_uncertainty_histogram(
        hist, out / "figures" / "uncertainty_safe_risky.png", "MDN student: safe vs risky frames"
    )
    return (
        "\n### Table IV — MDN uncertainty, safe vs risky frames (safe: robot centre → nearest "
        f"human surface > {RISKY_DISTANCE_M:g} m)\n\n"
        + table_iv_markdown(results, SCENARIOS)
        + "\nSame analysis with the risky threshold at the quantile that gives the "
        "paper's risky share (8.1 % HR-RL, 4.6 % HL-RR):\n\n"
        + table_iv_markdown(matched, SCENARIOS)
        + "\n![uncertainty histograms](figures/uncertainty_safe_risky.png)\n"
    )


def seed_table(summary: Mapping[str, Mapping[str, Any]], names: Sequence[str]) -> str:
    """Markdown: each student over its DAgger seeds — the mean success, the spread between
    seeds and every seed's (the per-seed rows, with intervals, are in Table III)."""
    lines = [
        "\n### Table III over DAgger seeds",
        "",
        "One DAgger run per seed (the same episodes for every student); mean and standard "
        "deviation over the seeds' success rates, and each seed's.",
        "",
        "| scenario | student | seeds | SR mean ± sd (%) | SR per seed (%) | collisions mean (%) |",
        "|---|---|---|---|---|---|",
    ]
    for sc in SCENARIOS:
        for name in names:
            cells = [summary.get(f"{sc}/{seed_row(name, s)}") for s in STUDENT_SEEDS]
            got = [c for c in cells if c is not None]
            if not got:
                continue
            sr = np.array([float(c["success_rate"]["mean"]) for c in got])  # [%]
            coll = np.mean([float(c["collision_rate"]["mean"]) for c in got])
            each = " / ".join(f"{v:.1f}" for v in sr)
            lines.append(
                f"| {sc.upper()} | {name} | {len(got)} | {sr.mean():.1f} ± {sr.std(ddof=0):.1f} "
                f"| {each} | {coll:.1f} |"
            )
    return "\n".join(lines) + "\n"


def social_tables(summary: Mapping[str, Mapping[str, Any]], rows: Sequence[str]) -> str:
    """Markdown: the social-navigation measures of every row, two tables per scenario."""
    from pioneer.eval.tables import measure_table

    parts = [
        "\n## Social navigation measures",
        "",
        "Beyond the paper: efficiency, smoothness, distances to people and collisions by kind "
        "(definitions, units and sources: docs/metrics.md). Shares of time are of the "
        "episodes' steps; the clearance is from the robot's centre to the nearest person's "
        "surface, the gap surface to surface.",
        "",
    ]
    for sc in SCENARIOS:
        parts.append(
            measure_table(
                summary, [sc], rows, ["efficiency", "social"], f"Social measures — {sc.upper()}"
            )
        )
        parts.append(
            measure_table(
                summary,
                [sc],
                rows,
                ["smoothness", "collisions"],
                f"Smoothness and collisions by kind — {sc.upper()}",
            )
        )
    return "\n".join(parts) + "\n"


def social_figures(
    out: Path, records: Sequence[Mapping[str, Any]], rows: Sequence[str]
) -> dict[str, str]:
    """The nearest-person clearance over time per row (violins) and, per scenario, where each
    row's robot drives (occupancy), from the records' per-step series."""
    from pioneer.eval.social import HALL_ZONES
    from pioneer.sim.scenarios import get_scenario
    from pioneer.viz.social import plot_clearance_distribution, plot_occupancy

    clear: dict[str, dict[str, list[float]]] = {sc: {} for sc in SCENARIOS}
    # every step's robot x and y, kept as two flat lists (pairs of 3 M steps cost seconds)
    steps: dict[str, dict[str, tuple[list[float], list[float]]]] = {sc: {} for sc in SCENARIOS}
    for r in records:
        series = r.get("series")
        if r["scenario"] not in clear or not isinstance(series, Mapping):
            continue
        c = clear[r["scenario"]].setdefault(r["policy"], [])
        c.extend(x for x in series["clearance"] if x is not None)
        if len(series["x"]) != len(series["y"]):
            raise DataError(
                expect(
                    f"a {r['policy']} record's series",
                    "x and y of equal length",
                    (len(series["x"]), len(series["y"])),
                    "delete the record's line (its episode runs again) or use a new --out",
                )
            )
        xs, ys = steps[r["scenario"]].setdefault(r["policy"], ([], []))
        xs.extend(series["x"])
        ys.extend(series["y"])
    where = {sc: {pol: np.column_stack(xy) for pol, xy in by.items()} for sc, by in steps.items()}

    def ordered(d: Mapping[str, Any]) -> dict[str, Any]:
        return {row: d[row] for row in rows if row in d}

    figs: dict[str, str] = {}
    if not any(where.values()):
        return figs
    plot_clearance_distribution(
        {sc.upper(): ordered(clear[sc]) for sc in SCENARIOS},
        out / "figures" / "clearance_distribution.png",
        zones=HALL_ZONES,
        title="Nearest person's clearance over every step of every episode (Hall's zones shaded)",
        contact=get_scenario(SCENARIOS[0]).sim.robot.radius,
    )
    figs["nearest-person clearance over time, per policy"] = "figures/clearance_distribution.png"
    for sc in SCENARIOS:
        if not where[sc]:
            continue
        plot_occupancy(
            get_scenario(sc).world(),
            ordered(where[sc]),
            out / "figures" / f"{sc}-occupancy.png",
            title=f"{sc.upper()} · where each policy's robot drives (all evaluation episodes)",
        )
        figs[f"{sc} occupancy of the robot, per policy"] = f"figures/{sc}-occupancy.png"
    return figs


def figures(out: Path, reward_tpl: str) -> dict[str, str]:
    """The static study (paper Fig. 3) and, per scenario, its world at t = 0 and the
    teacher's first evaluation episode as a plot and a GIF; titles → paths in ``out``."""
    from pioneer.control.teacher import make_teacher
    from pioneer.data import shipped_demos
    from pioneer.eval.episode import run_episode
    from pioneer.experiments.static_study import run_static_study
    from pioneer.reward.dataset import Dataset
    from pioneer.sim.scenarios import get_scenario, sample_state
    from pioneer.viz import plot_trajectory, render_frame, save_gif

    figs: dict[str, str] = {}
    study = run_static_study(Dataset.load(shipped_demos("static")), out / "figures")
    figs["static study (paper Fig. 3)"] = "figures/static_study.png"
    for sc in SCENARIOS:
        scenario = get_scenario(sc)
        start = sample_state(scenario, np.random.default_rng(episode_seed(sc, 0, 0)))
        png = out / "figures" / f"{sc}-world.png"
        plot_trajectory(scenario.world(), [start], png, title=f"{sc} · the world at t = 0")
        figs[f"{sc} world (initial state of evaluation seed 0, trial 0)"] = (
            f"figures/{sc}-world.png"
        )
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
    figs["_study"] = to_json({k: v for k, v in study.items() if k != "figure"})
    return figs


def index_page(
    profile: str,
    prof: Profile,
    tables: str,
    figs: dict[str, str],
    times: tuple[float, float],
    n: int,
    seed_set: str = "evaluation",
) -> str:
    """The report; ``times`` = (this invocation's wall time, the episodes' summed run time,
    over every invocation of a resumed run) [s]."""
    elapsed, episode_s = times
    study = json.loads(figs.pop("_study"))
    lines = [
        "# PioneeR — reproduction report",
        "",
        f"Profile `{profile}`: {prof.seeds} seeds × {prof.trials} trials per scenario and "
        f"policy ({n} episodes), {elapsed / 60:.1f} min in the last invocation; the episodes "
        f"ran for {episode_s / 60:.1f} min in all, summed over the workers and over every "
        "invocation of a resumed run. "
        f"Episodes on {seed_set} seeds (pioneer.seeds). Command: `pioneer reproduce --profile "
        f"{profile}{'' if seed_set == 'evaluation' else ' --seed-set ' + seed_set}`.",
        "",
        "The CrowdNav++ and SB3 PPO rows (Table I) are the shipped weights; how they were "
        "trained: src/pioneer/data/baselines/README.md. Tables I–II: `teacher-paper` and "
        "`teacher-paper-no-*` are the paper's teacher and its ablations (no soft margins; "
        "it stops when no command is feasible), the rows compared with the paper; `teacher` "
        "and `teacher-no-*` are ours, which the students imitate: soft margins to people "
        "and walls and the evade fallback (docs/teacher.md).",
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
