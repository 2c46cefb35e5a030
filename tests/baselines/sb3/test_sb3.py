"""The Stable-Baselines3 row: `pioneer train sb3-ppo` end to end with a tiny budget, its policy
file (no pickle) back as the registry's `sb3-ppo`, its checkpoint (no pickle) and resume, and
its refusals."""

from __future__ import annotations

import csv
import json
import random
import shlex
import signal
import zipfile

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

import torch
from safetensors.torch import load_file

from pioneer.baselines.sb3 import CHECKPOINT, CURVE_COLUMNS, env_id_for, make_sb3_policy
from pioneer.baselines.sb3.checkpoint import restore, save_state
from pioneer.baselines.sb3.train import _build
from pioneer.control.registry import build_policy
from pioneer.envs.env import NavEnv
from pioneer.registration import register_envs
from pioneer.reward.crowdnav import NO_INTRUSION, CrowdNavRewardConfig
from pioneer_testutils import (
    assert_house_message,
    file_tree,
    interrupted_line,
    one_error_line,
    run_cli,
    stop_cli,
)


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
        "checkpoint.safetensors",
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
    old = tmp_path / "old"  # a run made before checkpoints: its policy without one
    old.mkdir()
    old.joinpath("policy.safetensors").write_bytes((out / "policy.safetensors").read_bytes())
    before = file_tree(old)
    again = run_cli("train", "sb3-ppo", "--steps", "64", "--out", str(old))
    line = one_error_line(again.stderr, again.returncode, "--out", "made before", "new --out")
    assert_house_message(line)
    assert file_tree(old) == before
    resume = run_cli("train", "sb3-ppo", "--steps", "64", "--resume", "--out", str(tmp_path / "n"))
    one_error_line(resume.stderr, resume.returncode, "--resume", "drop --resume")
    assert not (tmp_path / "n").exists()
    # without weights= the shipped policy is loaded; a missing file is refused before any work
    gone = str(tmp_path / "gone.safetensors")
    missing = run_cli(
        "eval", "--policy", f"sb3-ppo:weights={gone}", "--scenario", "hl-rr", "--out",
        str(tmp_path / "e"),
    )  # fmt: skip
    assert missing.returncode == 2 and len(missing.stderr.strip().splitlines()) == 1
    assert "gone.safetensors" in missing.stderr
    assert not (tmp_path / "e").exists()
    bad = tmp_path / "bad.safetensors"
    bad.write_bytes(b"not a safetensors file")
    with pytest.raises(Exception, match="sb3-ppo weights"):
        make_sb3_policy(str(bad))


def test_scenarios_map_to_their_gymnasium_ids():
    assert env_id_for("hr-rl") == ("pioneer/ElevatorHRRL-v1", {})
    assert env_id_for("hl-rr") == ("pioneer/ElevatorHLRR-v1", {})
    assert env_id_for("hr-rl-compact") == ("pioneer/ElevatorHRRL-v1", {"scenario": "hr-rl-compact"})


# ------------------------------------------------------------------------------ resume
def _sb3(out, steps, *extra):
    argv = ["train", "sb3-ppo", "--scenario", "hl-rr", "--envs", "1", "--steps", str(steps)]
    return run_cli(*argv, "--out", str(out), *extra)


def _rows(out):
    return list(csv.reader((out / "curve.csv").open()))[1:]


def _metadata(path):
    from safetensors import safe_open

    with safe_open(str(path), framework="pt") as fh:
        return fh.metadata()


@pytest.fixture(scope="module")
def resumed(tmp_path_factory: pytest.TempPathFactory):
    """One update (2,048 steps), then the same command with --steps 4096 on the same --out;
    the folder and its files after the first part."""
    out = tmp_path_factory.mktemp("sb3-resume") / "run"
    first = _sb3(out, 2048)
    assert first.returncode == 0, first.stderr
    part1 = {p.name: p.read_bytes() for p in out.iterdir()}
    second = _sb3(out, 4096)
    assert second.returncode == 0, second.stderr
    return out, part1


