"""The Stable-Baselines3 row: `pioneer train sb3-ppo` end to end with a tiny budget, its policy
file (no pickle) back as the registry's `sb3-ppo`, and its refusals."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from pioneer.baselines.sb3 import CURVE_COLUMNS, env_id_for, make_sb3_policy
from pioneer.control.registry import build_policy
from pioneer.envs.env import NavEnv
from pioneer_testutils import assert_house_message, run_cli


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("sb3") / "run"
    res = run_cli("train", "sb3-ppo", "--scenario", "hl-rr", "--steps", "64", "--out", str(out))
    assert res.returncode == 0, res.stderr
    return out, res


def test_the_command_runs_end_to_end_and_writes_every_output(trained):
    out, res = trained
    assert {p.name for p in out.iterdir()} == {
        "policy.safetensors",
        "curve.csv",
        "curve.png",
        "train.json",
    }
    summary = json.loads((out / "train.json").read_text())
    # SB3 collects whole rollouts: one of its default 2,048 steps
    assert summary["env_steps"] == 2048 and summary["env_id"] == "pioneer/ElevatorHLRR-v1"
    assert summary["sb3"]["n_steps"] == 2048 and summary["sb3"]["policy"] == "MlpPolicy"
    assert "command" in summary  # the console script records its command line
    rows = list(csv.reader((out / "curve.csv").open()))
    assert tuple(rows[0]) == CURVE_COLUMNS and len(rows) == 2
    assert int(rows[1][1]) == 2048 and int(rows[1][2]) == summary["episodes"] > 0
    assert json.loads(res.stdout.splitlines()[-1])["final"].keys() == {
        "mean_return",
        "success_rate",
        "collision_rate",
        "timeout_rate",
    }
    assert not out.joinpath("policy.zip").exists()  # no SB3 zip (pickles)


def test_the_policy_file_loads_without_pickle_and_acts_like_sb3(trained):
    out, _ = trained
    from safetensors import safe_open

    with safe_open(str(out / "policy.safetensors"), framework="pt") as fh:
        assert json.loads(fh.metadata()["config"])["net_arch"] == {"pi": [64, 64], "vf": [64, 64]}
    policy = build_policy("sb3-ppo", "hl-rr", weights=str(out / "policy.safetensors"))
    env = NavEnv("hl-rr")
    obs, info = env.reset(seed=3)
    policy.reset(info, np.random.default_rng(0))
    a = policy.act(obs, info)
    ref, _ = policy.policy.predict(obs, deterministic=True)  # type: ignore[attr-defined]
    assert a.shape == (2,) and a.dtype == np.float64
    np.testing.assert_array_equal(a, ref.astype(np.float64))
    assert env.action_space.contains(a.astype(np.float32))


def test_eval_runs_the_trained_policy(trained, tmp_path):
    out, _ = trained
    spec = f"sb3-ppo:weights={out / 'policy.safetensors'}"
    res = run_cli(
        "eval", "--policy", spec, "--scenario", "hl-rr", "--seeds", "1", "--trials", "2",
        "--workers", "1", "--out", str(tmp_path / "e"),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "hl-rr/sb3-ppo" in res.stdout


def test_refusals_are_one_line(trained, tmp_path):
    out, _ = trained
    again = run_cli("train", "sb3-ppo", "--steps", "64", "--out", str(out))
    assert again.returncode == 2
    assert_house_message(again.stderr.strip(), "--out: expected a folder without an SB3 run")
    missing = run_cli(
        "eval", "--policy", "sb3-ppo", "--scenario", "hl-rr", "--out", str(tmp_path / "e")
    )
    assert missing.returncode == 2 and len(missing.stderr.strip().splitlines()) == 1
    assert "expected a value for ['weights']" in missing.stderr
    assert not (tmp_path / "e").exists()
    bad = tmp_path / "bad.safetensors"
    bad.write_bytes(b"not a safetensors file")
    with pytest.raises(Exception, match="sb3-ppo weights"):
        make_sb3_policy(str(bad))


def test_scenarios_map_to_their_gymnasium_ids():
    assert env_id_for("hr-rl") == ("pioneer/ElevatorHRRL-v1", {})
    assert env_id_for("hl-rr") == ("pioneer/ElevatorHLRR-v1", {})
    assert env_id_for("hr-rl-compact") == ("pioneer/ElevatorHRRL-v1", {"scenario": "hr-rl-compact"})
