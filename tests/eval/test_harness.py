"""Episodes and the evaluation harness (paper §V-B): deterministic episodes and seeds, resumable
records (after a kill, SIGINT, SIGTERM or a torn write), loud failure on a corrupt file, and the
same records from serial, parallel and Ray runs."""

from __future__ import annotations

import functools
import json
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from pioneer.control.registry import build_policy
from pioneer.control.teacher import make_teacher
from pioneer.envs.env import NavEnv
from pioneer.errors import ConfigError, DataError
from pioneer.eval.episode import RECORD_FORMAT, run_episode
from pioneer.eval.harness import (
    EPISODES_FILE,
    PolicySpec,
    Task,
    episode_seed,
    evaluate,
    read_records,
    run_task,
)
from pioneer_testutils import (
    STOP_SIGNALS,
    assert_house_message,
    interrupted_line,
    run_cli,
    stop_cli,
)

TIMING = ("wall_time_s", "decision_ms")
GOAL = PolicySpec.make("goal")  # in "static" it drives into the person: ~20 steps an episode


def _key(r):
    return (r["scenario"], r["policy"], int(r["seed"]), int(r["trial"]))


def _untimed(records):
    """Records without the timing fields, sorted by episode key."""
    return sorted(({k: v for k, v in r.items() if k not in TIMING} for r in records), key=_key)


def _lines(path: Path) -> list[str]:
    return path.read_text().splitlines()


def _expected_keys(scenarios, policies, seeds, trials):
    return {
        (sc, p, s, t)
        for sc in scenarios
        for p in policies
        for s in range(seeds)
        for t in range(trials)
    }


# --------------------------------------------------------------------------------------------
# episodes


def test_same_seed_gives_the_same_episode_bit_for_bit():
    sc, seed = "hr-rl", 3
    rec_a, tr_a = run_episode(sc, make_teacher(sc), seed, record=True)
    rec_b, tr_b = run_episode(sc, make_teacher(sc), seed, record=True)
    assert tr_a is not None and tr_b is not None
    assert rec_a == rec_b
    assert rec_a.to_dict() == rec_b.to_dict()
    assert len(tr_a.states) == len(tr_b.states) == rec_a.steps + 1
    assert np.array_equal(tr_a.robot, tr_b.robot)
    assert np.array_equal(tr_a.humans, tr_b.humans)
    assert all(a == b for a, b in zip(tr_a.states, tr_b.states, strict=True))
    assert not np.array_equal(tr_a.robot[0], tr_a.robot[-1])  # the robot did move
    # while another seed starts from another state
    _, info = NavEnv(sc).reset(seed=seed + 1)
    assert not np.array_equal(info["state"].robot[0], tr_a.robot[0])


def test_episode_record_fields():
    rec, traj = run_episode("static", build_policy("goal"), 0)
    assert traj is None
    d = rec.to_dict()
    assert d["scenario"] == "static" and d["policy"] == "goal" and d["seed"] == 0
    assert d["event"] == "collision"
    assert d["steps"] > 0
    assert d["time_s"] == pytest.approx(0.1 * d["steps"])
    assert d["min_gap_m"] < 0.0  # a collision: negative swept clearance
    assert d["collided_with"] == "human"  # the static study's goal runs into the crowd
    assert 0.0 < d["min_wall_gap_m"] < 5.0
    assert 0.0 < d["time_close_s"] <= d["time_s"]
    json.dumps(d)  # JSON-serialisable


def test_a_wall_collision_says_wall():
    """Facing a wall with no humans around: the record names the wall and its negative gap."""
    from pioneer.sim.scenarios import get_scenario

    class Straight:  # full speed ahead, never turning
        name = "straight"

        def reset(self, info, rng):
            pass

        def act(self, obs, info):
            return np.array([0.8, 0.0])

    sc = get_scenario("hr-rl").replace(name="wall-test", humans=())
    sc = sc.replace(robot_heading=(0.0, 0.0))  # facing +x: the lobby's side wall
    d = run_episode(sc, Straight(), 0)[0].to_dict()
    assert d["event"] == "collision" and d["collided_with"] == "wall"
    assert d["min_wall_gap_m"] < 0.0 and d["min_gap_m"] is None


