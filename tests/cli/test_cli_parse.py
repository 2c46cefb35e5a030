"""The ``pioneer`` command line itself (tyro): ``--help`` everywhere, defaults read from the
configs, and every bad command line as one line on stderr with exit code 2."""

from __future__ import annotations

import subprocess
import sys

import pytest

from pioneer.baselines.crowdnav.imitation import WarmStartConfig
from pioneer.baselines.crowdnav.ppo import PPOConfig
from pioneer.cli import main
from pioneer.learn.dagger import DaggerConfig
from pioneer.learn.models import StudentConfig
from pioneer.reward.crowdnav import CrowdNavRewardConfig
from pioneer.reward.density import DensityConfig
from pioneer.reward.recipe import RewardRecipe
from pioneer_testutils import assert_house_message, run_cli

COMMANDS = [
    ["run"],
    ["scenarios"],
    ["eval"],
    ["reproduce"],
    ["calibrate"],
    ["distill"],
    ["export"],
    ["replay"],
    ["train", "crowdnav++"],
    ["demos", "generate"],
    ["demos", "show"],
    ["teleop"],
    ["reward", "fit"],
    ["reward", "show"],
    ["study", "static"],
]
GROUPS = [[], ["train"], ["demos"], ["reward"], ["study"]]


def _exit_code(argv: list[str]) -> int:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    return int(exc.value.code or 0)


