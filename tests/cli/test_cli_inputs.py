"""Nothing a user owns is overwritten, nothing runs unbounded, no input is read blindly.

Each refusal here exits 2 with one line naming the problem and the fix, and leaves the file
tree byte for byte as it was (the style of ``test_cli_refusals.py``): an output that is one of
the command's inputs (the same file, a hard link, a path inside an input folder), an existing
dataset or model without ``--overwrite``, an input that is no regular file or no UTF-8 text
or too large, a count beyond its ceiling, a ``summarize`` over records ``eval`` would refuse.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import socket
from pathlib import Path

import pytest

import pioneer.eval.records as records
import pioneer.sim.scenarios.registry as registry
from pioneer.cli import main
from pioneer.config import MAX_EPISODES
from pioneer.data import DEMOS_DIR, STUDENTS_DIR
from pioneer.interrupt import Interrupted
from pioneer.sim.scenarios.distribution import MAX_LAYOUTS
from pioneer_testutils import file_tree, one_error_line, wrong_width_onnx

STUDENT = STUDENTS_DIR / "hr-rl-compact-mdn.safetensors"


def _main(argv: list[str]) -> int:
    """``pioneer ARGV`` in this process (a refused command line exits through SystemExit)."""
    try:
        return main([str(a) for a in argv])
    except SystemExit as exc:
        return int(exc.code or 0)


def _refused(tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[object], *needles):
    """Run ``argv``: exit 2, one line holding every needle, the tree below ``tmp_path`` as it
    was; returns the line."""
    before = file_tree(tmp_path)
    code = _main([str(a) for a in argv])
    line = one_error_line(capsys.readouterr().err, code, *needles, "fix:")
    assert file_tree(tmp_path) == before
    return line


@pytest.fixture
def work(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, scenario_registry) -> Path:
    """The test's folder, also the working folder: a dataset, a model, an ONNX graph, a bag
    folder and a scenario file the user made."""
    monkeypatch.chdir(tmp_path)
    shutil.copyfile(DEMOS_DIR / "static.npz", tmp_path / "d.npz")
    shutil.copyfile(STUDENT, tmp_path / "s.safetensors")
    wrong_width_onnx(tmp_path / "m.onnx")
    (tmp_path / "bag").mkdir()
    (tmp_path / "bag" / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (tmp_path / "l.json").write_text(
        json.dumps({"format": "pioneer.scenarios/1", "scenarios": {"x-1": {"static": {}}}})
    )
    return tmp_path


# --------------------------------------------------------------------------------------------
# 1. no command writes over its own input; an existing dataset or model needs --overwrite


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["reward", "fit", "--demos", "d.npz", "--out", "d.npz"], "the input d.npz itself"),
        (["reward", "fit", "--demos", "d.npz", "--out", "hard.npz"], "a link to the input d.npz"),
        (
            ["reward", "fit", "--demos", "d.npz", "--mirror-demos", "d.npz", "--out", "link.npz"],
            "a link to the input d.npz",
        ),
        (["export", "--model", "s.safetensors", "--out", "s.safetensors"], "itself"),
        (
            ["replay", "--bag", "bag", "--model", "m.onnx", "--out", "m.onnx", "--goal", "1", "0"],
            "the input m.onnx itself",
        ),
        (
            ["replay", "--bag", "bag", "--model", "m.onnx", "--out", "bag/x.csv", "--goal", 1, 0],
            "inside the input folder bag",
        ),
        (["--scenarios", "l.json", "sample-layouts", "--n", "1", "--out", "l.json"], "itself"),
        (["reward", "fit", "--demos", "link.npz", "--out", "d.npz"], "a link to the input"),
        (
            ["run", "--policy", "student-mdn:checkpoint=s.safetensors", "--png", "s.safetensors"],
            "the input",
        ),
        (
            ["run", "--policy", "student-mdn:checkpoint=s.safetensors", "--gif", "link2.st"],
            "a link to the input",
        ),
    ],
    ids=[
        "reward-fit",
        "hard-link",
        "symlink",
        "export",
        "replay-model",
        "replay-bag",
        "scenarios",
        "symlink-input",
        "run-png-onto-the-policy-file",
        "run-gif-onto-a-link-to-it",
    ],
)
def test_an_output_that_is_an_input_is_refused(work, capsys, argv, needle):
    os.link(work / "d.npz", work / "hard.npz")
    os.symlink(work / "d.npz", work / "link.npz")
    os.symlink(work / "s.safetensors", work / "link2.st")
    _refused(work, capsys, argv, needle)


@pytest.mark.parametrize(
    "argv",
    [
        ["demos", "generate", "--scenario", "static", "--positive", "1", "--out", "mine.npz"],
        ["reward", "fit", "--demos", "d.npz", "--out", "mine.npz"],
        ["export", "--model", "s.safetensors", "--out", "mine.npz"],
        ["sample-layouts", "--n", "1", "--out", "mine.npz"],
        ["replay", "--bag", "bag", "--model", "m.onnx", "--out", "mine.npz", "--goal", "1", "0"],
    ],
    ids=["demos-generate", "reward-fit", "export", "sample-layouts", "replay"],
)
def test_an_existing_output_is_kept_without_overwrite(work, capsys, argv):
    """``demos generate`` replaced an existing dataset (or any file) without a word."""
    (work / "mine.npz").write_text("a file the user made\n")
    _refused(work, capsys, argv, "mine.npz", "an existing file", "--overwrite")


def test_overwrite_replaces_an_existing_output(work, capsys):
    (work / "r.npz").write_text("an old model\n")
    argv = ["reward", "fit", "--demos", "d.npz", "--out", "r.npz", "--overwrite"]
    assert _main(argv) == 0
    assert json.loads(capsys.readouterr().out)["out"] == "r.npz"
    assert (work / "r.npz").read_bytes()[:2] == b"PK"  # the fitted model, an .npz archive


# --------------------------------------------------------------------------------------------
# 2. every input is what it claims: a regular file, UTF-8, of bounded size


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["--scenarios", "/dev/zero", "run"], ["/dev/zero", "a character device"]),
        (["reward", "fit", "--demos", "fifo", "--out", "r.npz"], ["--demos", "FIFO"]),
        (["reward", "fit", "--demos", "bag", "--out", "r.npz"], ["--demos", "a folder"]),
        (["reward", "show", "--model", "/dev/zero"], ["--model", "character device"]),
        (
            ["replay", "--bag", "bag", "--model", "fifo", "--out", "c.csv", "--goal", "1", "0"],
            ["--model", "FIFO"],
        ),
        (["--scenarios", "latin1.json", "run"], ["latin1.json", "UTF-8", "0xe9"]),
    ],
    ids=["dev-zero", "fifo", "folder", "device", "replay-fifo", "not-utf-8"],
)
def test_an_input_that_is_no_regular_utf8_file_is_refused(work, capsys, argv, needles):
    """``--scenarios /dev/zero`` read without limit, then a MemoryError; non-UTF-8 bytes were
    a UnicodeDecodeError traceback."""
    os.mkfifo(work / "fifo")
    (work / "latin1.json").write_bytes('{"format": "café"}'.encode("latin-1"))
    _refused(work, capsys, argv, *needles)


def test_a_scenario_file_beyond_the_size_limit_is_refused(work, capsys, monkeypatch):
    monkeypatch.setattr(registry, "MAX_SCENARIO_FILE_BYTES", 64)
    line = _refused(work, capsys, ["--scenarios", "l.json", "run"], "l.json", "at most 64 bytes")
    assert str((work / "l.json").stat().st_size) in line


# --------------------------------------------------------------------------------------------
# 3. every count is bounded by what can run, before any work


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (
            [
                *["eval", "--scenario", "static", "--policy", "goal", "--out", "e"],
                *["--seeds", "100000000000", "--trials", "100000000000"],
            ],
            ["--seeds × --trials", f"{MAX_EPISODES:,}"],
        ),
        (
            ["calibrate", "--scenario", "static", "--episodes", "1000000000000", "--out", "c"],
            ["--episodes", f"{MAX_EPISODES:,}"],
        ),
        (
            ["sample-layouts", "--n", "1000000000000", "--out", "l2.json"],
            ["--n", f"{MAX_LAYOUTS:,}"],
        ),
        (
            [
                "demos",
                "generate",
                "--scenario",
                "static",
                "--positive",
                "1000000000",
                "--out",
                "g.npz",
            ],
            ["--positive + --negative", "1,000,000"],
        ),
        (
            ["distill", "--scenario", "static", "--rounds", "100000000", "--out", "dg"],
            ["--rounds", f"{MAX_EPISODES:,}"],
        ),
        (
            ["study", "blind-sector", "--episodes", "1000000000", "--out", "b"],
            ["--episodes", f"{MAX_EPISODES:,}"],
        ),
    ],
    ids=["eval", "calibrate", "sample-layouts", "demos", "distill", "blind-sector"],
)
def test_a_count_beyond_its_ceiling_is_refused_before_any_work(work, capsys, argv, needles):
    """``eval --seeds 1e11 --trials 1e11`` grew memory at ≈ 100 MB/s with no output."""
    _refused(work, capsys, argv, *needles)


def test_sample_layouts_stopped_keeps_the_layouts_drawn(work, capsys, monkeypatch):
    """Stopping ``sample-layouts`` lost everything: now the layouts drawn so far are written,
    a scenario file of their own, and the line says how to draw them all."""
    import pioneer.cli.scenarios as cli_scenarios

    real = cli_scenarios.draw_variants

    def two_then_stop(*args, **kwargs):
        draws = real(*args, **kwargs)
        yield next(draws)
        yield next(draws)
        raise Interrupted(signal.SIGINT)

    monkeypatch.setattr(cli_scenarios, "draw_variants", two_then_stop)
    code = _main(["sample-layouts", "--n", "5", "--out", "part.json"])
    assert code == 130
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert "2 of 5 layouts kept in part.json" in line and "--overwrite" in line
    assert "resume with" not in line
    doc = json.loads((work / "part.json").read_text())
    assert list(doc["scenarios"]) == ["general-0000", "general-0001"]
    registry.load_scenario_file(work / "part.json")  # a valid scenario file


# --------------------------------------------------------------------------------------------
# 4. a scenario file is checked for the scenarios used


def test_a_large_scenario_file_checks_only_the_variant_used(
    tmp_path, capsys, monkeypatch, scenario_registry
):
    """A file of 100,000 variants: ``run`` on one of them checked every variant first
    (≈ 13 ms each, 20 min before the first step); now only the one it runs."""
    big = tmp_path / "big.json"
    entries = {f"v-{i:06d}": {"elevator": {"lobby_depth": 3.0 + i * 1e-6}} for i in range(100_000)}
    big.write_text(json.dumps({"format": "pioneer.scenarios/1", "scenarios": entries}))
    checked: list[str] = []
    real = registry.check_placement

    def counting(where, cfg, budget=float("inf")):
        checked.append(cfg.name)
        return real(where, cfg, budget)

    monkeypatch.setattr(registry, "check_placement", counting)
    argv = ["--scenarios", str(big), "run", "--scenario", "v-054321", "--policy", "goal"]
    assert _main(argv) == 0
    assert json.loads(capsys.readouterr().out.splitlines()[-1])["scenario"] == "v-054321"
    assert checked == ["v-054321"]


# --------------------------------------------------------------------------------------------
# 6. summarize holds eval's rules


def _record(**changes: object) -> str:
    rec = {"scenario": "static", "policy": "goal", "seed": 0, "trial": 0, "event": "success"}
    rec |= {"time_s": 5.0, "path_length_m": 3.0, "min_gap_m": 0.5, "format": 2}
    return json.dumps({**rec, **changes}) + "\n"


@pytest.mark.parametrize(
    ("lines", "needles"),
    [
        (
            [_record(), _record(trial=1, seed_set="validation")],
            ["evaluation and validation episodes", "seed_set"],
        ),
        ([_record(), _record(trial=1, time_s=float("nan"))], ["line 2", "NaN", "strict"]),
        (
            [_record(), json.dumps({"scenario": "static", "policy": "goal", "seed": 0}) + "\n"],
            ["line 2", "without trial, event", "(it has policy, scenario, seed)"],
        ),
        (
            [json.dumps({"variant": "fov-270", "scenario": "static", "event": "success"}) + "\n"],
            ["line 1", "without policy, seed, trial", "written by pioneer eval"],
        ),
        ([_record(), _record(trial=1, time_s="fast")], ["line 2: time_s", "a number or null"]),
        ([_record(), _record(trial=1, event="won")], ["line 2: event", "'won'"]),
        ([_record(), '{"scenario": "caf\xe9"}\n'], ["line 2", "UTF-8", "0xe9"]),
    ],
    ids=["mixed-seed-sets", "nan", "missing", "other-kind", "not-a-number", "event", "latin-1"],
)
def test_summarize_refuses_records_eval_would_refuse(tmp_path, capsys, lines, needles):
    run = tmp_path / "run"
    run.mkdir()
    encoding = "latin-1" if any("\xe9" in line for line in lines) else "utf-8"
    (run / "episodes.jsonl").write_bytes("".join(lines).encode(encoding))
    _refused(tmp_path, capsys, ["summarize", run], *needles)


def test_summarize_refuses_a_record_line_beyond_the_limit(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(records, "MAX_RECORD_BYTES", 200)
    run = tmp_path / "run"
    run.mkdir()
    (run / "episodes.jsonl").write_text(_record() + _record(trial=1, note="x" * 300))
    _refused(tmp_path, capsys, ["summarize", run], "line 2", "at most 200 bytes")


def test_summarize_refuses_while_a_run_writes_to_the_folder(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "episodes.jsonl").write_text(_record())
    holder = {"pid": os.getpid(), "host": socket.gethostname(), "started": "now"}
    (run / ".lock").write_text(json.dumps(holder) + "\n")
    _refused(
        tmp_path,
        capsys,
        ["summarize", run],
        "another run writing",
        "summarize a copy of the folder",
    )


# --------------------------------------------------------------------------------------------
# 7. --scenarios repeats or takes several files


@pytest.mark.parametrize(
    "head",
    [["--scenarios", "A", "--scenarios", "B"], ["--scenarios", "A", "B"]],
    ids=["repeated", "several"],
)
def test_scenarios_repeats_or_takes_several_files(tmp_path, capsys, head, scenario_registry):
    """``--scenarios A --scenarios B`` was refused with "write --scenarios A B", which was
    refused too, while ``--help`` said "(repeatable)"."""
    for name in "AB":
        doc = {"format": "pioneer.scenarios/1", "scenarios": {f"from-{name}": {"static": {}}}}
        (tmp_path / name).write_text(json.dumps(doc))
    head = [str(tmp_path / w) if w in "AB" else w for w in head]
    assert _main([*head, "run", "--scenario", "from-B", "--policy", "goal"]) == 0
    assert json.loads(capsys.readouterr().out)["scenario"] == "from-B"
    assert _main([*head, "run", "--scenario", "from-A", "--policy", "goal"]) == 0


# --------------------------------------------------------------------------------------------
# 8. messages name the field the user wrote and the path that failed


def test_people_too_large_for_the_layout_are_blamed_on_human_radius(
    tmp_path, capsys, scenario_registry
):
    """It was refused naming a derived region (``Region.y``), not ``human_radius``."""
    doc = {"format": "pioneer.scenarios/1", "scenarios": {"fat": {"elevator": {"human_radius": 5}}}}
    (tmp_path / "fat.json").write_text(json.dumps(doc))
    argv = ["--scenarios", tmp_path / "fat.json", "run", "--scenario", "fat"]
    line = _refused(tmp_path, capsys, argv, "fat.json", "'fat'", "human_radius", "received 5;")
    assert "Region" not in line


def test_a_full_disk_behind_standard_output_is_named(tmp_path, capsys, monkeypatch):
    """``pioneer run > /dev/full`` said "a file: … No space left on device"."""

    class Full:
        def write(self, text: str) -> int:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        def flush(self) -> None:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr("sys.stdout", Full())
    monkeypatch.chdir(tmp_path)
    line = _refused(tmp_path, capsys, ["run", "--scenario", "static", "--policy", "goal"], "ENOSPC")
    assert "standard output" in line and "kept" not in line