# --------------------------------------------------------------------------------------------
# episode seeds


def test_episode_seed_is_stable_and_distinct():
    # fixed values: the seed depends on crc32 and SeedSequence only (no salted hash())
    assert episode_seed("hr-rl", 0, 0) == 3059802104
    assert episode_seed("static", 1, 2) == 171176969
    assert episode_seed("hl-rr", 4, 99) == 2840022838
    grid = [(sc, s, t) for sc in ("hr-rl", "hl-rr", "static") for s in range(5) for t in range(40)]
    seeds = [episode_seed(*g) for g in grid]
    assert seeds == [episode_seed(*g) for g in grid]
    assert len(set(seeds)) == len(grid)
    assert all(isinstance(x, int) and 0 <= x < 2**32 for x in seeds)


def test_validation_episodes_are_other_seeds_than_evaluation_episodes():
    from pioneer.seeds import TRAINING_BASE, VALIDATION_BASE

    grid = [(sc, s, t) for sc in ("hr-rl", "hl-rr") for s in range(3) for t in range(50)]
    val = [episode_seed(*g, seed_set="validation") for g in grid]
    assert len(set(val)) == len(grid)
    assert all(VALIDATION_BASE <= x < TRAINING_BASE for x in val)
    assert val == [episode_seed(*g, seed_set="validation") for g in grid]


def test_a_validation_run_records_its_seed_set_and_refuses_to_mix(tmp_path):
    recs = evaluate(
        ["static"], [GOAL], 1, 2, tmp_path, workers=1, progress=False, seed_set="validation"
    )
    for r in recs:
        assert r["seed_set"] == "validation"
        assert r["episode_seed"] == episode_seed("static", r["seed"], r["trial"], "validation")
    with pytest.raises(ConfigError, match="another --out") as exc:
        evaluate(["static"], [GOAL], 1, 3, tmp_path, workers=1, progress=False)
    assert "validation episodes" in str(exc.value)
    with pytest.raises(ConfigError, match="seed set"):
        evaluate(["static"], [GOAL], 1, 1, tmp_path / "x", progress=False, seed_set="test")


def test_eval_cli_takes_the_validation_seed_set(tmp_path):
    from pioneer.cli import main

    out = tmp_path / "val"
    argv = ["eval", "--scenario", "static", "--policy", "goal", "--seeds", "1", "--trials", "2"]
    assert main([*argv, "--seed-set", "validation", "--out", str(out), "--workers", "1"]) == 0
    recs = read_records(out / EPISODES_FILE)
    assert [r["seed_set"] for r in recs] == ["validation", "validation"]


def test_every_record_can_be_replayed_alone(tmp_path):
    recs = evaluate(["static"], [GOAL], 2, 2, tmp_path, workers=1, progress=False)
    for r in recs:
        assert r["episode_seed"] == episode_seed(r["scenario"], r["seed"], r["trial"])
        replay, _ = run_episode(r["scenario"], build_policy("goal"), r["episode_seed"])
        assert {**replay.to_dict(), "seed": r["seed"]} == {k: r[k] for k in replay.to_dict()}
    # every policy meets the same initial states: trials differ from each other
    assert len({r["episode_seed"] for r in recs}) == 4


# --------------------------------------------------------------------------------------------
# records file and resume


