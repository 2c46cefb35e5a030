"""``pioneer run`` with the teacher and ``pioneer eval``: records, labels, resume, one-line
errors with exit code 2, one line and exit code 143 when a signal stops it."""

from __future__ import annotations

import json
import shlex
import signal
import subprocess

import pytest

import pioneer.eval.harness as harness
from pioneer.cli import main
from pioneer.control.teacher import make_teacher
from pioneer.eval.episode import run_episode
from pioneer.eval.harness import EPISODES_FILE, read_records
from pioneer_testutils import run_cli


def _one_error_line(err: str) -> str:
    lines = err.strip("\n").splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("pioneer: error:")
    return lines[0]


def _pioneer(*argv: str) -> subprocess.CompletedProcess[str]:
    """The CLI in a fresh interpreter (exit code and stderr as a user sees them)."""
    return run_cli(*argv, timeout=300)


def _eval_argv(out, *extra):
    return ["eval", "--scenario", "static", "--out", str(out), "--workers", "1", *extra]


# --------------------------------------------------------------------------------------------
# pioneer run


def test_run_teacher_prints_a_json_record(capsys):
    assert main(["run", "--scenario", "hr-rl", "--policy", "teacher", "--seed", "0"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1
    rec = json.loads(out[0])
    assert (rec["scenario"], rec["policy"], rec["seed"]) == ("hr-rl", "teacher", 0)
    assert rec["event"] in {"success", "collision", "timeout"}
    assert rec["steps"] > 0
    assert rec["time_s"] == pytest.approx(0.1 * rec["steps"])


def test_run_no_density_names_the_ablation_and_matches_a_direct_run(capsys):
    argv = ["run", "--scenario", "hr-rl", "--policy", "teacher", "--seed", "2", "--no-density"]
    assert main(argv) == 0
    rec = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert rec["policy"] == "teacher-no-density"
    direct, _ = run_episode("hr-rl", make_teacher("hr-rl", density=False), 2)
    expected = {**direct.to_dict(), "policy": "teacher-no-density"}
    expected.pop("series")  # the printed record is the short one (no per-step series)
    assert rec == expected


def test_run_unknown_policy_exits_2_with_one_line():
    proc = _pioneer("run", "--policy", "nope")
    assert proc.returncode == 2
    line = _one_error_line(proc.stderr)
    assert "policy" in line and "nope" in line and "teacher" in line  # lists the choices
    assert proc.stdout == ""


def test_run_ablation_flag_with_a_non_teacher_policy_is_a_one_line_error(capsys):
    try:
        code = main(["run", "--scenario", "static", "--policy", "goal", "--no-density"])
    except TypeError:
        code = 1
    assert code == 2
    assert "density" in _one_error_line(capsys.readouterr().err)


# --------------------------------------------------------------------------------------------
# pioneer eval


def test_eval_writes_records_and_summary_then_resumes(tmp_path, capsys):
    out = tmp_path / "ev"
    assert main(_eval_argv(out, "--policy", "goal", "--seeds", "2", "--trials", "2")) == 0
    stdout = capsys.readouterr().out
    assert "static/goal: SR 0.0%" in stdout
    assert "(4 episodes)" in stdout
    lines = (out / EPISODES_FILE).read_text().splitlines()
    assert len(lines) == 4
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary) == ["static/goal"]
    assert summary["static/goal"]["collision_rate"]["mean"] == 100.0
    assert summary["static/goal"]["seeds"] == 2
    # the same command again: nothing new runs, nothing is duplicated
    assert main(_eval_argv(out, "--policy", "goal", "--seeds", "2", "--trials", "2")) == 0
    assert "(4 episodes)" in capsys.readouterr().out
    assert (out / EPISODES_FILE).read_text().splitlines() == lines


def test_eval_stopped_by_sigterm_names_the_kept_records_and_the_command(
    tmp_path, capsys, monkeypatch
):
    """In this process (one worker): SIGTERM during the third episode → exit 143, one line,
    the two finished records kept; the same command completes the set."""
    real, started = harness.run_task, []

    def signalled_on_the_third(task):
        started.append(task.key)
        if len(started) == 3:
            signal.raise_signal(signal.SIGTERM)
        return real(task)

    monkeypatch.setattr(harness, "run_task", signalled_on_the_third)
    out = tmp_path / "ev"
    argv = _eval_argv(out, "--policy", "goal", "--seeds", "1", "--trials", "4")
    assert main(argv) == 143
    path = out / EPISODES_FILE
    assert capsys.readouterr().err.splitlines()[-1] == (
        f"pioneer: interrupted (SIGTERM); 2 of 4 episodes kept in {path}; "
        f"resume with: {shlex.join(['pioneer', *argv])}"
    )
    kept = path.read_text().splitlines()
    assert len(kept) == 2
    assert main(argv) == 0
    lines = path.read_text().splitlines()
    assert lines[:2] == kept
    keys = [(r["policy"], r["trial"]) for r in map(json.loads, lines)]
    assert sorted(keys) == [("goal", t) for t in range(4)]


def test_eval_no_density_labels_only_the_teacher(tmp_path, capsys):
    out = tmp_path / "ev"
    argv = _eval_argv(out, "--policy", "teacher", "goal", "--no-density")
    assert main([*argv, "--seeds", "1", "--trials", "1"]) == 0
    recs = [json.loads(x) for x in (out / EPISODES_FILE).read_text().splitlines()]
    assert sorted(r["policy"] for r in recs) == ["goal", "teacher-no-density"]
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary) == {"static/goal", "static/teacher-no-density"}
    stdout = capsys.readouterr().out
    assert "static/teacher-no-density: SR" in stdout