def test_a_rerun_with_more_steps_resumes_from_the_checkpoint(resumed, tmp_path):
    out, part1 = resumed
    first = tmp_path / "first"
    first.mkdir()
    for name, data in part1.items():
        first.joinpath(name).write_bytes(data)
    # after the first part the checkpoint holds the weights it wrote as its policy
    policy, state = load_file(first / "policy.safetensors"), load_file(first / CHECKPOINT)
    assert policy and all(torch.equal(v, state[f"policy/{k}"]) for k, v in policy.items())
    summary = json.loads((out / "train.json").read_text())
    assert summary["env_steps"] == 4096 and summary["resumed_from_steps"] == 2048
    assert summary["updates"] == 2
    rows = _rows(out)
    assert [r[:2] for r in rows] == [["1", "2048"], ["2", "4096"]]
    assert rows[0] == _rows(first)[0]  # curve.csv kept its row and was appended to
    assert int(rows[1][2]) == summary["episodes"] >= int(rows[0][2])
    assert not torch.equal(load_file(out / "policy.safetensors")["log_std"], policy["log_std"])
    # a finished run: the same command again trains nothing and keeps the weights
    weights = load_file(out / "policy.safetensors")
    again = _sb3(out, 4096)
    assert again.returncode == 0, again.stderr
    assert (
        json.loads((out / "train.json").read_text())["env_steps"] == 4096 and len(_rows(out)) == 2
    )
    assert all(torch.equal(v, weights[k]) for k, v in load_file(out / "policy.safetensors").items())


def _global_rngs():
    return random.getstate(), np.random.get_state(), torch.get_rng_state()  # noqa: NPY002


def _set_global_rngs(states):
    random.setstate(states[0])
    np.random.set_state(states[1])  # noqa: NPY002
    torch.set_rng_state(states[2])


def test_the_checkpoint_holds_no_pickle_and_round_trips_the_training_state(resumed, tmp_path):
    out, _ = resumed
    ckpt = out / CHECKPOINT
    raw = ckpt.read_bytes()
    header = json.loads(raw[8 : 8 + int.from_bytes(raw[:8], "little")])  # safetensors: JSON + data
    assert not zipfile.is_zipfile(ckpt)  # torch.save writes a zip of pickles
    dtypes = {v["dtype"] for k, v in header.items() if k != "__metadata__"}
    assert dtypes <= {"F32", "F64", "I64", "U8"}
    assert json.loads(header["__metadata__"]["settings"])["n_envs"] == 1
    stored = load_file(ckpt)
    saved = _global_rngs()  # building the model and restoring the state set the global RNGs
    try:
        register_envs()
        model, venv = _build("pioneer/ElevatorHLRR-v1", {}, 1, 0)  # a fresh model
        curve = restore(ckpt, model)
        venv.close()
        assert model.num_timesteps == 4096 and model._n_updates == 20  # 2 updates of 10 epochs
        assert len(curve.rows) == 2 and len(curve.window) == min(curve.episodes, 100)
        osd = model.policy.optimizer.state_dict()
        n_params = len(list(model.policy.parameters()))
        names = {f"optim/{i}/{k}" for i, st in osd["state"].items() for k in st}
        assert names == {k for k in stored if k.startswith("optim/")}
        assert len(names) == 3 * n_params  # exp_avg, exp_avg_sq, step of every parameter
        for i, st in osd["state"].items():
            for k, v in st.items():
                ref = stored[f"optim/{i}/{k}"]
                assert v.dtype == ref.dtype and torch.equal(v, ref), (i, k)
        for k, v in model.policy.state_dict().items():
            assert torch.equal(v, stored[f"policy/{k}"]), k
        assert torch.equal(torch.get_rng_state(), stored["rng/torch"])
        key = np.random.get_state()[1]  # noqa: NPY002
        np.testing.assert_array_equal(key, stored["rng/numpy_key"].numpy())
        # written again from the restored model: the same tensors and state
        again = tmp_path / "again.safetensors"
        settings = json.loads(header["__metadata__"]["settings"])
        save_state(again, model, curve, curve.wall, settings)
        rewritten = load_file(again)
        assert rewritten.keys() == stored.keys()
        assert all(torch.equal(rewritten[k], stored[k]) for k in stored), "round trip"
    finally:
        _set_global_rngs(saved)


@pytest.mark.parametrize(
    ("extra", "flag"),
    [
        (["--envs", "2"], "--envs"),
        (["--seed", "1"], "--seed"),
        (["--scenario", "hr-rl"], "--scenario"),
        (["--reward", "no-intrusion"], "--reward"),
    ],
)
def test_other_settings_on_an_existing_run_are_refused(resumed, extra, flag):
    out, _ = resumed
    before = file_tree(out)
    argv = {"--scenario": "hl-rr", "--envs": "1", "--steps": "6144", "--seed": "0"}
    argv[extra[0]] = extra[1]
    res = run_cli("train", "sb3-ppo", *[a for kv in argv.items() for a in kv], "--out", str(out))
    line = one_error_line(res.stderr, res.returncode, flag, "only --steps may change")
    assert_house_message(line, f"received {{'{flag}'")
    assert file_tree(out) == before