def test_evaluate_writes_one_record_per_episode(tmp_path):
    seen = []
    recs = evaluate(
        ["static", "hr-rl"],
        [GOAL],
        2,
        2,
        tmp_path,
        workers=1,
        progress=False,
        on_record=seen.append,
    )
    path = tmp_path / EPISODES_FILE
    assert len(recs) == len(seen) == 8
    assert {_key(r) for r in recs} == _expected_keys(["static", "hr-rl"], ["goal"], 2, 2)
    lines = _lines(path)
    assert len(lines) == 8
    assert [json.loads(x) for x in lines] == seen
    assert read_records(path) == recs
    for r in recs:
        assert r["event"] in {"success", "collision", "timeout"}
        assert r["wall_time_s"] > 0 and r["decision_ms"] > 0


def test_resume_runs_only_the_new_episodes(tmp_path):
    first = []
    evaluate(["static"], [GOAL], 2, 2, tmp_path, workers=1, progress=False, on_record=first.append)
    assert len(first) == 4
    before = _lines(tmp_path / EPISODES_FILE)
    second = []
    recs = evaluate(
        ["static"], [GOAL], 2, 4, tmp_path, workers=1, progress=False, on_record=second.append
    )
    assert len(second) == 4
    assert {(r["seed"], r["trial"]) for r in second} == {(s, t) for s in range(2) for t in (2, 3)}
    lines = _lines(tmp_path / EPISODES_FILE)
    assert lines[:4] == before  # old records untouched
    keys = [_key(json.loads(x)) for x in lines]
    assert len(keys) == len(set(keys)) == 8
    assert set(keys) == _expected_keys(["static"], ["goal"], 2, 4)
    assert len(recs) == 8
    # nothing left to do: nothing runs
    third = []
    evaluate(["static"], [GOAL], 2, 4, tmp_path, workers=1, progress=False, on_record=third.append)
    assert third == []
    assert len(_lines(tmp_path / EPISODES_FILE)) == 8


@pytest.mark.slow
def test_a_killed_run_resumes_with_one_record_per_episode(tmp_path):
    out = tmp_path / "eval"
    path = out / EPISODES_FILE
    seeds, trials = 2, 100  # 200 episodes of ~20 steps: long enough to be killed mid-run
    cmd = [
        sys.executable, "-m", "pioneer.cli", "eval", "--scenario", "static", "--policy", "goal",
        "--seeds", str(seeds), "--trials", str(trials), "--out", str(out), "--workers", "1",
    ]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 300  # a guard against a hang, not a timing assertion
        while time.monotonic() < deadline and proc.poll() is None:
            if path.exists() and path.read_bytes().count(b"\n") >= 1:
                break
            time.sleep(0.002)
        proc.kill()  # SIGKILL: no cleanup, no flush
    finally:
        proc.wait(timeout=60)
    assert proc.returncode == -signal.SIGKILL, "the run should have been killed mid-way"
    written = path.read_bytes().split(b"\n")
    n_before = len(written) - 1  # complete lines
    assert 1 <= n_before < seeds * trials
    print(f"killed after {n_before} of {seeds * trials} records")
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=600, check=False)
    assert res.returncode == 0, res.stderr
    assert "static/goal: SR 0.0%" in res.stdout
    assert f"({seeds * trials} episodes)" in res.stdout
    lines = _lines(path)
    assert len(lines) == seeds * trials
    assert [x.encode() for x in lines[:n_before]] == written[:n_before]
    keys = [_key(json.loads(x)) for x in lines]
    assert len(set(keys)) == len(keys)
    assert set(keys) == _expected_keys(["static"], ["goal"], seeds, trials)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["static/goal"]["episodes"] == seeds * trials


# ~3 s an episode (300 steps of a finer window): a signal always finds episodes running
SLOW_DWA = "dwa:n_v=15,n_omega=41"


