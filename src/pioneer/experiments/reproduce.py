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

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pioneer.errors import ConfigError, expect
from pioneer.eval.harness import PolicySpec, evaluate
from pioneer.eval.metrics import summarize
from pioneer.eval.report import write_summary
from pioneer.experiments.reproduce_plan import (
    ARRIVING,
    BASELINES,
    CLASSIC,
    PAPER_ROWS,
    PAPER_STUDENT,
    PAPER_TEACHERS,
    PROFILES,
    SCENARIOS,
    SHIELD,
    STUDENTS,
    TEACHERS,
    Profile,
    student_specs,
)
from pioneer.experiments.reproduce_report import (
    figures,
    index_page,
    seed_table,
    social_figures,
    social_tables,
    table_iv,
    time_table,
)
from pioneer.experiments.timing import announcement, estimate, jit_cache_warm
from pioneer.io import inside, output_dir_kind, run_lock, write_text_atomic
from pioneer.parallel import worker_count

__all__ = ["fit_models", "reproduce"]


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
    md += seed_table(summary, [*STUDENTS, PAPER_STUDENT])
    md += table_iv(out, records)
    rows = [p.row for p in policies]
    md += social_tables(summary, rows)
    md += time_table(records, worker_count(workers))
    figs = social_figures(out, records, rows)
    figs.update(figures(out, reward_tpl))
    elapsed = time.perf_counter() - t0
    episode_s = sum(float(r.get("wall_time_s", 0.0)) for r in records)
    write_text_atomic(
        out / "index.md",
        index_page(profile, prof, md, figs, (elapsed, episode_s), len(records), seed_set),
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
