"""End to end: ``pioneer reproduce --profile smoke`` writes every table, figure and report."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pioneer.cli import main
from pioneer.data import STUDENT_SEEDS
from pioneer.eval.harness import read_records
from pioneer.eval.metrics import RANGES
from pioneer.experiments.reproduce_plan import (
    ARRIVING,
    BASELINES,
    CLASSIC,
    PAPER_STUDENT,
    PAPER_TEACHERS,
    SCENARIOS,
    SHIELD,
    STUDENTS,
    TEACHERS,
    UNCERTAINTY_KEY,
    student_specs,
)


@pytest.fixture(scope="module")
def smoke(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("reproduce") / "smoke"
    assert main(["reproduce", "--profile", "smoke", "--out", str(out), "--workers", "2"]) == 0
    return out


def test_the_uncertainty_key_names_the_paper_threshold() -> None:
    # uncertainty.json files already written are read by this key: it must not drift
    assert UNCERTAINTY_KEY == "threshold_0.8m"


def test_every_row_is_evaluated_once(smoke: Path) -> None:
    recs = read_records(smoke / "eval" / "episodes.jsonl")
    rows = {(r["scenario"], r["policy"]) for r in recs}
    student_rows = [p.row for p in student_specs()]
    rows_i = (*PAPER_TEACHERS, *TEACHERS, *BASELINES, *ARRIVING, *CLASSIC, *student_rows, SHIELD)
    expected = {(sc, p) for sc in SCENARIOS for p in rows_i}
    assert rows == expected
    assert len(recs) == len(expected)  # 1 seed × 1 trial each
    students = [r for r in recs if r["policy"] in (*student_rows, SHIELD)]
    assert all(len(r["frames"]["clearance"]) == r["steps"] for r in students)


def test_the_report_has_tables_i_to_iv_and_its_figures(smoke: Path) -> None:
    index = (smoke / "index.md").read_text()
    for title in ("Table I", "Table II", "Table III", "Table III over DAgger seeds", "Table IV"):
        assert title in index
    for name in (*STUDENTS, PAPER_STUDENT):  # every student over its seeds
        assert f"| HR-RL | {name} | {len(STUDENT_SEEDS)} |" in index
    for row in ("crowdnav++", "cvar-bf", "student-mdn", "student-mlp", SHIELD):
        assert f"| {row}" in index or f"{row} |" in index
    unc = json.loads((smoke / "uncertainty.json").read_text())
    assert set(unc[UNCERTAINTY_KEY]) == set(SCENARIOS)
    for sc in SCENARIOS:
        r = unc[UNCERTAINTY_KEY][sc]
        assert r["frames_safe"] + r["frames_risky"] > 0
    for fig in ("static_study.png", "uncertainty_safe_risky.png", "hr-rl-teacher.gif"):
        assert (smoke / "figures" / fig).stat().st_size > 0
    for name in ("summary.json", "summary.md", "summary.csv"):
        assert (smoke / name).stat().st_size > 0


def test_tables_i_and_ii_carry_the_papers_teacher_and_ours(smoke: Path) -> None:
    """Table II: the paper's teacher and its three ablations (the rows with the paper's values)
    and ours with its three; Table I: both teachers."""
    index = (smoke / "index.md").read_text()
    table_ii = index.split("**Table II")[1].split("**Table III")[0]
    for sc in SCENARIOS:
        rows = [
            line.split(" | ")[1]
            for line in table_ii.splitlines()
            if line.startswith(f"| {sc.upper()} |")
        ]
        assert rows == [*PAPER_TEACHERS, *TEACHERS]
    paper_cells = {
        line.split(" | ")[1]: line.split(" | ")[5]
        for line in table_ii.splitlines()
        if line.startswith("| HR-RL |")
    }
    assert paper_cells["teacher-paper-no-density"] == "83.0 / 13.61 / 4.55"
    assert paper_cells["teacher-no-density"] == "–"  # ours: no paper value beside it
    table_i = index.split("**Table I —")[1].split("**Table II")[0]
    assert "| HR-RL | teacher-paper | " in table_i and "| HR-RL | teacher | " in table_i


def test_the_report_has_the_social_measures_and_their_figures(smoke: Path) -> None:
    index = (smoke / "index.md").read_text()
    assert "## Social navigation measures" in index
    for sc in SCENARIOS:
        assert f"**Social measures — {sc.upper()}**" in index
        assert f"**Smoothness and collisions by kind — {sc.upper()}**" in index
        assert f"(figures/{sc}-occupancy.png)" in index
        assert (smoke / "figures" / f"{sc}-occupancy.png").stat().st_size > 0
    assert "(figures/clearance_distribution.png)" in index
    assert (smoke / "figures" / "clearance_distribution.png").stat().st_size > 0
    for row in ("teacher", "dwa", SHIELD):
        assert any(line.startswith(f"| HR-RL | {row} |") for line in index.splitlines()), row
    recs = read_records(smoke / "eval" / "episodes.jsonl")
    assert all(len(r["series"]["x"]) == r["steps"] + 1 for r in recs)


def test_no_interval_in_the_report_exceeds_its_quantitys_range(smoke: Path) -> None:
    """One seed: the intervals are over episodes (Wilson for rates) and say so."""
    summary = json.loads((smoke / "summary.json").read_text())
    for entry in summary.values():
        assert entry["interval"] == "episodes"
        for metric, (low, high) in RANGES.items():
            cell = entry[metric]
            if cell["mean"] is not None:
                assert low <= cell["lo"] <= cell["mean"] <= cell["hi"] <= high, (metric, cell)
    assert "95 % CI over episodes (1 seed," in (smoke / "index.md").read_text()


def test_a_rerun_resumes_without_new_episodes(smoke: Path) -> None:
    before = (smoke / "eval" / "episodes.jsonl").read_text()
    assert main(["reproduce", "--profile", "smoke", "--out", str(smoke), "--workers", "1"]) == 0
    assert (smoke / "eval" / "episodes.jsonl").read_text() == before
    # the report counts the episodes' run time over every invocation, not only the last one
    recs = read_records(smoke / "eval" / "episodes.jsonl")
    total_min = sum(r["wall_time_s"] for r in recs) / 60
    assert f"the episodes ran for {total_min:.1f} min in all" in (smoke / "index.md").read_text()


def test_the_announcement_names_the_run_and_stays_one_short_line(tmp_path, capsys):
    import pioneer.experiments.reproduce as rep
    from pioneer.experiments.reproduce_plan import PROFILES

    rep._announce("smoke", PROFILES["smoke"], ["goal", "teacher-paper"], tmp_path, workers=8)
    line = capsys.readouterr().err.strip()
    assert line.startswith("pioneer reproduce --profile smoke: 4 episodes (0 done), expected ≈ ")
    assert "\n" not in line and len(line) < 300


def test_the_report_says_where_the_time_went(smoke: Path) -> None:
    """Per row: episodes and summed run time; the paper's rows apart from the extra ones."""
    from pioneer.experiments.reproduce_plan import PAPER_ROWS
    from pioneer.experiments.timing import row_times

    recs = read_records(smoke / "eval" / "episodes.jsonl")
    index = (smoke / "index.md").read_text()
    section = index[index.index("## Where the time went") :]
    times = row_times(recs)
    assert set(times) == {r["policy"] for r in recs}
    for row, (n, sec) in times.items():
        part = "paper" if row in PAPER_ROWS else "extra"
        assert f"| {row} | {part} | {n} | {sec / 60:.1f} |" in section
    paper = sum(sec for row, (_, sec) in times.items() if row in PAPER_ROWS)
    assert f"The paper's rows (Tables I–IV) ran {paper / 60:.1f} CPU-min" in section
    assert set(PAPER_ROWS) == {*PAPER_TEACHERS, *BASELINES, *STUDENTS}
