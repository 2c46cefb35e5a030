"""Check everything before writing anything: every ``pioneer`` command, given one invalid input,
exits 2 with one line and leaves the file system as it found it — no output folder, no
``config.json``, no exported model, no scenarios file. And the lines say what is wrong: a file
of the wrong format is named as such (never with a hint to load it unsafely), a bad flag is
blamed on the flag, every argument error is one line."""

from __future__ import annotations

import io
import os
import zipfile
from pathlib import Path

import numpy as np
import pytest

from pioneer.cli import main
from pioneer.cli._app import _TREE, _Group
from pioneer.data import DEMOS_DIR, STUDENTS_DIR
from pioneer_testutils import file_tree, one_error_line, wrong_width_onnx

STATIC_DEMOS = str(DEMOS_DIR / "static.npz")
ELEVATOR_DEMOS = str(DEMOS_DIR / "hr-rl.npz")
MLP = str(STUDENTS_DIR / "hr-rl-mlp.safetensors")
MDN = str(STUDENTS_DIR / "hr-rl-mdn.safetensors")

# command → (one invalid input, in the command line; a word its error line names). IN/… are
# input files (made by the fixture); OUT is the output path, inside the test's own folder.
INVALID: dict[str, tuple[str, str]] = {
    "run": ("run --scenario static --policy student-onnx:model=IN/w28.onnx --png OUT", "28"),
    "scenarios": ("--scenarios IN/evil.json scenarios --png-dir OUT", "../../evil"),
    "eval": (
        "eval --scenario static --policy student-mdn:checkpoint=IN/random.npz --workers 1 "
        "--out OUT",
        "random.npz",
    ),
    "summarize": ("summarize IN/random.npz", "an existing folder"),
    "reproduce": ("reproduce --profile smoke --workers 0 --out OUT", "--workers"),
    "sample-layouts": ("sample-layouts --prefix ../../x --n 1 --out OUT", "--prefix"),
    "calibrate": ("calibrate --driver nope --episodes 1 --out OUT", "nope"),
    "distill": ("distill --scenario static --reward IN/random.npz --out OUT", "random.npz"),
    "finetune": ("finetune --scenario hr-rl --student IN/random.npz --out OUT", "random.npz"),
    "export": (f"export --model {MLP} --action-mode mean --out OUT", "--action-mode"),
    "replay": ("replay --bag IN/missing.bag --model IN/w28.onnx --out OUT --goal 1 0", "bag"),
    "train crowdnav++": ("train crowdnav++ --scenario nope --out OUT", "nope"),
    "train sb3-ppo": ("train sb3-ppo --scenario nope --steps 8 --out OUT", "nope"),
    "demos generate": ("demos generate --scenario nope --out OUT", "nope"),
    "demos show": ("demos show IN/random.npz", "not an .npz archive"),
    "teleop": ("teleop --scenario nope --out OUT", "nope"),
    "reward fit": (f"reward fit --demos {STATIC_DEMOS} --min-gamma 5 --out OUT", "--min-gamma"),
    "reward show": (f"reward show --model {MDN}", "a safetensors file"),
    "study static": (f"study static --demos {ELEVATOR_DEMOS} --out OUT", "static"),
    "study blind-sector": ("study blind-sector --fov 0 --out OUT", "--fov"),
}


def _main(argv: list[str]) -> int:
    """``pioneer ARGV`` in this process: its exit code (a refused command line exits through
    SystemExit, as the console script would)."""
    try:
        return main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)


def _leaves(group: _Group, prefix: str = "") -> list[str]:
    out = []
    for name, child in group.children.items():
        full = f"{prefix}{name}"
        out += _leaves(child, f"{full} ") if isinstance(child, _Group) else [full]
    return out


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    """Invalid input files: random bytes named .npz, a scenario file whose variant's name
    leaves its folder, an ONNX graph 28 wide that claims the 29-D observation."""
    d = tmp_path_factory.mktemp("inputs")
    (d / "random.npz").write_bytes(np.random.default_rng(0).bytes(256))
    (d / "evil.json").write_text(
        '{"format": "pioneer.scenarios/1", "scenarios": {"../../evil": {"static": {}}}}'
    )
    wrong_width_onnx(d / "w28.onnx")
    return d


def test_every_command_has_an_invalid_input_here():
    assert sorted(INVALID) == sorted(_leaves(_TREE))


@pytest.mark.parametrize("name", list(INVALID))
def test_an_invalid_input_leaves_the_file_system_as_it_was(
    name, inputs, tmp_path, capsys, monkeypatch, scenario_registry
):
    monkeypatch.chdir(tmp_path)  # a command that wrote anyway would write here
    work = tmp_path / "work"
    work.mkdir()
    (work / "kept.txt").write_text("a file the user had\n")
    text, needle = INVALID[name]
    argv = [w.replace("IN/", f"{inputs}/").replace("OUT", str(work / "out")) for w in text.split()]
    before, inputs_before = file_tree(tmp_path), file_tree(inputs)
    code = _main(argv)
    one_error_line(capsys.readouterr().err, code, needle, "fix:")
    assert file_tree(tmp_path) == before
    assert file_tree(inputs) == inputs_before
    assert not (inputs.parent / "evil.png").exists() and not Path("evil.png").exists()