@pytest.mark.parametrize("path", GROUPS, ids=lambda p: " ".join(["pioneer", *p]))
def test_help_of_the_tree_lists_the_commands(path, capsys):
    assert _exit_code([*path, "--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: {' '.join(['pioneer', *path])} ")
    below = [c[len(path)] for c in COMMANDS if c[: len(path)] == path]
    assert below and all(name in out for name in below)
    if not path:
        assert "--scenarios FILE" in out


@pytest.mark.parametrize("path", COMMANDS, ids=" ".join)
def test_help_of_every_command_lists_its_defaults(path, capsys):
    assert _exit_code([*path, "--help"]) == 0
    captured = capsys.readouterr()
    assert captured.out.startswith(f"usage: {' '.join(['pioneer', *path])} ")
    assert "(default: " in captured.out or "(required)" in captured.out
    assert captured.err == ""


def test_help_shows_the_config_defaults(capsys):
    assert _exit_code(["distill", "--help"]) == 0
    out = capsys.readouterr().out
    assert f"(default: {DaggerConfig().teacher_episodes})" in out
    assert "{mdn,mlp}" in out and "{applied,teacher}" in out
    assert _exit_code(["train", "crowdnav++", "--help"]) == 0
    out = capsys.readouterr().out
    assert f"(default: {PPOConfig().total_steps})" in out and "{sfm,dwa,teacher}" in out


def test_distill_defaults_are_the_dagger_config(monkeypatch, tmp_path):
    import pioneer.cli.learning as learning

    seen = {}

    def fake_run_dagger(cfg, out, workers, reward=None):
        seen.update(cfg=cfg, workers=workers, reward=reward)
        raise RuntimeError("stop here")

    monkeypatch.setattr(learning, "run_dagger", fake_run_dagger)
    with pytest.raises(RuntimeError, match="stop here"):
        main(["distill", "--out", str(tmp_path / "d")])
    assert seen == {"cfg": DaggerConfig(), "workers": None, "reward": None}


def test_train_defaults_are_the_ppo_and_warm_start_configs(monkeypatch, tmp_path):
    import pioneer.cli.learning as learning

    seen = {}

    def fake_train(scenario, out, ppo, reward, warm, resume, command, torch_threads):
        seen.update(ppo=ppo, reward=reward, warm=warm, resume=resume, threads=torch_threads)
        raise RuntimeError("stop here")

    monkeypatch.setattr(learning, "train_crowdnav", fake_train)
    with pytest.raises(RuntimeError, match="stop here"):
        main(["train", "crowdnav++", "--out", str(tmp_path / "t")])
    assert seen == {
        "ppo": PPOConfig(),
        "reward": CrowdNavRewardConfig(),  # the CrowdNav++ reward, the trainer's default
        "warm": WarmStartConfig(),
        "resume": None,
        "threads": 1,
    }


def test_reward_fit_defaults_are_the_recipe_and_density_config():
    from pioneer.cli.reward import RewardFit

    fit = RewardFit(demos="d.npz", out="m.npz")
    assert fit.recipe == RewardRecipe() and fit.recipe.density == DensityConfig()


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        ([], ["a command", "usage: pioneer"]),
        (["evl"], ["'evl'", "did you mean eval?"]),
        (["train"], ["pioneer train", "crowdnav++"]),
        (["train", "ppo"], ["pioneer train", "'ppo'"]),
        (["--scenarios"], ["--scenarios", "FILE"]),
        (["--verbose", "run"], ["'--verbose'"]),
        (["eval"], ["--out", "required", "add --out DIR"]),
        (["eval", "--out", "x", "--sedes", "3"], ["'--sedes'", "did you mean --seeds?"]),
        (["eval", "--out", "x", "--seeds", "many"], ["--seeds", "INT", "'many'"]),
        (["eval", "--out", "x", "--backend", "slurm"], ["--backend", "process, ray", "'slurm'"]),
        (["reproduce", "--profile", "fast"], ["--profile", "smoke, quick, paper", "'fast'"]),
        (["distill", "--out", "x", "--student", "cnn"], ["--student", "mdn, mlp"]),
        (["replay", "--bag", "b", "--model", "m", "--out", "o", "--goal", "1"], ["--goal X Y"]),
        (["demos", "show"], ["FILE", "required"]),
        (["demos", "show", "a.npz", "b.npz"], ["'b.npz'"]),
        (["run", "--lidar=yes"], ["'yes'"]),
        # argparse would keep the last of a repeated option silently (hl-rr alone here)
        (
            ["eval", "--out", "x", "--scenario", "hr-rl", "--scenario", "hl-rr"],
            ["--scenario given more than once", "write --scenario A B"],
        ),
        (["run", "--seed", "1", "--seed=2"], ["--seed given more than once"]),
    ],
)
def test_a_bad_command_line_is_one_line_and_exit_2(argv, needles, capsys, tmp_path):
    assert _exit_code(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip("\n").splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("pioneer: error: ")
    assert_house_message(lines[0], *needles)
    assert captured.out == ""


def test_without_tyros_hook_a_refusal_is_still_one_line(monkeypatch, capsys):
    import pioneer.cli._parse as parse

    monkeypatch.setattr(parse, "tyro_errors", None)
    assert _exit_code(["eval", "--out", "x", "--seeds", "many"]) == 2
    lines = capsys.readouterr().err.strip("\n").splitlines()
    assert len(lines) == 1 and lines[0].startswith("pioneer: error: ")
    assert "--seeds" in lines[0] and "many" in lines[0] and "│" not in lines[0]


def test_an_unknown_scenario_is_one_line_and_writes_nothing(tmp_path):
    out = tmp_path / "x"
    argv = ["eval", "--scenario", "nope", "--policy", "teacher", "--out", str(out)]
    proc = run_cli(*argv, timeout=300)
    assert proc.returncode == 2
    lines = proc.stderr.strip("\n").splitlines()
    assert len(lines) == 1 and lines[0].startswith("pioneer: error: ")
    assert_house_message(lines[0], "scenario", "nope")
    assert proc.stdout == "" and not out.exists()


def test_python_dash_m_help():
    proc = subprocess.run(
        [sys.executable, "-m", "pioneer.cli", "--help"],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert proc.returncode == 0 and proc.stdout.startswith("usage: pioneer ")
    assert "reproduce" in proc.stdout and proc.stderr == ""


# ------------------------------------------------------------ the options are the configs
def _parsed(argv: list[str]):
    """The options object ``pioneer ARGV`` would run (parsed, not run)."""
    from pioneer.cli._app import _parse

    command, _ = _parse(argv)
    return command


def test_distill_flags_fill_the_dagger_and_student_configs():
    cmd = _parsed(["distill", "--out", "d", "--rounds", "3", "--student", "mlp", "--hidden", "64"])
    assert cmd.dagger == DaggerConfig(rounds=3, student=StudentConfig(kind="mlp", hidden=(64,)))
    cmd = _parsed(["distill", "--out", "d", "--action-mode", "mean", "--nll-beta", "0.5"])
    assert cmd.dagger.student == StudentConfig(action_mode="mean", nll_beta=0.5)


def test_crowdnav_flags_keep_their_names_and_fill_the_configs():
    argv = ["train", "crowdnav++", "--out", "t", "--steps", "100", "--envs", "4"]
    cmd = _parsed([*argv, "--bc-expert", "dwa", "--bc-episodes", "2", "--gamma", "0.9"])
    assert cmd.ppo == PPOConfig(total_steps=100, n_envs=4, gamma=0.9)
    assert cmd.warm == WarmStartConfig(expert="dwa", bc_episodes=2)


def test_reward_fit_and_demos_generate_flags_fill_their_configs():
    from pioneer.demos.generate import Selection

    cmd = _parsed(
        ["reward", "fit", "--demos", "d", "--out", "m", "--lam", "0.5", "--gamma", "graded"]
    )
    assert cmd.recipe == RewardRecipe(gamma="graded", density=DensityConfig(lam=0.5))
    cmd = _parsed(["demos", "generate", "--scenario", "static", "--out", "o", "--max-time", "9"])
    assert cmd.selection == Selection(max_time_s=9.0)


@pytest.mark.parametrize(
    ("argv", "flag", "bound"),
    [
        (["distill", "--out", "d", "--rounds", "-1"], "--rounds", ">= 0"),
        (["distill", "--out", "d", "--nll-beta", "2"], "--nll-beta", ">= 0 and <= 1"),
        (["distill", "--out", "d", "--hidden", "0"], "--hidden[0]", ">= 1"),
        (["train", "crowdnav++", "--out", "t", "--envs", "0"], "--envs", ">= 1"),
        (["train", "crowdnav++", "--out", "t", "--bc-lr", "0"], "--bc-lr", "> 0"),
        (
            ["reward", "fit", "--demos", "d", "--out", "m", "--max-inducing", "0"],
            "--max-inducing",
            ">= 1",
        ),
    ],
)
def test_a_config_value_out_of_range_is_refused_naming_its_flag(argv, flag, bound, capsys):
    assert _exit_code(argv) == 2
    captured = capsys.readouterr()
    (line,) = captured.err.strip("\n").splitlines()
    assert line.startswith(f"pioneer: error: {flag}: expected ") and bound in line
    assert_house_message(line, flag)


@pytest.mark.parametrize(
    ("path", "configs"),
    [
        (["distill"], ["DaggerConfig", "StudentConfig"]),
        (["train", "crowdnav++"], ["PPOConfig", "WarmStartConfig"]),
        (["reward", "fit"], ["RewardRecipe", "DensityConfig"]),
        (["demos", "generate"], ["Selection"]),
    ],
)
def test_every_field_of_a_nested_config_is_a_flag(path, configs, capsys):
    """The flags are the configs' fields, as registered (renamed, or left out)."""
    import dataclasses
    import re

    from pioneer.cli._parse import _FLAGS, _shown, flag_name

    assert _exit_code([*path, "--help"]) == 0
    out = capsys.readouterr().out
    by_name = {cls.__name__: cls for cls in _FLAGS}
    for name in configs:
        cls = by_name[name]
        for f in dataclasses.fields(cls):
            if dataclasses.is_dataclass(f.default):
                continue  # a nested config: its own group
            listed = re.search(re.escape(flag_name(cls, f.name)) + r"[ ,\n]", out) is not None
            assert listed == _shown(cls, f.name), (name, f.name)


def test_config_flags_refuses_unknown_fields_and_a_second_meaning():
    from pioneer.cli._parse import config_flags

    with pytest.raises(TypeError, match="no fields"):
        config_flags(PPOConfig, total_step="steps")
    with pytest.raises(TypeError, match="other flags"):
        config_flags(PPOConfig, total_steps="n")
    config_flags(PPOConfig, total_steps="steps", n_envs="envs")  # the same again: fine
