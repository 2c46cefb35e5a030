"""A run folder that cannot lie: every record names what made it (``made_by`` and the folder's
``manifest.json``), a row made otherwise is refused instead of resumed, one run writes to a
folder at a time (its lock), each episode counts once, and an unreachable Ray cluster is one
line."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from pioneer.cli import main
from pioneer.data import STUDENTS_DIR
from pioneer.errors import ConfigError
from pioneer.eval.harness import EPISODES_FILE, PolicySpec, evaluate, read_records
from pioneer.eval.manifest import MANIFEST_FILE, PARAMETERS_ADDED, first_difference
from pioneer.io import LOCK_FILE, run_lock
from pioneer_testutils import file_tree, one_error_line

STUDENT_A = STUDENTS_DIR / "hr-rl-compact-mdn.safetensors"
STUDENT_B = STUDENTS_DIR / "hl-rr-compact-mdn.safetensors"


def _eval(out: Path, policy: str, *extra: str, trials: int = 1) -> list[str]:
    return [
        "eval", "--scenario", "static", "--policy", policy, "--seeds", "1",
        "--trials", str(trials), "--workers", "1", "--out", str(out), *extra,
    ]  # fmt: skip


def _sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


# --------------------------------------------------------------------------------------------
# every record knows what made it


def test_records_and_manifest_name_the_parameters_and_the_files(tmp_path, capsys):
    ckpt = tmp_path / "a.safetensors"
    shutil.copy(STUDENT_A, ckpt)
    out = tmp_path / "ev"
    assert main(_eval(out, f"student-mdn:checkpoint={ckpt},label=mine")) == 0
    (rec,) = read_records(out / EPISODES_FILE)
    made = rec["made_by"]
    assert made["policy"] == "student-mdn"
    assert made["params"]["checkpoint"] == str(ckpt)
    assert made["params"]["action_mode"] is None and made["params"]["kind"] == "mdn"
    assert made["files"] == {"checkpoint": {"path": str(ckpt), "sha256": _sha(ckpt)}}
    manifest = json.loads((out / MANIFEST_FILE).read_text())
    assert manifest["rows"] == {"mine": {"static": made}}
    assert not (out / LOCK_FILE).exists()  # released at the end


def test_a_default_reward_records_the_shipped_demos_it_is_fitted_on(tmp_path):
    from pioneer.data import shipped_demos
    from pioneer.eval.harness import made_by

    made = made_by(PolicySpec.make("teacher"), "hr-rl")
    assert made["params"]["reward"] is None and made["params"]["density"] is True
    assert made["files"]["demos"]["sha256"] == _sha(shipped_demos("hr-rl"))
    assert made["files"]["mirror_demos"]["path"] == str(shipped_demos("hl-rr"))


def test_a_scenario_file_is_recorded_with_its_hash(tmp_path, scenario_registry):
    path = tmp_path / "v.json"
    path.write_text(
        json.dumps({"format": "pioneer.scenarios/1", "scenarios": {"static-1s": {"static": {}}}})
    )
    out = tmp_path / "ev"
    argv = _eval(out, "goal")
    argv[argv.index("static")] = "static-1s"
    assert main(["--scenarios", str(path), *argv]) == 0
    (rec,) = read_records(out / EPISODES_FILE)
    assert rec["made_by"]["files"]["scenario_file"] == {
        "path": str(path.resolve()),
        "sha256": _sha(path),
    }


@pytest.mark.parametrize(
    ("first", "second", "key"),
    [
        ("dwa:n_v=5", "dwa:n_v=9", "params.n_v: expected 5"),
        ("dwa", "sfm:label=dwa", "policy: expected 'dwa'"),
        (
            f"student-mdn:checkpoint={STUDENT_A}",
            f"student-mdn:checkpoint={STUDENT_B}",
            "params.checkpoint",
        ),
    ],
    ids=["parameter", "policy", "checkpoint"],
)
def test_a_row_made_otherwise_is_refused_not_resumed(tmp_path, capsys, first, second, key):
    """Stale results reported as new: the same --out and row label with another parameter or
    checkpoint ran 0 episodes and reported the old records. Now: one line naming the first
    difference and the fix, nothing written; --overwrite starts over."""
    out = tmp_path / "ev"
    assert main(_eval(out, first)) == 0
    before = file_tree(tmp_path)
    capsys.readouterr()
    code = main(_eval(out, second))
    one_error_line(capsys.readouterr().err, code, key, "--overwrite", "new --out", "static")
    assert file_tree(tmp_path) == before
    assert main(_eval(out, second, "--overwrite")) == 0
    (rec,) = read_records(out / EPISODES_FILE)
    mine = json.loads((out / MANIFEST_FILE).read_text())["rows"][rec["policy"]]["static"]
    assert rec["made_by"] == mine


def test_a_checkpoint_changed_in_place_is_refused(tmp_path, capsys):
    ckpt = tmp_path / "s.safetensors"
    shutil.copy(STUDENT_A, ckpt)
    out = tmp_path / "ev"
    assert main(_eval(out, f"student-mdn:checkpoint={ckpt}")) == 0
    shutil.copy(STUDENT_B, ckpt)  # retrained into the same path
    capsys.readouterr()
    code = main(_eval(out, f"student-mdn:checkpoint={ckpt}", trials=2))
    one_error_line(capsys.readouterr().err, code, "files.checkpoint.sha256", _sha(STUDENT_A))
    assert len(read_records(out / EPISODES_FILE)) == 1


def test_the_same_settings_resume_however_they_are_written(tmp_path):
    """``dwa`` and ``dwa:n_v=7`` (its default) are the same row: resolved, not compared as
    typed; the second run only adds the new trial."""
    from pioneer.baselines.classic import DWAPolicy
    from pioneer.config import default

    out = tmp_path / "ev"
    assert main(_eval(out, "dwa")) == 0
    n_v = default(DWAPolicy, "n_v")
    assert main(_eval(out, f"dwa:n_v={n_v}", trials=2)) == 0
    recs = read_records(out / EPISODES_FILE)
    assert [r["trial"] for r in recs] == [0, 1]
    assert recs[0]["made_by"] == recs[1]["made_by"]


def test_records_without_made_by_are_refused(tmp_path, capsys):
    out = tmp_path / "ev"
    assert main(_eval(out, "goal")) == 0
    path = out / EPISODES_FILE
    (rec,) = read_records(path)
    rec.pop("made_by")
    path.write_text(json.dumps(rec) + "\n")
    (out / MANIFEST_FILE).unlink()
    capsys.readouterr()
    code = main(_eval(out, "goal", trials=2))
    one_error_line(capsys.readouterr().err, code, "written before run manifests", "--overwrite")


def test_a_row_recorded_before_a_parameter_existed_resumes_at_its_old_value(tmp_path, capsys):
    """A teacher row written before ``precision`` was a parameter (its ``made_by`` without it)
    was made with float64 rays: it resumes with them, and is refused with float32 (and with
    the default, the fast rollouts)."""
    out = tmp_path / "ev"
    assert main(_eval(out, "teacher:density=false,precision=float64")) == 0
    path = out / EPISODES_FILE
    (rec,) = read_records(path)
    assert rec["made_by"]["params"]["precision"] == PARAMETERS_ADDED["precision"]
    manifest = json.loads((out / MANIFEST_FILE).read_text())
    for made in (rec["made_by"], manifest["rows"]["teacher"]["static"]):
        made["params"].pop("precision")  # as written before the parameter existed
    path.write_text(json.dumps(rec) + "\n")
    (out / MANIFEST_FILE).write_text(json.dumps(manifest))
    before = file_tree(tmp_path)
    capsys.readouterr()
    code = main(_eval(out, "teacher:density=false,precision=float32", trials=2))
    one_error_line(capsys.readouterr().err, code, "params.precision", "'float64'", "float32")
    assert file_tree(tmp_path) == before
    code = main(_eval(out, "teacher:density=false", trials=2))
    one_error_line(capsys.readouterr().err, code, "params.precision", "'float64'", "fast")
    assert file_tree(tmp_path) == before
    assert main(_eval(out, "teacher:density=false,precision=float64", trials=2)) == 0
    assert [r["trial"] for r in read_records(path)] == [0, 1]


def test_first_difference_names_the_first_changed_key_in_order():
    old = {"policy": "dwa", "params": {"a": 1, "b": 2}, "files": {}}
    new = {"policy": "dwa", "params": {"a": 1, "b": 3}, "files": {"x": {"sha256": "f"}}}
    assert first_difference(old, new) == ("params.b", 2, 3)
    with pytest.raises(ValueError):
        first_difference(old, old)


# --------------------------------------------------------------------------------------------
# one writer per run folder


def test_a_folder_held_by_a_running_writer_is_refused(tmp_path, capsys):
    """Two writers, deterministically: a lock held by a live process (a sleeping child)."""
    out = tmp_path / "ev"
    out.mkdir()
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        lock = {"pid": holder.pid, "host": socket.gethostname(), "started": "now"}
        (out / LOCK_FILE).write_text(json.dumps(lock))
        before = file_tree(tmp_path)
        code = main(_eval(out, "goal"))
        one_error_line(
            capsys.readouterr().err, code, "one writer at a time", f"pid {holder.pid}", "--out"
        )
        assert file_tree(tmp_path) == before
    finally:
        holder.kill()
        holder.wait()


def test_a_stale_lock_is_replaced(tmp_path):
    """A writer killed with SIGKILL leaves its lock: its pid is gone, so the next run takes it."""
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    out = tmp_path / "ev"
    out.mkdir()
    lock = {"pid": dead.pid, "host": socket.gethostname(), "started": "then"}
    (out / LOCK_FILE).write_text(json.dumps(lock))
    recs = evaluate(["static"], [PolicySpec.make("goal")], 1, 1, out, workers=1, progress=False)
    assert len(recs) == 1
    assert not (out / LOCK_FILE).exists()


def test_run_lock_is_released_on_an_exception_and_refuses_a_second_holder(tmp_path):
    with pytest.raises(RuntimeError), run_lock(tmp_path / "r") as folder:
        assert json.loads((folder / LOCK_FILE).read_text())["pid"] == os.getpid()
        with pytest.raises(ConfigError, match="one writer at a time"), run_lock(folder):
            pass
        raise RuntimeError("boom")
    assert list((tmp_path / "r").iterdir()) == []


def test_two_runs_started_at_once_write_each_episode_once(tmp_path):
    """Two writers as they happen: two identical runs into one folder at once. Either the
    second is refused by the lock (one line) or, if the first was already done, it resumes
    with nothing to do; the records hold every episode once either way."""
    out = tmp_path / "ev"
    argv = ["eval", "--scenario", "static", "--policy", "goal", "--seeds", "2", "--trials", "5",
            "--workers", "1", "--out", str(out)]  # fmt: skip
    cmd = [sys.executable, "-m", "pioneer.cli", *argv]
    procs = [subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    results = [(p.wait(timeout=600), p.stderr.read() if p.stderr else "") for p in procs]
    assert 0 in [code for code, _ in results], results
    for code, err in results:
        if code != 0:
            one_error_line(err, code, "one writer at a time")
    lines = (out / EPISODES_FILE).read_text().splitlines()
    keys = [(r["scenario"], r["policy"], r["seed"], r["trial"]) for r in map(json.loads, lines)]
    assert len(keys) == len(set(keys)) == 10
    assert not (out / LOCK_FILE).exists()


def test_a_duplicated_record_counts_once_with_a_warning(tmp_path, capsys):
    out = tmp_path / "ev"
    assert main(_eval(out, "goal", trials=3)) == 0
    path = out / EPISODES_FILE
    lines = path.read_text().splitlines()
    path.write_text("\n".join([*lines, lines[0], lines[1]]) + "\n")  # copied by hand
    capsys.readouterr()
    assert len(read_records(path)) == 3
    assert "2 repeated episode record(s) ignored" in capsys.readouterr().err
    assert main(_eval(out, "goal", trials=3)) == 0
    captured = capsys.readouterr()
    assert "(3 episodes)" in captured.out
    assert captured.err.count("repeated episode record") == 1  # one warning per read


# --------------------------------------------------------------------------------------------
# an unreachable distributed backend


def _closed_port() -> int:
    """A TCP port on 127.0.0.1 nothing listens on (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_an_unreachable_ray_address_is_one_line_naming_it(tmp_path, capsys):
    """Refused before Ray is started (which would retry for minutes): exit 2, one line naming
    the address, nothing written."""
    address = f"127.0.0.1:{_closed_port()}"
    out = tmp_path / "ev"
    argv = ["eval", "--scenario", "static", "--policy", "goal", "--seeds", "1", "--trials", "1",
            "--backend", "ray", "--ray-address", address, "--out", str(out)]  # fmt: skip
    code = main(argv)
    one_error_line(capsys.readouterr().err, code, "--ray-address", address, "fix:")
    assert list(tmp_path.iterdir()) == []


def test_a_ray_address_without_the_ray_backend_is_refused(tmp_path, capsys):
    code = main([*_eval(tmp_path / "ev", "goal"), "--ray-address", "127.0.0.1:1"])
    one_error_line(capsys.readouterr().err, code, "--ray-address", "--backend ray")
    assert list(tmp_path.iterdir()) == []
