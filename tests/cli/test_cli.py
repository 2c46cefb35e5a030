"""The ``pioneer`` command line: one episode with GIF/PNG output, one-line errors, exit codes."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from PIL import Image

from pioneer.cli import main


def test_run_writes_gif_and_png(tmp_path, capsys):
    gif, png = tmp_path / "a.gif", tmp_path / "a.png"
    argv = ["run", "--scenario", "hr-rl", "--policy", "goal", "--seed", "0"]
    code = main([*argv, "--gif", str(gif), "--png", str(png)])
    assert code == 0
    assert gif.is_file() and png.is_file()
    with Image.open(gif) as im:
        assert im.format == "GIF"
        assert im.n_frames > 1
    with Image.open(png) as im:
        assert im.format == "PNG"
    out = capsys.readouterr().out.strip().splitlines()
    record = json.loads(out[-1])
    assert record["scenario"] == "hr-rl"
    assert record["policy"] == "goal"
    assert record["seed"] == 0
    assert record["event"] in {"success", "collision", "timeout"}
    with Image.open(gif) as im:
        assert im.n_frames == record["steps"] + 1
    assert sorted(os.listdir(tmp_path)) == ["a.gif", "a.png"]


def test_run_without_outputs_prints_record(capsys):
    assert main(["run", "--scenario", "static", "--seed", "3"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1
    record = json.loads(out[0])
    assert record["scenario"] == "static"
    assert record["seed"] == 3


def test_run_with_lidar_rays(tmp_path):
    gif = tmp_path / "rays.gif"
    assert main(["run", "--scenario", "static", "--gif", str(gif), "--lidar"]) == 0
    with Image.open(gif) as im:
        assert im.n_frames > 1


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["run", "--scenario", "nope"], "scenario"),
        (["run", "--policy", "nope"], "policy"),
    ],
)
def test_user_errors_are_one_line_with_exit_code_2(argv, needle, capsys, tmp_path):
    code = main([*argv, "--gif", str(tmp_path / "x.gif")])
    assert code == 2
    captured = capsys.readouterr()
    err = captured.err.strip("\n")
    assert err.startswith("pioneer: error:")
    assert len(err.splitlines()) == 1
    assert needle in err
    assert "expected" in err and "received" in err and "fix" in err
    assert "nope" in err
    assert not (tmp_path / "x.gif").exists()


def test_missing_subcommand_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as exc:
        main([])
    assert exc.value.code == 2
    assert "usage" in capsys.readouterr().err


def test_version_prints_the_packages_version(capsys):
    from importlib.metadata import version

    from pioneer import __version__

    assert main(["--version"]) == 0
    assert capsys.readouterr().out == f"pioneer {__version__}\n"
    assert version("pioneer-nav") == __version__  # the metadata's version is read from it


def _console_commands():
    cmds = [[sys.executable, "-m", "pioneer.cli"]]
    script = Path(sys.executable).with_name("pioneer")
    if script.is_file():
        cmds.append([str(script)])
    return cmds


@pytest.mark.parametrize("cmd", _console_commands(), ids=lambda c: Path(c[-1]).name)
def test_console_script_bad_scenario_exit_code(cmd):
    proc = subprocess.run(
        [*cmd, "run", "--scenario", "nope"],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("pioneer: error:")
    assert "Traceback" not in proc.stderr


def test_run_prints_a_short_record_and_frames_only_on_request(capsys):
    argv = ["run", "--scenario", "static", "--policy", "goal", "--seed", "0"]
    assert main(argv) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 1
    record = json.loads(lines[0])
    assert record["collided_with"] in {None, "human", "wall", "human and wall"}
    assert main([*argv, "--frames"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    frames = [json.loads(x) for x in lines[:-1]]
    assert len(frames) == record["steps"] + 1 and json.loads(lines[-1]) == record
    assert set(frames[0]) == {"t", "x", "y", "theta", "v", "omega", "gap", "wall_gap"}
    assert [f["t"] for f in frames[:3]] == pytest.approx([0.0, 0.1, 0.2])