@pytest.mark.slow
@STOP_SIGNALS
def test_a_signal_stops_eval_at_once_and_the_rerun_completes_the_set(tmp_path, signum, group):
    """Ctrl-C (SIGINT to the whole process group, as a terminal sends it) or ``kill`` (SIGTERM
    to the command alone) with two workers busy: exit 128 + signal within 2 s, no process
    left, one line naming what was kept and the command that resumes; the rerun completes the
    set, each episode once, the kept records untouched."""
    out = tmp_path / "eval"
    path = out / EPISODES_FILE
    trials = 3
    argv = [
        "eval", "--scenario", "static", "--policy", SLOW_DWA, "--seeds", "1",
        "--trials", str(trials), "--workers", "2", "--out", str(out),
    ]  # fmt: skip
    stopped = stop_cli(
        argv, lambda: path.is_file() and b"\n" in path.read_bytes(), signum, tmp_path, group
    )
    print(f"{signal.Signals(signum).name}: exit {stopped.returncode} in {stopped.seconds:.2f} s")
    stopped.assert_clean(signum)
    kept = _lines(path)
    assert 1 <= len(kept) < trials
    assert interrupted_line(stopped.stderr) == (
        f"pioneer: interrupted ({signal.Signals(signum).name}); {len(kept)} of {trials} "
        f"episodes kept in {path}; resume with: {shlex.join(['pioneer', *argv])}"
    )
    res = run_cli(*argv)
    assert res.returncode == 0, res.stderr
    lines = _lines(path)
    assert lines[: len(kept)] == kept
    keys = [_key(json.loads(x)) for x in lines]
    assert len(keys) == len(set(keys)) == trials
    assert set(keys) == _expected_keys(["static"], ["dwa"], 1, trials)


