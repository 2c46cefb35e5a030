"""``pioneer summarize RUN_DIR``: the run's own numbers from its records alone; old records
leave the measure columns empty with one note; bad input is one line, exit 2, nothing
written. ``pioneer eval --metrics`` chooses the tables printed."""

from __future__ import annotations

import json
import re

import pytest

from pioneer.cli import main
from pioneer.eval.harness import EPISODES_FILE
from pioneer.eval.metrics import MEASURES
from pioneer_testutils import file_tree, one_error_line

SUMMARIES = ("summary.json", "summary.md", "summary.csv")


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory):
    """A tiny evaluation: the goal driver and the teacher, 1 seed × 1 trial, in static."""
    out = tmp_path_factory.mktemp("summarize") / "run"
    argv = ["eval", "--scenario", "static", "--policy", "goal", "teacher", "--out", str(out)]
    assert main([*argv, "--seeds", "1", "--trials", "1", "--workers", "1"]) == 0
    return out


def test_summarize_gives_the_numbers_of_the_run_itself(run, capsys, tmp_path):
    written = {name: (run / name).read_bytes() for name in SUMMARIES}
    for name in SUMMARIES:
        (run / name).unlink()
    capsys.readouterr()
    assert main(["summarize", str(run)]) == 0
    printed = capsys.readouterr()
    assert {name: (run / name).read_bytes() for name in SUMMARIES} == written
    assert "static/teacher: SR 100.0%" in printed.out and printed.err == ""
    assert "**Navigation performance**" in printed.out
    assert "**Collisions by kind (% of episodes)**" in printed.out  # the default: paper
    assert "**Social distances**" not in printed.out
    summary = json.loads(written["summary.json"])
    teacher = summary["static/teacher"]
    assert set(MEASURES) <= set(teacher) and teacher["measured"] == 1
    assert 0.0 < teacher["spl"]["mean"] <= 1.0
    assert summary["static/goal"]["robot_into_person_rate"]["mean"] == 100.0
    assert summary["static/goal"]["other_person_collision_rate"]["mean"] == 100.0  # "static"


@pytest.mark.parametrize(
    ("metrics", "titles", "absent"),
    [
        ("social", ("Efficiency", "Smoothness", "Social distances", "Collisions"), "SR ↑"),
        ("all", ("Navigation performance", "Efficiency", "Social distances"), None),
    ],
)
def test_metrics_chooses_the_tables_printed(run, capsys, metrics, titles, absent):
    assert main(["summarize", str(run), "--metrics", metrics]) == 0
    out = capsys.readouterr().out
    for title in titles:
        assert f"**{title}" in out
    if absent:
        assert absent not in out


def test_old_records_leave_the_measure_columns_empty_with_one_note(run, tmp_path, capsys):
    old = tmp_path / "old"
    old.mkdir()
    lines = []
    for line in (run / EPISODES_FILE).read_text().splitlines():
        rec = json.loads(line)
        del rec["measures"], rec["series"]
        rec["format"] = 2
        lines.append(json.dumps(rec))
    (old / EPISODES_FILE).write_text("\n".join(lines) + "\n")
    # asked for the social measures, records that hold none are refused, nothing written
    before = file_tree(tmp_path)
    code = main(["summarize", str(old), "--metrics", "all"])
    one_error_line(capsys.readouterr().err, code, "format 3")
    assert file_tree(tmp_path) == before
    # the paper's metrics (the default) are all there; the measure columns stay empty
    assert main(["summarize", str(old)]) == 0
    assert main(["summarize", str(old), "--metrics", "paper"]) == 0
    capsys.readouterr()
    assert main(["summarize", str(old)]) == 0
    captured = capsys.readouterr()
    notes = captured.err.strip().splitlines()
    assert len(notes) == 1 and notes[0].startswith("pioneer: note: 2 of 2 episodes")
    assert "re-run" in notes[0]
    summary = json.loads((old / "summary.json").read_text())
    goal = summary["static/goal"]
    assert goal["collision_rate"]["mean"] == 100.0  # the paper's metrics are all there
    assert goal["measured"] == 0 and goal["spl"]["mean"] is None  # NaN → null
    assert "| STATIC | goal |" in captured.out  # the paper's table with collisions by kind


@pytest.mark.parametrize("case", ["missing", "empty", "reproduce", "corrupt", "no-records"])
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys, case):
    target = tmp_path / "target"
    needle = {"missing": "an existing folder", "empty": EPISODES_FILE}.get(case, "")
    if case != "missing":
        target.mkdir()
    if case == "reproduce":
        (target / "eval").mkdir()
        (target / "eval" / EPISODES_FILE).write_text("{}\n")
        needle = str(target / "eval")
    if case == "corrupt":
        (target / EPISODES_FILE).write_text("{not json}\n")
        needle = "line 1"
    if case == "no-records":
        (target / EPISODES_FILE).write_text("")
        needle = "at least one episode record"
    before = file_tree(tmp_path)
    code = main(["summarize", str(target)])
    one_error_line(capsys.readouterr().err, code, needle)
    assert file_tree(tmp_path) == before


def test_an_unknown_metric_set_is_refused(run, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["summarize", str(run), "--metrics", "everything"])
    assert exc.value.code == 2
    assert "everything" in capsys.readouterr().err


def test_the_summary_line_shows_no_time_without_a_success(run, capsys):
    """The go-to-goal robot collides in every episode: TT and PL (over successes) are
    not available, said once."""
    assert main(["summarize", str(run)]) == 0
    line = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("static/goal:")]
    assert len(line) == 1
    assert line[0].startswith("static/goal: SR 0.0%  TT, PL – (no successes)  (")


def test_the_summary_line_shows_time_and_length_of_the_successes(run, capsys):
    assert main(["summarize", str(run)]) == 0
    line = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("static/teacher:")]
    assert len(line) == 1
    assert re.fullmatch(
        r"static/teacher: SR 100\.0%  TT \d+\.\d\d s  PL \d+\.\d\d m  \(1 episodes\)", line[0]
    )