def test_a_resumed_run_is_reproducible(resumed, tmp_path):
    """The same run interrupted and resumed at the same step, twice: the same weights, Adam
    state and RNG states, bit for bit (the curves differ only in their wall times)."""
    out, _ = resumed
    copy = tmp_path / "copy"
    for steps in (2048, 4096):
        res = _sb3(copy, steps)
        assert res.returncode == 0, res.stderr
    for name in ("policy.safetensors", CHECKPOINT):
        a, b = load_file(out / name), load_file(copy / name)
        assert a.keys() == b.keys()
        for k in a.keys() - {"curve"}:
            assert torch.equal(a[k], b[k]), (name, k)
    assert [r[:-1] for r in _rows(out)] == [r[:-1] for r in _rows(copy)]


@pytest.mark.slow
def test_a_signal_keeps_the_finished_updates_and_the_rerun_resumes(resumed, tmp_path, capsys):
    """Ctrl-C during the first update: it finishes, its checkpoint is written, the one line
    names it; the same command resumes — to the weights of the run resumed at that step."""
    out = tmp_path / "run"
    argv = ["train", "sb3-ppo", "--scenario", "hl-rr", "--envs", "1", "--steps", "4096"]
    argv += ["--out", str(out)]

    def started() -> bool:  # the first rollout is collected: its update runs
        return (out / "curve.csv").is_file() and len(_rows(out)) >= 1

    stopped = stop_cli(argv, started, signal.SIGINT, tmp_path, group=True)
    kept = len(_rows(out))
    with capsys.disabled():
        print(f"SIGINT: exit {stopped.returncode} in {stopped.seconds:.2f} s, {kept} update kept")
    stopped.assert_clean(signal.SIGINT)
    assert interrupted_line(stopped.stderr) == (
        f"pioneer: interrupted (SIGINT); update {kept} of 2 kept in {out / CHECKPOINT}; "
        f"resume with: {shlex.join(['pioneer', *argv])}"
    )
    state = json.loads(_metadata(out / CHECKPOINT)["counters"])
    assert state["num_timesteps"] == 2048 * kept
    res = run_cli(*argv)
    assert res.returncode == 0, res.stderr
    assert json.loads((out / "train.json").read_text())["env_steps"] == 4096
    if kept == 1:  # resumed at step 2,048, as the `resumed` run
        a, b = load_file(resumed[0] / "policy.safetensors"), load_file(out / "policy.safetensors")
        assert all(torch.equal(a[k], b[k]) for k in a)


@pytest.mark.parametrize("scenario", ["hr-rl", "hl-rr"])
def test_the_shipped_policy_loads_without_weights(scenario):
    """The `sb3-ppo` row of Table I: the shipped file of each scenario, the files it recorded."""
    from pioneer.control.policy_files import sb3_files
    from pioneer.data import shipped_sb3_weights

    policy = build_policy("sb3-ppo", scenario)
    env = NavEnv(scenario)
    obs, info = env.reset(seed=0)
    policy.reset(info, np.random.default_rng(0))
    assert env.action_space.contains(policy.act(obs, info).astype(np.float32))
    # it acts as SB3's own predict, bit for bit, along an episode
    for _ in range(60):
        a = policy.act(obs, info)
        ref, _ = policy.policy.predict(obs, deterministic=True)  # type: ignore[attr-defined]
        np.testing.assert_array_equal(a, ref.astype(np.float64))
        obs, _, done, cut, info = env.step(a)
        if done or cut:
            break
    assert sb3_files(scenario, {}) == {"weights": shipped_sb3_weights(scenario)}
    assert sb3_files(scenario, {"weights": "mine.safetensors"}) == {}


def test_the_reward_without_intrusion_reaches_the_environments(tmp_path):
    """``--reward no-intrusion``: every training environment prices steps with
    :data:`~pioneer.reward.crowdnav.NO_INTRUSION`, and the run's summary names it."""
    venv = _build(*env_id_for("hl-rr"), 2, 0)[1]
    assert all(e.unwrapped.reward.config == CrowdNavRewardConfig() for e in venv.envs)
    env_id, kwargs = env_id_for("hl-rr")
    venv = _build(env_id, {**kwargs, "reward": NO_INTRUSION}, 2, 0)[1]
    assert all(e.unwrapped.reward.config is NO_INTRUSION for e in venv.envs)
    out = tmp_path / "run"
    argv = ["--scenario", "hl-rr", "--steps", "64", "--reward", "no-intrusion"]
    res = run_cli("train", "sb3-ppo", *argv, "--out", str(out))
    assert res.returncode == 0, res.stderr
    assert json.loads((out / "train.json").read_text())["reward"] == "no-intrusion"


def test_learning_writes_no_log_folder_of_sb3s_own(tmp_path, monkeypatch):
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # where SB3's default logger writes
    model, venv = _build(*env_id_for("hl-rr"), 1, 0)
    model.learn(64)
    venv.close()
    assert not list(tmp_path.glob("SB3-*"))  # no /tmp/SB3-<time> per run
