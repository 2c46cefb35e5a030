"""``pioneer reproduce``: the paper's tables and figures from the shipped demonstrations.

Steps (each output is written atomically; the evaluation resumes if interrupted):
1. fit the density reward of each elevator scenario on its shipped demos → ``models/``;
2. evaluate the teacher, its three ablations, the baselines (paper Tables I–II), and the shipped
   DAgger students — MDN, MLP and the uncertainty-shielded MDN (Table III) — on HR-RL and HL-RR;
3. write ``summary.json``, ``summary.md`` and ``summary.csv`` (our rows beside the paper's) and
   the safe/risky uncertainty analysis of the MDN (Table IV, ``uncertainty.json``, histogram);
4. the social-navigation measures of every row (docs/metrics.md): two tables per scenario, the
   distribution of the nearest person's clearance and a heat map of where each row's robot
   drives;
5. the static-study figure (paper Fig. 3), a trajectory plot and a GIF per scenario;
6. ``index.md``, a report that links everything.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pioneer.data import STUDENT_SEEDS
from pioneer.errors import ConfigError, DataError, expect
from pioneer.eval.episode import RISKY_DISTANCE_M
from pioneer.eval.harness import PolicySpec, episode_seed, evaluate
from pioneer.eval.metrics import summarize
from pioneer.eval.report import write_summary
from pioneer.experiments.timing import announcement, estimate, jit_cache_warm, row_times
from pioneer.io import inside, output_dir_kind, run_lock, to_json, write_text_atomic
from pioneer.parallel import worker_count

__all__ = [
    "PAPER_ROWS",
    "PROFILES",
    "UNCERTAINTY_KEY",
    "Profile",
    "reproduce",
]


@dataclasses.dataclass(frozen=True)
class Profile:
    """How much to run."""

    seeds: int
    trials: int


PROFILES = {
    "smoke": Profile(seeds=1, trials=1),  # the whole pipeline in a minute (tests, CI)
    "quick": Profile(seeds=2, trials=10),
    "paper": Profile(seeds=5, trials=100),
}
SCENARIOS = ("hr-rl", "hl-rr")
# paper Tables I–II: the paper's teacher (no soft margins, the stop fallback) and its ablations,
# the rows compared with the paper; beside them ours (soft margins in tiers, the evade
# fallback: docs/teacher.md), the teacher the students imitate, and its ablations
PAPER_TEACHERS = (
    "teacher-paper",
    "teacher-paper-no-density",
    "teacher-paper-no-goal",
    "teacher-paper-no-obstacle",
)
TEACHERS = ("teacher", "teacher-no-density", "teacher-no-goal", "teacher-no-obstacle")
STUDENTS = ("student-mdn", "student-mlp")  # paper Table III, the shipped DAgger students
PAPER_STUDENT = "student-mdn-paper"  # the paper's DAgger recipe, as a measured row
SHIELD = "student-shield"  # beyond the paper: the MDN handing over to the teacher when unsure
BASELINES = ("cvar-bf", "crowdnav++")  # paper Table I (CrowdNav++: pure PPO, its own recipe)
# beyond the paper, in Table I: CrowdNav++ as its authors' family would train it here (an
# imitation warm start, then PPO on the CrowdNav++ reward without its intrusion term)
ARRIVING = ("crowdnav++-il-teacher",)
# beyond the paper, in Table I: classic references and Stable-Baselines3's PPO with its
# defaults on the environment's own reward
CLASSIC = ("dwa", "sfm", "goal", "sb3-ppo")
PAPER_ROWS = (*PAPER_TEACHERS, *BASELINES, *STUDENTS)  # the rows of the paper's Tables I–IV
SEED_ROW = "{name}-s{seed}"  # the row of a student's other DAgger seeds (seed 0: its name)
# uncertainty.json: the key of the safe/risky split at the paper's threshold (Table IV)
UNCERTAINTY_KEY = f"threshold_{RISKY_DISTANCE_M:g}m"


def _time_table(records: Sequence[dict[str, Any]], workers: int) -> str:
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


def fit_models(out: Path, scenarios: Sequence[str]) -> dict[str, str]:
    """Fit and save the reward of every scenario; returns the model paths."""
    from pioneer.reward.recipe import default_reward

    paths = {}
    for sc in scenarios:
        p = inside(out, f"models/{sc}.reward.npz")
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
    seed_set: str = "evaluation",
    overwrite: bool = False,
) -> dict[str, Any]:
    """Run the whole pipeline on the ``seed_set`` episodes (evaluation seeds for the reported
    tables, validation seeds to check a choice); returns a small summary (paths and headline
    numbers). ``overwrite``: the evaluation starts over (its records in ``OUT/eval`` are
    deleted). One run writes to ``out_dir`` at a time (:func:`pioneer.io.run_lock`)."""
    if profile not in PROFILES:
        raise ConfigError(
            expect("profile", f"one of {sorted(PROFILES)}", profile, "use smoke, quick or paper")
        )
    output_dir_kind(out_dir)
    with run_lock(out_dir) as out:
        return _reproduce(profile, out, workers, progress, extra_policies, seed_set, overwrite)


def _reproduce(
    profile: str,
    out: Path,
    workers: int | None,
    progress: bool,
    extra_policies: Sequence[PolicySpec],
    seed_set: str,
    overwrite: bool,
) -> dict[str, Any]:
    prof = PROFILES[profile]
    t0 = time.perf_counter()
    fit_models(out, SCENARIOS)
    reward_tpl = str(out / "models" / "{scenario}.reward.npz")
    policies = [PolicySpec.make(name, reward=reward_tpl) for name in (*PAPER_TEACHERS, *TEACHERS)]
    extra = [PolicySpec.make(name) for name in (*BASELINES, *ARRIVING, *CLASSIC)]
    extra += list(extra_policies)
    students = student_specs()
    students.append(PolicySpec.make(SHIELD, reward=reward_tpl))
    policies += extra + students
    if progress:
        _announce(profile, prof, [p.row for p in policies], out, workers, fresh=overwrite)
    records = evaluate(
        SCENARIOS,
        policies,
        prof.seeds,
        prof.trials,
        out / "eval",
        workers,
        progress=progress,
        seed_set=seed_set,
        overwrite=overwrite,
    )
    summary = summarize(records)
    md = write_summary(
        out,
        summary,
        [
            (
                "I",
                "Table I — navigation performance",
                SCENARIOS,
                [
                    "teacher-paper",
                    *BASELINES,
                    "teacher",
                    *[p.row for p in extra if p.row not in BASELINES],
                ],
            ),
            (
                "II",
                "Table II — ablation of the reward terms",
                SCENARIOS,
                [*PAPER_TEACHERS, *TEACHERS],
            ),
            (
                "III",
                "Table III — distilled students (shipped DAgger checkpoints) and the "
                "uncertainty shield",
                SCENARIOS,
                [p.row for p in students],
            ),
        ],
    )
    md += _seed_table(summary, [*STUDENTS, PAPER_STUDENT])
    md += _table_iv(out, records)
    rows = [p.row for p in policies]
    md += _social_tables(summary, rows)
    md += _time_table(records, worker_count(workers))
    figures = _social_figures(out, records, rows)
    figures.update(_figures(out, reward_tpl))
    elapsed = time.perf_counter() - t0
    episode_s = sum(float(r.get("wall_time_s", 0.0)) for r in records)
    write_text_atomic(
        out / "index.md",
        _index(profile, prof, md, figures, (elapsed, episode_s), len(records), seed_set),
    )
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


def _announce(
    profile: str,
    prof: Profile,
    rows: Sequence[str],
    out: Path,
    workers: int | None,
    fresh: bool = False,
) -> None:
    """One line before the work: how many episodes, how many are done (none when ``fresh``:
    starting over), the expected time on this machine (:mod:`pioneer.experiments.timing`)."""
    import sys

    from pioneer.eval.harness import EPISODES_FILE, read_records

    per_row = len(SCENARIOS) * prof.seeds * prof.trials
    done = 0 if fresh else len(read_records(out / "eval" / EPISODES_FILE))
    total = per_row * len(rows)
    est = estimate(
        [r for r in rows if r in PAPER_ROWS],
        [r for r in rows if r not in PAPER_ROWS],
        per_row * (1.0 - done / total),
        worker_count(workers),
        cold=not jit_cache_warm(),
    )
    print(announcement(profile, total, done, est), file=sys.stderr, flush=True)


def _table_iv(out: Path, records: Sequence[dict[str, Any]]) -> str:
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


def student_specs() -> list[PolicySpec]:
    """Table III's students: each shipped recipe (and the paper's) at every DAgger seed of
    :data:`pioneer.data.STUDENT_SEEDS`; seed 0 is the row of its name."""
    return [
        PolicySpec.make(name, label=_seed_row(name, seed), seed=seed)
        for name in (*STUDENTS, PAPER_STUDENT)
        for seed in STUDENT_SEEDS
    ]


def _seed_row(name: str, seed: int) -> str:
    return name if seed == 0 else SEED_ROW.format(name=name, seed=seed)


def _seed_table(summary: Mapping[str, Mapping[str, Any]], names: Sequence[str]) -> str:
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
            cells = [summary.get(f"{sc}/{_seed_row(name, s)}") for s in STUDENT_SEEDS]
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


def _social_tables(summary: Mapping[str, Mapping[str, Any]], rows: Sequence[str]) -> str:
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


def _social_figures(
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


def _figures(out: Path, reward_tpl: str) -> dict[str, str]:
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


def _index(
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