@pytest.mark.parametrize(
    ("flag", "value"), [("--seeds", "0"), ("--trials", "0"), ("--seeds", "-1")]
)
def test_eval_bad_counts_exit_2_with_one_line(tmp_path, capsys, flag, value):
    out = tmp_path / "ev"
    argv = _eval_argv(out, "--policy", "goal", "--seeds", "1", "--trials", "1")
    argv[argv.index(flag) + 1] = value
    assert main(argv) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert "seeds/trials" in line and "expected" in line and "fix" in line
    assert not out.exists()


@pytest.mark.parametrize(
    ("scenarios", "policies"), [(["static"], ["goal", "nope"]), (["static", "nope"], ["goal"])]
)
def test_eval_unknown_name_exits_2(tmp_path, capsys, scenarios, policies):
    out = tmp_path / "ev"
    argv = ["eval", "--scenario", *scenarios, "--policy", *policies, "--out", str(out)]
    assert main([*argv, "--seeds", "1", "--trials", "1", "--workers", "1"]) == 2
    last = capsys.readouterr().err.strip("\n").splitlines()[-1]
    assert last.startswith("pioneer: error:")
    assert "nope" in last and "expected one of" in last


@pytest.mark.parametrize(
    ("scenarios", "policies"), [(["static"], ["goal", "nope"]), (["static", "nope"], ["goal"])]
)
def test_eval_checks_names_before_running_anything(tmp_path, capsys, scenarios, policies):
    out = tmp_path / "ev"
    argv = ["eval", "--scenario", *scenarios, "--policy", *policies, "--out", str(out)]
    assert main([*argv, "--seeds", "1", "--trials", "3", "--workers", "1"]) == 2
    assert "nope" in _one_error_line(capsys.readouterr().err)
    records = out / EPISODES_FILE
    assert not records.exists() or records.read_text() == ""


def test_eval_on_a_corrupt_records_file_exits_2_naming_the_line(tmp_path, capsys):
    out = tmp_path / "ev"
    assert main(_eval_argv(out, "--policy", "goal", "--seeds", "1", "--trials", "2")) == 0
    path = out / EPISODES_FILE
    first, second = path.read_text().splitlines()
    corrupt = f"{first}\n{{not json}}\n{second}\n"
    path.write_text(corrupt)
    capsys.readouterr()
    assert main(_eval_argv(out, "--policy", "goal", "--seeds", "1", "--trials", "3")) == 2
    captured = capsys.readouterr()
    line = _one_error_line(captured.err)
    assert "line 2" in line and EPISODES_FILE in line
    assert "{not json}" in line
    assert captured.out == ""
    assert path.read_text() == corrupt


# --------------------------------------------------------------------------------------------
# pioneer --scenarios FILE: scenario variants reach the spawned evaluation workers

_VARIANTS = {
    "format": "pioneer.scenarios/1",
    "scenarios": {
        "static-short": {"static": {"width": 5.0}, "sim": {"time_limit": 3.0}},
        "hr-rl-wide": {
            "elevator": {"lobby_width": 5.0},
            "sim": {"time_limit": 2.0},
            "base": "hr-rl",
        },
    },
}


@pytest.fixture
def variant_file(tmp_path, scenario_registry):
    path = tmp_path / "variants.json"
    path.write_text(json.dumps(_VARIANTS))
    return path


def _eval_records(out, *argv):
    """Run ``pioneer *argv eval … --out out`` and return the episode records."""
    assert main([*argv, "--out", str(out)]) == 0
    return read_records(out / EPISODES_FILE)


