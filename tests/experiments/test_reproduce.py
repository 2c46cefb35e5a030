"""End to end: ``pioneer reproduce --profile smoke`` writes every table, figure and report."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pioneer.cli import main
from pioneer.data import STUDENT_SEEDS
from pioneer.eval.harness import read_records
from pioneer.eval.metrics import RANGES
from pioneer.experiments.reproduce import (
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
    rows_i = (*PAPER_TEACHERS, *TEACHERS, *BASELINES, *CLASSIC, *student_rows, SHIELD)
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


@pytest.mark.parametrize("warm", [True, False])
def test_the_expected_time_is_announced_before_the_work(tmp_path, capsys, monkeypatch, warm):
    import pioneer.experiments.reproduce as rep

    paper_rows = (
        "teacher", "teacher-no-goal", "teacher-no-density", "teacher-no-obstacle", "cvar-bf",
        "crowdnav++",
    )  # fmt: skip
    extra_rows = ("teacher-paper", "goal")
    rows = [*paper_rows, *extra_rows]  # ≥ 10 min on 2 workers: announced in whole minutes
    times = rep.episode_times()
    per_episode = sum(times.episode_s[row] for row in rows)
    assert rep.expected_seconds(rows, 1000, 2) == pytest.approx(per_episode * 500)
    assert rep.expected_seconds(rows, 1000, 1) == pytest.approx(per_episode * 1000)
    assert rep.expected_seconds(["unknown"], 10, 1) == pytest.approx(10 * times.default_episode_s)
    monkeypatch.setattr(rep, "jit_cache_warm", lambda: warm)
    rep._announce("paper", rep.PROFILES["paper"], rows, tmp_path, workers=2)
    line = capsys.readouterr().err.strip()
    assert line.startswith("pioneer reproduce --profile paper: 8,000 episodes (0 done)")
    paper = sum(times.episode_s[row] for row in paper_rows) * 500 / 60
    extra = sum(times.episode_s[row] for row in extra_rows) * 500 / 60
    fixed = (times.overhead_s + (0.0 if warm else times.cold_jit_s)) / 60
    compiling = "" if warm else ", compiling the kernels"
    assert paper + extra + fixed >= 10.0, "the rows' episode times fell: take more rows"
    assert (
        f"expected ≈ {paper + extra + fixed:.0f} min (the paper's rows {paper:.0f}, the extra "
        f"rows {extra:.0f}, start-up{compiling} and report {fixed:.0f}) with 2 worker(s)"
    ) in line
    # the machine the times come from, by name (not "the reference machine": another host)
    assert (
        f"the one these times were measured on ({times.machine_short()}, {times.measured}" in line
    )


def test_the_announced_machine_is_named_without_its_feature_list():
    from pioneer.experiments.reproduce import EpisodeTimes

    def named(machine: str) -> str:
        return EpisodeTimes({}, 0.1, 0.0, 0.0, "2026-01-01", machine).machine_short()

    assert named("AMD EPYC (znver4: sse4.2+avx+avx2), 2 CPUs, Linux-6") == "AMD EPYC (znver4)"
    assert named("Intel Xeon, 2 CPUs") == "Intel Xeon"
    assert named("") == "unknown"


def test_a_short_run_is_announced_in_tenths_of_a_minute(tmp_path, capsys, monkeypatch):
    import pioneer.experiments.reproduce as rep

    monkeypatch.setattr(rep, "jit_cache_warm", lambda: False)
    rep._announce("smoke", rep.PROFILES["smoke"], ["goal"], tmp_path, workers=1)
    line = capsys.readouterr().err.strip()
    times = rep.episode_times()
    episodes = times.episode_s["goal"] * 2 / 60
    fixed = (times.overhead_s + times.cold_jit_s) / 60
    assert f"expected ≈ {episodes + fixed:.1f} min (the paper's rows 0.0, the extra rows" in line
    assert f"start-up, compiling the kernels and report {fixed:.1f})" in line


def test_the_shipped_episode_times_cover_every_row_of_the_run():
    from pioneer.experiments.reproduce import episode_times

    times = episode_times()
    rows = (*TEACHERS, *BASELINES, *CLASSIC, *STUDENTS, SHIELD)
    assert set(rows) <= set(times.episode_s)
    assert all(s > 0 for s in times.episode_s.values())
    assert times.measured and times.machine  # a measurement names its date and machine


def test_episode_times_round_trip_and_refuse_bad_files(tmp_path):
    from pioneer.errors import DataError
    from pioneer.experiments.reproduce import episode_times, load_episode_times

    p = tmp_path / "times.json"
    p.write_text(json.dumps(episode_times().to_dict()))
    assert load_episode_times(p) == episode_times()
    bad = {**episode_times().to_dict(), "overhead_s": -1}
    p.write_text(json.dumps(bad))
    with pytest.raises(DataError, match="overhead_s"):
        load_episode_times(p)
    p.write_text(json.dumps({"format": "something/1"}))
    with pytest.raises(DataError, match="format"):
        load_episode_times(p)
    with pytest.raises(DataError, match="readable JSON"):
        load_episode_times(tmp_path / "absent.json")


def test_the_benchmark_script_updates_the_rows_it_measured(monkeypatch):
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2]))  # the repository
    from benchmarks import episode_times as bench

    from pioneer.experiments.reproduce import episode_times

    old = episode_times()
    records = [
        {"policy": "goal", "wall_time_s": 0.2},
        {"policy": "goal", "wall_time_s": 0.4},
        {"policy": "my-policy", "wall_time_s": 1.0},
    ]
    new = bench.updated(old, records, "2030-01-02", "a machine", scale=2.0)
    assert new.of("goal") == pytest.approx(0.15) and new.of("my-policy") == pytest.approx(0.5)
    assert new.of("teacher") == old.of("teacher")  # not in the run: kept
    assert new.measured == "2030-01-02" and new.machine == "a machine"
    assert "divided by 2" in new.source
    assert any("cvar-bf" in n and old.measured in n for n in new.notes)  # kept rows named


def test_the_jit_cache_is_found_where_numba_keeps_it(tmp_path, monkeypatch):
    from numba.core import config

    from pioneer.experiments.reproduce import jit_cache_warm

    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path / "numba"))
    assert not jit_cache_warm()
    index = tmp_path / "numba" / "work_src_pioneer_sim" / "kernel.step_kernel-39.py311.nbi"
    index.parent.mkdir(parents=True)
    index.write_bytes(b"")
    assert not jit_cache_warm()  # the teacher's rollout kernel is compiled on its own
    (index.parent / "lanes.trajectory_kernel_lanes-75.py311.nbi").write_bytes(b"")
    assert jit_cache_warm()


def test_the_report_says_where_the_time_went(smoke: Path) -> None:
    """Per row: episodes and summed run time; the paper's rows apart from the extra ones."""
    from pioneer.experiments.reproduce import PAPER_ROWS, row_times

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