# --------------------------------------------------------------------------------------------
# messages that say what is wrong


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["reward", "show", "--model", "IN/random.npz"], ["not an .npz archive"]),
        (["demos", "show", "IN/random.npz"], ["not an .npz archive"]),
        (["reward", "show", "--model", MDN], ["a safetensors file", "not an .npz archive"]),
        (["demos", "show", "IN/objects.npz"], ["object arrays", "never loaded"]),
        (["reward", "fit", "--demos", "IN/empty.npz", "--out", "OUT"], ["an empty file"]),
    ],
    ids=["random-bytes", "random-bytes-demos", "safetensors", "pickled-objects", "empty"],
)
def test_a_file_of_another_format_is_named_as_such(inputs, tmp_path, capsys, argv, needles):
    """Random bytes reported numpy's "contains pickled data … load it unsafely with
    allow_pickle": no pickle was there, and the hint invited unsafe loading."""
    objects = io.BytesIO()
    np.save(objects, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with zipfile.ZipFile(tmp_path / "objects.npz", "w") as z:
        z.writestr("x.npy", objects.getvalue())
    (tmp_path / "empty.npz").write_bytes(b"")
    for name in ("random.npz",):
        os.symlink(inputs / name, tmp_path / name)
    argv = [a.replace("IN/", f"{tmp_path}/").replace("OUT", str(tmp_path / "o")) for a in argv]
    code = _main(argv)
    line = one_error_line(capsys.readouterr().err, code, *needles)
    assert "allow_pickle" not in line and "unsafe" not in line
    assert not (tmp_path / "o").exists()


def test_min_gamma_out_of_range_is_blamed_on_the_flag(tmp_path, capsys):
    """It was blamed on the dataset ("labels: expected positive and negative samples")."""
    argv = ["reward", "fit", "--demos", STATIC_DEMOS, "--out", str(tmp_path / "r.npz")]
    code = _main([*argv, "--min-gamma", "5"])
    one_error_line(capsys.readouterr().err, code, "--min-gamma", "[-1, 1]", "5.0")
    code = _main([*argv, "--min-gamma", "1"])  # in range, but keeps no negatives
    one_error_line(capsys.readouterr().err, code, "--min-gamma", "0 negative")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["eval", "--trials", "x", "--out", "OUT"], "--trials"),
        (["eval", "--workers", "x", "--out", "OUT"], "--workers"),
        (
            ["demos", "generate", "--scenario", "static", "--positive", "x", "--out", "OUT"],
            "--positive",
        ),
        (["teleop", "--max-episodes", "1.5", "--out", "OUT"], "--max-episodes"),
        (["replay", "--bag", "b", "--model", "m", "--out", "OUT", "--goal", "1", "x"], "--goal"),
    ],
)
def test_every_argument_error_is_one_line(tmp_path, capsys, argv, needle):
    """A non-integer count for an optional option (``int | None``) gave tyro's multi-line
    list of every type's failure."""
    code = _main([a.replace("OUT", str(tmp_path / "o")) for a in argv])
    line = one_error_line(capsys.readouterr().err, code, needle, "fix:")
    assert "NoneType" not in line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (
            ["eval", "--scenario", "static", "--policy", "goal", "--no-density", "--out", "OUT"],
            "--no-density",
        ),
        (
            [
                "eval",
                "--scenario",
                "static",
                "--policy",
                "goal",
                "--backend",
                "ray",
                "--workers",
                "2",
                "--out",
                "OUT",
            ],
            "--workers",
        ),
        (
            [
                "distill",
                "--scenario",
                "static",
                "--student",
                "mlp",
                "--nll-beta",
                "0.5",
                "--out",
                "OUT",
            ],
            "--nll-beta",
        ),
        (["export", "--model", MLP, "--action-mode", "mean", "--out", "OUT"], "--action-mode"),
        (["run", "--scenario", "static", "--policy", "goal", "--lidar"], "--lidar"),
    ],
    ids=["ablation-without-teacher", "workers-with-ray", "mdn-flag-for-mlp", "mlp-export", "lidar"],
)
def test_a_flag_that_does_not_apply_is_refused_not_ignored(tmp_path, capsys, argv, needle):
    code = _main([a.replace("OUT", str(tmp_path / "o")) for a in argv])
    one_error_line(capsys.readouterr().err, code, needle, "fix:")
    assert list(tmp_path.iterdir()) == []