def test_scenarios_option_runs_a_variant_in_two_worker_processes(variant_file, tmp_path):
    argv = ["--scenarios", str(variant_file), "eval", "--scenario", "static-short"]
    argv += ["--policy", "goal", "--seeds", "1", "--trials", "4", "--workers", "2"]
    recs = _eval_records(tmp_path / "ev", *argv)
    assert len(recs) == 4 and {r["scenario"] for r in recs} == {"static-short"}
    assert all(r["time_s"] <= 3.0 + 1e-9 for r in recs)  # the variant's time limit, not 30 s


def test_a_variant_with_a_base_runs_the_shipped_student_in_workers(variant_file, tmp_path):
    argv = ["--scenarios", str(variant_file), "eval", "--scenario", "hr-rl-wide"]
    argv += ["--policy", "student-mlp", "--seeds", "1", "--trials", "2", "--workers", "2"]
    recs = _eval_records(tmp_path / "ev", *argv)
    assert [r["policy"] for r in recs] == ["student-mlp"] * 2
    assert all(r["time_s"] <= 2.0 + 1e-9 for r in recs)


def test_scenarios_option_with_a_bad_file_exits_2_with_one_line(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "pioneer.scenarios/1", "scenarios": {"x": {"elevator": {"d": 1}}}}')
    proc = _pioneer("--scenarios", str(bad), "run", "--scenario", "x")
    assert proc.returncode == 2
    line = _one_error_line(proc.stderr)
    assert "bad.json" in line and "'d'" in line


# --------------------------------------------------------------------------------------------
# --policy NAME:key=value,… (own checkpoints, options, row labels)


def test_eval_policy_parameters_reach_the_workers(tmp_path):
    from pioneer.data import shipped_student

    ckpt = shipped_student("hr-rl", "mlp")
    argv = ["eval", "--scenario", "hr-rl", "--seeds", "1", "--trials", "2", "--workers", "2"]
    pols = ["student-mlp", f"student-mlp:checkpoint={ckpt},label=mine"]
    recs = _eval_records(tmp_path / "ev", *argv, "--policy", *pols)
    by_row = {}
    for r in recs:
        by_row.setdefault(r["policy"], []).append(r)
    assert sorted(by_row) == ["mine", "student-mlp"]
    strip = ("policy", "wall_time_s", "decision_ms", "made_by")
    same = [{k: v for k, v in r.items() if k not in strip} for r in by_row["mine"]]
    base = [{k: v for k, v in r.items() if k not in strip} for r in by_row["student-mlp"]]
    assert sorted(same, key=str) == sorted(base, key=str)  # the same checkpoint
    files = {
        row: [r["made_by"]["files"]["checkpoint"]["sha256"] for r in rs]
        for row, rs in by_row.items()
    }
    assert files["mine"] == files["student-mlp"]  # the records say so too


@pytest.mark.parametrize(
    ("policies", "needle"),
    [
        (["student-mlp:chekpoint=x"], "chekpoint"),
        (["goal", "goal"], "label="),
        (["goal:"], "NAME"),
        (["nope:a=1"], "nope"),
    ],
)
def test_eval_bad_policy_parameters_exit_2_with_one_line(tmp_path, policies, needle):
    proc = _pioneer(
        "eval", "--scenario", "static", "--out", str(tmp_path / "e"), "--policy", *policies
    )
    assert proc.returncode == 2
    assert needle in _one_error_line(proc.stderr)
    assert not (tmp_path / "e").exists()


def test_run_with_a_policy_label_and_parameters(capsys):
    assert (
        main(["run", "--scenario", "static", "--policy", "goal:label=my-goal", "--seed", "1"]) == 0
    )
    rec = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert rec["policy"] == "my-goal"


def test_scenarios_command_lists_variants_and_draws_them(variant_file, tmp_path, capsys):
    out = tmp_path / "layouts"
    assert main(["--scenarios", str(variant_file), "scenarios", "--png-dir", str(out)]) == 0
    text = capsys.readouterr().out
    rows = {line.split()[0]: line.split() for line in text.splitlines()[1:] if line.strip()}
    assert rows["hr-rl-wide"][1] == "hr-rl"  # the variant's learned parts
    assert rows["static-short"][1] == "static-short" and rows["hr-rl-r03"][1] == "hr-rl"
    assert rows["static-short"][-1] == "3.0"  # its time limit [s]
    assert rows["hr-rl"][-2] == "100"  # every start-state draw places every body
    assert "placed [%]" in text.splitlines()[0]
    pngs = sorted(p.stem for p in out.glob("*.png"))
    assert {"hr-rl", "hl-rr", "static", "hr-rl-wide", "static-short"} <= set(pngs)