def test_a_torn_last_line_is_dropped_with_a_warning_and_rerun(tmp_path, capsys):
    evaluate(["static"], [GOAL], 1, 3, tmp_path, workers=1, progress=False)
    path = tmp_path / EPISODES_FILE
    lines = _lines(path)
    lost = json.loads(lines[-1])
    # a crash in the middle of writing the last record: half a line, no newline
    path.write_text("\n".join(lines[:-1]) + "\n" + lines[-1][: len(lines[-1]) // 2])
    capsys.readouterr()
    rerun = []
    recs = evaluate(
        ["static"], [GOAL], 1, 3, tmp_path, workers=1, progress=False, on_record=rerun.append
    )
    err = capsys.readouterr().err
    assert "unfinished last line" in err
    assert str(path) in err
    assert len(rerun) == 1
    assert _key(rerun[0]) == _key(lost)
    assert _untimed(rerun) == _untimed([lost])  # the same episode, run again
    new_lines = _lines(path)
    assert new_lines[:2] == lines[:2]
    keys = [_key(json.loads(x)) for x in new_lines]
    assert len(keys) == len(set(keys)) == 3
    assert len(recs) == 3


def test_read_records_drops_a_torn_line_and_keeps_the_file_line_aligned(tmp_path, capsys):
    path = tmp_path / EPISODES_FILE
    good = {
        "scenario": "static",
        "policy": "goal",
        "seed": 0,
        "trial": 0,
        "event": "collision",
        "format": RECORD_FORMAT,
    }
    path.write_text(json.dumps(good) + "\n" + '{"scenario": "sta')
    assert read_records(path) == [good]
    assert "unfinished last line" in capsys.readouterr().err
    assert path.read_text() == json.dumps(good) + "\n"
    # a file holding only a torn line becomes empty
    path.write_text('{"scen')
    assert read_records(path) == []
    assert path.read_text() == ""
    # the whole lines are kept byte for byte (cut at the last newline, never rewritten), also
    # behind a torn tail longer than one read
    whole = (json.dumps(good, indent=None, separators=(",", ":")) + "\n").encode()
    path.write_bytes(whole + b'{"scenario": "' + b"x" * 70_000)
    assert read_records(path) == [good]
    assert path.read_bytes() == whole
    assert read_records(tmp_path / "missing.jsonl") == []


@pytest.mark.parametrize(
    ("bad", "needle"),
    [("{not json}", "one JSON record"), ('{"scenario": "static"}', "fields")],
    ids=["not-json", "missing-fields"],
)
def test_a_malformed_line_in_the_middle_is_a_data_error_naming_it(tmp_path, bad, needle):
    evaluate(["static"], [GOAL], 1, 3, tmp_path, workers=1, progress=False)
    path = tmp_path / EPISODES_FILE
    lines = _lines(path)
    corrupt = "\n".join([lines[0], bad, *lines[1:]]) + "\n"
    path.write_text(corrupt)
    with pytest.raises(DataError, match=r"line 2\b") as exc:
        read_records(path)
    assert needle in str(exc.value)
    assert "expected" in str(exc.value) and "fix" in str(exc.value)
    ran = []
    with pytest.raises(DataError, match=r"line 2\b"):
        evaluate(
            ["static"], [GOAL], 1, 4, tmp_path, workers=1, progress=False, on_record=ran.append
        )
    assert ran == []  # nothing runs on top of a corrupt file ...
    assert path.read_text() == corrupt  # ... and nothing in it is lost


@pytest.mark.parametrize("bad", ["[1, 2]", '"text"'])
def test_a_json_line_that_is_not_a_record_is_a_data_error(tmp_path, bad):
    path = tmp_path / EPISODES_FILE
    good = {"scenario": "static", "policy": "goal", "seed": 0, "trial": 0, "event": "collision"}
    path.write_text(f"{json.dumps(good)}\n{bad}\n")
    with pytest.raises(DataError, match=r"line 2\b"):
        read_records(path)


@pytest.mark.parametrize("bad", ["null", "42"])
def test_a_json_scalar_line_is_a_data_error(tmp_path, bad):
    path = tmp_path / EPISODES_FILE
    good = {"scenario": "static", "policy": "goal", "seed": 0, "trial": 0, "event": "collision"}
    path.write_text(f"{json.dumps(good)}\n{bad}\n")
    with pytest.raises(DataError, match=r"line 2\b"):
        read_records(path)


def test_bad_counts_and_backend_are_config_errors(tmp_path):
    with pytest.raises(ConfigError, match="seeds/trials"):
        evaluate(["static"], [GOAL], 0, 3, tmp_path / "a", progress=False)
    with pytest.raises(ConfigError, match="seeds/trials"):
        evaluate(["static"], [GOAL], 2, 0, tmp_path / "a", progress=False)
    with pytest.raises(ConfigError, match="backend"):
        evaluate(["static"], [GOAL], 1, 1, tmp_path / "b", backend="dask", progress=False)
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_run_task_labels_the_record_with_the_policy_row():
    spec = PolicySpec.make("teacher", label="teacher-no-density", density=False)
    assert spec.row == "teacher-no-density"
    assert spec.kwargs == (("density", False),)
    rec = run_task(Task("static", spec, 3, 1))
    assert rec["policy"] == "teacher-no-density"
    assert (rec["scenario"], rec["seed"], rec["trial"]) == ("static", 3, 1)
    assert rec["episode_seed"] == episode_seed("static", 3, 1)
    assert rec["decision_ms"] == pytest.approx(1000.0 * rec["wall_time_s"] / rec["steps"])


# --------------------------------------------------------------------------------------------
# backends


PARALLEL_POLICIES = [GOAL, PolicySpec.make("teacher", label="teacher-no-density", density=False)]


@pytest.mark.slow
def test_parallel_and_serial_runs_give_the_same_records(tmp_path):
    serial = evaluate(
        ["static"], PARALLEL_POLICIES, 2, 2, tmp_path / "serial", workers=1, progress=False
    )
    parallel = evaluate(
        ["static"], PARALLEL_POLICIES, 2, 2, tmp_path / "parallel", workers=2, progress=False
    )
    assert len(serial) == len(parallel) == 8
    assert {_key(r) for r in parallel} == _expected_keys(
        ["static"], ["goal", "teacher-no-density"], 2, 2
    )
    assert _untimed(parallel) == _untimed(serial)
    assert any(r["event"] == "success" for r in serial)  # the teacher episodes do something
    on_disk = read_records(tmp_path / "parallel" / EPISODES_FILE)
    assert _untimed(on_disk) == _untimed(serial)


@pytest.mark.slow
def test_ray_backend_gives_the_same_records(tmp_path):
    ray = pytest.importorskip("ray")
    process = evaluate(["static"], [GOAL], 2, 2, tmp_path / "process", workers=1, progress=False)
    started = not ray.is_initialized()
    if started:
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        seen = []
        recs = evaluate(
            ["static"],
            [GOAL],
            2,
            2,
            tmp_path / "ray",
            backend="ray",
            progress=False,
            on_record=seen.append,
        )
    finally:
        if started:
            ray.shutdown()
    assert len(seen) == len(recs) == 4
    assert _untimed(recs) == _untimed(process)
    assert _untimed(read_records(tmp_path / "ray" / EPISODES_FILE)) == _untimed(process)


def test_a_scenario_redefined_under_the_same_name_is_refused_on_resume(tmp_path, scenario_registry):
    """scenarios.json pins each scenario's definition to the output folder."""
    from pioneer.sim.world import SimConfig

    sc = scenario_registry
    short = sc.static_study_scenario(sim=SimConfig(time_limit=1.0)).replace(name="static-1s")
    sc.register_scenario("static-1s", lambda: short)
    out = tmp_path / "ev"
    first = evaluate(["static", "static-1s"], [GOAL], 1, 1, out, workers=1, progress=False)
    recorded = json.loads((out / "scenarios.json").read_text())
    assert set(recorded) == {"static", "static-1s"}
    assert recorded["static-1s"]["sim"]["time_limit"] == 1.0
    again = evaluate(["static-1s"], [GOAL], 1, 1, out, workers=1, progress=False)
    assert len(again) == len(first) == 2  # same definition: resumes, nothing re-run
    longer = short.replace(sim=SimConfig(time_limit=2.0))
    sc.register_scenario("static-1s", lambda: longer)
    with pytest.raises(ConfigError) as err:
        evaluate(["static-1s"], [GOAL], 1, 2, out, workers=1, progress=False)
    assert_house_message(str(err.value), "static-1s", "sim", "--out")
    assert len(_lines(out / EPISODES_FILE)) == 2


@pytest.mark.parametrize(
    ("text", "name", "kwargs", "label"),
    [
        ("goal", "goal", {}, ""),
        ("teacher:density=false,horizon=2.5", "teacher", {"density": False, "horizon": 2.5}, ""),
        (
            "student-mdn:checkpoint=C:/runs/a b/s.safetensors,action_mode=mean,label=mine",
            "student-mdn",
            {"checkpoint": "C:/runs/a b/s.safetensors", "action_mode": "mean"},
            "mine",
        ),
        ('sfm:name="x",label=3', "sfm", {"name": "x"}, "3"),
        ("dwa:v=[0.1]", "dwa", {"v": (0.1,)}, ""),  # a list becomes a (hashable) tuple
        ("dwa:v=[0.1, 0.2],w=1", "dwa", {"v": (0.1, 0.2), "w": 1}, ""),  # commas in a list
        (  # commas (and an escaped quote) inside a quoted text; a quoted label
            'student-mlp:checkpoint="runs/a,b/\\"c\\".safetensors",label="x.y"',
            "student-mlp",
            {"checkpoint": 'runs/a,b/"c".safetensors'},
            "x.y",
        ),
    ],
)
def test_policy_spec_parse(text, name, kwargs, label):
    spec = PolicySpec.parse(text)
    assert (spec.name, dict(spec.kwargs), spec.label) == (name, kwargs, label)
    assert spec == PolicySpec(name, tuple(sorted(kwargs.items())), label)  # order-free
    assert hash(spec) == hash(PolicySpec.parse(text))


@pytest.mark.parametrize(
    "text",
    [
        "",
        ":a=1",
        "goal:",
        "goal:a",
        "goal:=1",
        "goal:a=1,a=2",
        "goal:1a=2",
        "goal:a=1,b",
        "goal:a=[1,2",
        'goal:a="x,b=2',
    ],
)
def test_policy_spec_parse_refuses_bad_syntax(text):
    with pytest.raises(ConfigError) as err:
        PolicySpec.parse(text)
    assert_house_message(str(err.value), "NAME")


@pytest.mark.parametrize(
    ("spec", "needle"),
    [
        (PolicySpec.make("student-mdn"), "shipped student"),
        (PolicySpec.make("student-shield"), "shipped student"),
        (PolicySpec.make("teacher"), "shipped demos"),
        (PolicySpec.make("crowdnav++"), "CrowdNav++"),
    ],
)
def test_a_missing_shipped_part_fails_before_any_episode(tmp_path, scenario_registry, spec, needle):
    """A variant without a 'base' has no shipped demos/students/weights: refused up front."""
    sc = scenario_registry
    sc.register_scenario("lobby-x", lambda: sc.elevator_scenario().replace(name="lobby-x"))
    with pytest.raises(DataError) as err:
        evaluate(["lobby-x"], [GOAL, spec], 1, 1, tmp_path / "ev", workers=1, progress=False)
    assert_house_message(str(err.value), needle, "lobby-x")
    assert not (tmp_path / "ev" / EPISODES_FILE).exists()
    # with its own parts (a checkpoint / reward / weights parameter) nothing shipped is looked
    # up; a given reward model is loaded and checked against the scenario instead
    own = {"student-mdn": "checkpoint", "student-shield": "checkpoint", "teacher": "reward"}
    if spec.name in own:
        kw = {own[spec.name]: "x", **({"reward": "x"} if spec.name == "student-shield" else {})}
        from pioneer.eval.harness import _check_shipped_parts

        check = functools.partial(
            _check_shipped_parts, ["lobby-x"], [PolicySpec.make(spec.name, **kw)]
        )
        if "reward" in kw:
            with pytest.raises(DataError, match=r"reward model: expected an existing \.npz"):
                check()
        else:
            check()


@pytest.mark.slow
def test_ray_workers_see_scenario_files(tmp_path, monkeypatch, scenario_registry):
    ray = pytest.importorskip("ray")
    sc = scenario_registry  # PIONEER_SCENARIOS is empty until after ray.init
    path = tmp_path / "v.json"
    path.write_text(
        json.dumps(
            {
                "format": "pioneer.scenarios/1",
                "scenarios": {"static-2s": {"static": {}, "sim": {"time_limit": 2.0}}},
            }
        )
    )
    started = not ray.is_initialized()
    if started:  # before the variable is set: the workers can only get it from the task's env
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    monkeypatch.setenv(sc.SCENARIOS_ENV, str(path))
    try:
        recs = evaluate(
            ["static-2s"], [GOAL], 1, 2, tmp_path / "ray", backend="ray", progress=False
        )
    finally:
        if started:
            ray.shutdown()
    assert len(recs) == 2 and all(r["time_s"] <= 2.0 + 1e-9 for r in recs)


@pytest.mark.parametrize("workers", [1, 2])
def test_a_policy_that_cannot_be_built_fails_before_any_episode(tmp_path, workers):
    """Every policy of a run is built (in the workers) before the first episode: a corrupt
    checkpoint is found before any record, and no records file is left behind."""
    bad = tmp_path / "bad.safetensors"
    bad.write_text("not a checkpoint")
    spec = PolicySpec.make("student-mdn", checkpoint=str(bad))
    with pytest.raises(DataError) as err:
        evaluate(["static"], [GOAL, spec], 2, 1, tmp_path / "ev", workers=workers, progress=False)
    assert_house_message(str(err.value), "bad.safetensors")
    assert not (tmp_path / "ev" / EPISODES_FILE).exists()
