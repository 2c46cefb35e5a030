"""DAgger (``pioneer.learn.dagger``) and ``pioneer distill``: outputs, labels, seeds,
determinism across runs and worker counts, resume (also after SIGINT or SIGTERM), refused
reruns, bad settings.

The runs use a test-only scenario, ``tiny-static``: the static study truncated after 0.8 s
(8 decisions an episode), so a whole DAgger run takes a few seconds. Spawned collection
workers learn it through the pool initializer (see ``_tiny_worker_init``).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import shlex
import shutil
import signal
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch

import pioneer.learn.dagger as dagger
import pioneer.reward.recipe as reward_default
from pioneer.cli import main
from pioneer.control.teacher import Assumptions, SoftMargins, make_teacher
from pioneer.envs.env import NavEnv
from pioneer.errors import ConfigError, DataError, ScenarioError
from pioneer.eval.harness import episode_seed
from pioneer.io import file_sha256
from pioneer.learn import MDN, MLPStudent, load_student, make_student_policy, read_checkpoint_meta
from pioneer.learn.collect import TARGET_CANDIDATES
from pioneer.learn.dagger import DaggerConfig, DaggerResult, run_dagger, scenario_set, score_weights
from pioneer.learn.dagger_folder import SCENARIO_FILE
from pioneer.learn.models import StudentConfig
from pioneer.seeds import DAGGER_BASE, TRAINING_BASE, dagger_seed, training_seed
from pioneer.sim.scenarios import ScenarioConfig, StaticStudyLayout, static_study_scenario
from pioneer.sim.scenarios import registry as scenarios
from pioneer.sim.world import SimConfig
from pioneer_testutils import (
    STOP_SIGNALS,
    assert_house_message,
    file_tree,
    interrupted_line,
    one_error_line,
    run_cli,
    stop_cli,
)

torch.set_num_threads(1)

TINY = "tiny-static"
TIME_LIMIT = 0.8  # [s] episode length of the tiny scenario
TINY_CFG = DaggerConfig(
    scenario=TINY,
    teacher_episodes=2,
    rounds=2,
    episodes_per_round=2,
    epochs_initial=2,
    epochs_per_round=1,
)
EPISODE_KEYS = {
    "obs",
    "target_commands",
    "target_scores",
    "action",
    "applied",
    "gap",
    "aleatoric",
    "epistemic",
    "event",
    "time_s",
    "env_seed",
    "scenario",
}


def _tiny_scenario() -> ScenarioConfig:
    return dataclasses.replace(
        static_study_scenario(sim=SimConfig(time_limit=TIME_LIMIT)), name=TINY
    )


_REAL_WORKER_INIT = dagger._worker_init


def _tiny_worker_init() -> None:
    """Pool initializer: spawned workers import this module (the parent's ``sys.path`` is
    passed on), register the tiny scenario, then run the real initializer."""
    scenarios._REGISTRY.setdefault(TINY, _tiny_scenario)
    _REAL_WORKER_INIT()


@pytest.fixture(scope="module", autouse=True)
def tiny_scenario() -> Iterator[str]:
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(scenarios._REGISTRY, TINY, _tiny_scenario)
        mp.setattr(dagger, "_worker_init", _tiny_worker_init)
        yield TINY


@pytest.fixture(scope="module")
def reward_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The static study's density reward, fitted once (the tiny scenario has no demos)."""
    path = tmp_path_factory.mktemp("reward") / "static.npz"
    reward_default.default_reward("static").save(path)
    return path


@pytest.fixture(scope="module")
def run_mdn(tmp_path_factory: pytest.TempPathFactory) -> tuple[DaggerResult, list[dict[str, Any]]]:
    """The reference run (workers=1, default reward → ``DIR/reward.npz``) and its callbacks."""
    out = tmp_path_factory.mktemp("dagger") / "mdn"
    rows: list[dict[str, Any]] = []
    real = reward_default.default_reward
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(reward_default, "default_reward", lambda scenario: real("static"))
        res = run_dagger(TINY_CFG, out, workers=1, progress=False, on_round=rows.append)
    return res, rows


def _load(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as f:
        return {k: f[k] for k in f.files}


def _episodes(out: Path) -> dict[str, dict[str, np.ndarray]]:
    """Every episode file of a run, by path relative to the run folder."""
    return {
        str(p.relative_to(out)): _load(p) for p in sorted((out / "rounds").glob("round-*/ep-*.npz"))
    }


def _same_rows(a: list[dict[str, Any]], b: list[dict[str, Any]]) -> bool:
    """Equal curve rows (NaN equal to NaN)."""
    return len(a) == len(b) and all(
        ra.keys() == rb.keys()
        and all(
            x == y or (isinstance(x, float) and math.isnan(x) and math.isnan(y))
            for x, y in zip(ra.values(), rb.values(), strict=True)
        )
        for ra, rb in zip(a, b, strict=True)
    )


def _assert_same_episodes(a: Path, b: Path) -> None:
    ea, eb = _episodes(a), _episodes(b)
    assert sorted(ea) == sorted(eb)
    for name, ep in ea.items():
        assert set(ep) == set(eb[name]), name
        for key, arr in ep.items():
            np.testing.assert_array_equal(arr, eb[name][key], err_msg=f"{name}:{key}")


def _assert_same_weights(a: Path, b: Path) -> None:
    sa, sb = load_student(a).state_dict(), load_student(b).state_dict()
    assert list(sa) == list(sb)
    for key, value in sa.items():
        assert torch.equal(value, sb[key]), key


def _snapshot(out: Path, rounds: range) -> dict[str, tuple[int, bytes]]:
    """mtime and content of every file of the given rounds."""
    return {
        str(p.relative_to(out)): (p.stat().st_mtime_ns, p.read_bytes())
        for r in rounds
        for p in sorted((out / "rounds" / f"round-{r:02d}").iterdir())
    }


@pytest.fixture
def collected(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Paths of the episodes collected from now on (in-process collection, workers=1)."""
    seen: list[str] = []
    real = dagger._collect_task

    def spy(args: tuple[str, str, str | None, int, str]) -> str:
        seen.append(str(Path(args[4]).relative_to(Path(args[4]).parents[1])))
        return real(args)

    monkeypatch.setattr(dagger, "_collect_task", spy)
    return seen


def _distill_argv(out: Path, *extra: str, rounds: int = 2) -> list[str]:
    return [
        "distill",
        "--scenario",
        TINY,
        "--out",
        str(out),
        "--teacher-episodes",
        "2",
        "--rounds",
        str(rounds),
        "--episodes-per-round",
        "2",
        "--epochs-initial",
        "2",
        "--epochs-per-round",
        "1",
        "--workers",
        "1",
        *extra,
    ]


# ------------------------------------------------------------------------------ outputs
def test_run_writes_every_output(run_mdn):
    res, _ = run_mdn
    out = res.out
    assert res.student == out / "student.safetensors"
    for name in ("config.json", "reward.npz", "curves.csv", "curves.png", "student.safetensors"):
        assert (out / name).is_file(), name
    settings = {**TINY_CFG.to_dict(), "reward_sha256": None}  # the default reward
    assert json.loads((out / "config.json").read_text()) == settings
    assert (out / "curves.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in (out / "rounds").iterdir()) == [
        "round-00",
        "round-01",
        "round-02",
    ]
    for rnd in range(3):
        rdir = out / "rounds" / f"round-{rnd:02d}"
        assert sorted(p.name for p in rdir.iterdir()) == [
            "ep-000.npz",
            "ep-001.npz",
            "student.safetensors",
        ]
    assert not list(out.rglob(".*"))  # no temporary file left behind
    # The final student is the last round's.
    assert res.student.read_bytes() == (out / "rounds/round-02/student.safetensors").read_bytes()


def test_curves_have_one_row_per_round(run_mdn):
    res, rows = run_mdn
    assert rows == res.curves
    assert [r["round"] for r in res.curves] == [0, 1, 2]
    assert [r["driver"] for r in res.curves] == ["teacher", "student", "student"]
    assert [r["episodes"] for r in res.curves] == [2, 2, 2]
    frames = [r["frames_total"] for r in res.curves]
    assert frames[0] > 0 and frames[0] < frames[1] < frames[2]
    assert frames[-1] == sum(len(ep["obs"]) for ep in _episodes(res.out).values())
    assert math.isnan(res.curves[0]["loss_new_data"])
    assert all(math.isfinite(r["loss_new_data"]) for r in res.curves[1:])
    assert all(math.isfinite(r["train_loss"]) for r in res.curves)
    for r in res.curves:
        assert 0.0 <= r["success_rate"] + r["collision_rate"] <= 1.0
        assert 0.0 < r["mean_time_s"] <= TIME_LIMIT + 1e-9
    with open(res.out / "curves.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert len(table) == 3
    assert [int(t["frames_total"]) for t in table] == frames
    assert [t["driver"] for t in table] == ["teacher", "student", "student"]


def test_final_student_loads_with_dagger_info(run_mdn):
    res, _ = run_mdn
    model = load_student(res.student)
    assert isinstance(model, MDN) and not model.training
    info = read_checkpoint_meta(res.student)["info"]
    assert info["source"] == "dagger"
    assert info["scenario"] == TINY and info["round"] == 2
    assert info["dagger"] == TINY_CFG.to_dict()
    assert info["frames"] == res.curves[-1]["frames_total"]
    assert len(info["loss_history"]) == TINY_CFG.epochs_per_round
    assert info["loss_history"][-1] == pytest.approx(res.curves[-1]["train_loss"])
    qs = info["uncertainty_quantiles"]
    assert set(qs) == {"aleatoric", "epistemic"}
    for name, by_q in qs.items():
        assert list(by_q) == ["0.5", "0.9", "0.95", "0.99"], name
        values = list(by_q.values())
        assert all(v >= 0 and math.isfinite(v) for v in values)
        assert values == sorted(values), name
    first = read_checkpoint_meta(res.out / "rounds/round-00/student.safetensors")["info"]
    assert first["round"] == 0 and len(first["loss_history"]) == TINY_CFG.epochs_initial


def test_warm_started_rounds_keep_round_0s_normalisation(run_mdn):
    # Re-fitting the standardisation under trained weights would shift the network's inputs
    # and outputs before any training; it is fitted once, on round 0's frames.
    res, _ = run_mdn
    models = [load_student(res.out / f"rounds/round-{r:02d}/student.safetensors") for r in range(3)]
    eps = sorted((res.out / "rounds/round-00").glob("ep-*.npz"))
    obs = np.concatenate([np.load(p)["obs"] for p in eps])
    first = models[0]
    assert torch.allclose(first.obs_mean, torch.as_tensor(obs.mean(axis=0)), atol=1e-5)
    for later in models[1:]:
        for name in ("obs_mean", "obs_std", "act_mean", "act_std"):
            assert torch.equal(getattr(later, name), getattr(first, name)), name


def test_episode_files_hold_labelled_frames(run_mdn):
    res, _ = run_mdn
    eps = _episodes(res.out)
    assert len(eps) == 6
    for name, ep in eps.items():
        rnd, i = int(name.split("round-")[1][:2]), int(name.split("ep-")[1][:3])
        assert set(ep) == EPISODE_KEYS, name
        n = len(ep["obs"])
        assert ep["obs"].shape == (n, 29) and ep["obs"].dtype == np.float32
        for key in ("action", "applied"):
            assert ep[key].shape == (n, 2) and ep[key].dtype == np.float32
            assert np.all(np.isfinite(ep[key]))
        for key in ("gap", "aleatoric", "epistemic"):
            assert ep[key].shape == (n,)
        assert str(ep["event"]) in {"success", "collision", "timeout"}
        k = TARGET_CANDIDATES
        assert ep["target_commands"].shape == (n, k, 2) and ep["target_scores"].shape == (n, k)
        # the best candidate, smoothed as the teacher sends it, is the label itself
        np.testing.assert_allclose(ep["target_commands"][:, 0], ep["action"], atol=1e-6)
        finite = np.isfinite(ep["target_scores"])
        assert finite[:, 0].all() and np.all(np.diff(finite.astype(int), axis=1) <= 0)
        s = np.where(finite, ep["target_scores"], -np.inf)
        assert np.all(np.diff(s, axis=1)[finite[:, 1:]] <= 0)  # best first
        assert float(ep["time_s"]) == pytest.approx(0.1 * n)
        assert int(ep["env_seed"]) == dagger_seed(TINY, 0, rnd, i)
        if rnd == 0:  # the teacher drives: no student uncertainty
            assert np.all(np.isnan(ep["aleatoric"])) and np.all(np.isnan(ep["epistemic"]))
        else:
            assert np.all(ep["aleatoric"] > 0) and np.all(ep["epistemic"] >= 0)


# ------------------------------------------------------------------------------ labels
def test_teacher_round_labels_are_the_applied_commands(run_mdn):
    res, _ = run_mdn
    for i in range(2):
        ep = _load(res.out / f"rounds/round-00/ep-{i:03d}.npz")
        np.testing.assert_array_equal(ep["action"], ep["applied"])


def test_student_rounds_apply_the_previous_rounds_student(run_mdn):
    res, _ = run_mdn
    for rnd in (1, 2):
        ckpt = res.out / f"rounds/round-{rnd - 1:02d}/student.safetensors"
        pol = make_student_policy(ckpt)
        for i in range(2):
            ep = _load(res.out / f"rounds/round-{rnd:02d}/ep-{i:03d}.npz")
            pol.reset({}, np.random.default_rng(0))
            u = np.stack([pol.act(o, {}) for o in ep["obs"]])
            np.testing.assert_allclose(ep["applied"], u, rtol=0, atol=1e-6)
            unc = np.asarray(pol.uncertainty)
            np.testing.assert_allclose(ep["aleatoric"], unc[:, 0], rtol=1e-6)
            np.testing.assert_allclose(ep["epistemic"], unc[:, 1], rtol=1e-6)
            # The labels are the teacher's, not the student's own commands.
            assert not np.allclose(ep["action"], ep["applied"], atol=1e-3)


def test_student_round_labels_are_the_teachers_decisions_from_the_applied_command(
    run_mdn, reward_file
):
    """Replay a student episode with its applied commands: every stored frame is the state's
    observation, and every label is the teacher's decision smoothed from ``state.command``."""
    res, _ = run_mdn
    ep = _load(res.out / "rounds/round-02/ep-001.npz")
    teacher = make_teacher(TINY, reward=str(reward_file))
    env = NavEnv(TINY)
    obs, info = env.reset(seed=int(ep["env_seed"]))
    teacher.reset(info, np.random.default_rng(0))
    for t in range(len(ep["obs"])):
        np.testing.assert_array_equal(ep["obs"][t], obs)
        assert ep["gap"][t] == info["min_gap"]
        state = info["state"]
        label = teacher.decide(info["world"], state, prev=state.command[0]).command
        np.testing.assert_allclose(ep["action"][t], label, rtol=0, atol=1e-6)
        obs, _, term, trunc, info = env.step(ep["applied"][t].astype(np.float64))
        assert (term or trunc) == (t == len(ep["obs"]) - 1)
    assert info["event"] == str(ep["event"])


def test_dagger_seeds_are_deterministic_and_disjoint_from_evaluation_seeds():
    for scenario in ("hr-rl", "hl-rr", TINY):
        train = {
            dagger_seed(scenario, s, r, e) for s in range(3) for r in range(4) for e in range(20)
        }
        assert len(train) == 3 * 4 * 20  # all distinct
        assert train == {
            dagger_seed(scenario, s, r, e) for s in range(3) for r in range(4) for e in range(20)
        }
        evaluation = {episode_seed(scenario, s, t) for s in range(3) for t in range(80)}
        assert not train & evaluation
        # training seeds, in DAgger's half of the range: above every demonstration seed
        assert all(DAGGER_BASE <= x < 2 * TRAINING_BASE for x in train)
        assert training_seed(100_000, 10**6) < DAGGER_BASE  # demos: seed, seed + 100,000
    assert dagger_seed("hr-rl", 0, 0, 0) != dagger_seed("hl-rr", 0, 0, 0)
    assert dagger_seed("hr-rl", 0, 1, 0) != dagger_seed("hr-rl", 0, 0, 1)


# ------------------------------------------------------------------------------ determinism
def test_two_workers_collect_the_same_episodes(run_mdn, reward_file, tmp_path):
    res, _ = run_mdn
    try:
        res2 = run_dagger(TINY_CFG, tmp_path / "w2", workers=2, reward=reward_file, progress=False)
    finally:
        torch.set_num_threads(1)  # run_dagger sets one torch thread per worker in this process
    ea, eb = _episodes(res.out), _episodes(res2.out)
    assert sorted(ea) == sorted(eb)
    for name, ep in ea.items():
        other = eb[name]
        for key in ("event", "env_seed", "time_s"):
            assert ep[key] == other[key], name
        if name.startswith("rounds/round-00"):  # the teacher drives: bit for bit
            for key, arr in ep.items():
                np.testing.assert_array_equal(arr, other[key], err_msg=f"{name}:{key}")
        for key in ("obs", "action", "applied", "gap", "aleatoric", "epistemic"):
            np.testing.assert_allclose(
                ep[key], other[key], rtol=1e-5, atol=1e-6, err_msg=f"{name}:{key}"
            )
    assert [r["frames_total"] for r in res2.curves] == [r["frames_total"] for r in res.curves]
    assert read_checkpoint_meta(res2.student)["info"]["dagger"] == TINY_CFG.to_dict()
    # Bit for bit, student rounds and weights included: training runs on one torch thread
    # whatever the worker count.
    _assert_same_weights(res.student, res2.student)
    _assert_same_episodes(res.out, res2.out)


# ------------------------------------------------------------------------------ resume
def test_cli_distill_repeats_the_run_and_resumes(run_mdn, reward_file, tmp_path, capsys, collected):
    """`pioneer distill` with one round, then resumed to two rounds, then an interrupted last
    round: every step reuses what is on disk, collects exactly what is missing, and ends with
    the reference run's episodes and weights (same settings, another folder)."""
    res, _ = run_mdn
    out = tmp_path / "cli"
    assert main(_distill_argv(out, "--reward", str(reward_file), rounds=1)) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("student: ")
    assert str(out / "student.safetensors") in lines[0]
    assert f"{res.curves[1]['frames_total']} frames" in lines[0]
    assert collected == [f"round-{r:02d}/ep-{i:03d}.npz" for r in (0, 1) for i in (0, 1)]
    assert not (out / "reward.npz").exists()  # the given reward is used, not refitted
    assert json.loads((out / "config.json").read_text())["rounds"] == 1
    for rnd in (0, 1):
        ckpt = f"rounds/round-{rnd:02d}/student.safetensors"
        _assert_same_weights(res.out / ckpt, out / ckpt)
    _assert_same_weights(
        out / "student.safetensors", res.out / "rounds/round-01/student.safetensors"
    )
    before = _snapshot(out, range(2))

    # More rounds: rounds 0 and 1 are reused untouched, round 2 is added.
    collected.clear()
    two = run_dagger(TINY_CFG, out, workers=1, reward=reward_file, progress=False)
    assert collected == ["round-02/ep-000.npz", "round-02/ep-001.npz"]
    assert _snapshot(out, range(2)) == before
    assert _same_rows(two.curves, res.curves)
    assert json.loads((out / "config.json").read_text())["rounds"] == 2
    _assert_same_episodes(res.out, out)
    _assert_same_weights(res.student, two.student)

    # Nothing missing: nothing collected, nothing retrained.
    collected.clear()
    all_before = _snapshot(out, range(3))
    run_dagger(TINY_CFG, out, workers=1, reward=reward_file, progress=False)
    assert collected == []
    assert _snapshot(out, range(3)) == all_before

    # An interrupted last round: exactly the missing episode is collected again, and the
    # student retrained to the weights of the uninterrupted run.
    (out / "rounds/round-02/ep-001.npz").unlink()
    (out / "rounds/round-02/student.safetensors").unlink()
    (out / "student.safetensors").unlink()
    kept = _snapshot(out, range(3))
    collected.clear()
    again = run_dagger(TINY_CFG, out, workers=1, reward=reward_file, progress=False)
    assert collected == ["round-02/ep-001.npz"]
    after = _snapshot(out, range(3))
    assert {k: after[k] for k in kept} == kept
    _assert_same_episodes(res.out, out)
    _assert_same_weights(res.student, again.student)
    _assert_same_weights(res.student, out / "rounds/round-02/student.safetensors")


def _static_argv(out: Path, reward: Path, workers: int) -> list[str]:
    """A short DAgger run on the static study (~0.5 s an episode), in a fresh interpreter."""
    return [
        "distill", "--scenario", "static", "--teacher-episodes", "4", "--rounds", "1",
        "--episodes-per-round", "2", "--epochs-initial", "2", "--epochs-per-round", "1",
        "--reward", str(reward), "--workers", str(workers), "--out", str(out),
    ]  # fmt: skip


@pytest.fixture(scope="module")
def static_run(tmp_path_factory: pytest.TempPathFactory, reward_file: Path) -> Path:
    """That run uninterrupted (in this process, one worker: the same episodes and weights)."""
    out = tmp_path_factory.mktemp("dagger") / "static"
    assert main(_static_argv(out, reward_file, 1)) == 0
    return out


@pytest.mark.slow
@STOP_SIGNALS
def test_a_signal_stops_distill_at_once_and_the_rerun_ends_bit_for_bit(
    tmp_path, reward_file, static_run, signum, group
):
    """Stopped while two workers collect: exit 128 + signal within 2 s, no process left, one
    line with what was kept and the command; the rerun ends with the uninterrupted run's
    episodes and student, bit for bit."""
    out = tmp_path / "run"
    argv = _static_argv(out, reward_file, 2)
    first = out / "rounds" / "round-00"
    stopped = stop_cli(argv, lambda: any(first.glob("ep-*.npz")), signum, tmp_path, group)
    print(f"{signal.Signals(signum).name}: exit {stopped.returncode} in {stopped.seconds:.2f} s")
    stopped.assert_clean(signum)
    episodes = len(list((out / "rounds").glob("round-*/ep-*.npz")))
    students = len(list((out / "rounds").glob("round-*/student.safetensors")))
    assert 1 <= episodes < 6
    assert interrupted_line(stopped.stderr) == (
        f"pioneer: interrupted ({signal.Signals(signum).name}); {episodes} of 6 episodes and "
        f"{students} of 2 rounds kept in {out}; resume with: {shlex.join(['pioneer', *argv])}"
    )
    res = run_cli(*argv)
    assert res.returncode == 0, res.stderr
    _assert_same_episodes(static_run, out)
    _assert_same_weights(static_run / "student.safetensors", out / "student.safetensors")


def test_a_recreated_run_folder_drives_with_its_own_students(tmp_path, reward_file):
    cfg = TINY_CFG.replace(teacher_episodes=1, rounds=1, episodes_per_round=1)
    out = tmp_path / "again"
    run_dagger(cfg, out, workers=1, reward=reward_file, progress=False)
    shutil.rmtree(out)
    run_dagger(cfg.replace(seed=1), out, workers=1, reward=reward_file, progress=False)
    ep = _load(out / "rounds/round-01/ep-000.npz")
    pol = make_student_policy(out / "rounds/round-00/student.safetensors")
    u = np.stack([pol.act(o, {}) for o in ep["obs"]])
    np.testing.assert_allclose(ep["applied"], u, rtol=0, atol=1e-6)


def test_a_corrupt_episode_file_is_reported_with_the_fix(tmp_path, reward_file):
    out = tmp_path / "corrupt"
    cfg = TINY_CFG.replace(rounds=0, teacher_episodes=1)
    run_dagger(cfg, out, workers=1, reward=reward_file, progress=False)
    (out / "rounds/round-00/ep-000.npz").write_bytes(b"not an npz file")
    with pytest.raises(DataError) as err:
        run_dagger(cfg, out, workers=1, reward=reward_file, progress=False)
    assert_house_message(str(err.value), "ep-000.npz", "delete that file")


def test_a_resume_with_another_reward_is_refused_before_any_work(
    run_mdn, reward_file, tmp_path, capsys
):
    """The settings hold the reward file's hash: the remaining episodes of a run are never
    labelled under another reward (a default-reward run resumed with --reward, a --reward run
    resumed with another file), and the refusal leaves the folder as it was."""
    res, _ = run_mdn
    out = tmp_path / "run"
    shutil.copytree(res.out, out)
    shutil.rmtree(out / "rounds" / "round-02")  # a round still to collect
    other = tmp_path / "other.npz"
    shutil.copyfile(reward_file, other)
    with open(other, "ab") as fh:  # another file's bytes (a zip archive reads past them)
        fh.write(b"\0")
    before = file_tree(tmp_path)
    assert main(_distill_argv(out, "--reward", str(reward_file))) == 2
    one_error_line(capsys.readouterr().err, 2, "reward_sha256", "None", "--out")
    assert file_tree(tmp_path) == before
    config = json.loads((out / "config.json").read_text())
    config["reward_sha256"] = file_sha256(reward_file)  # as a run made with --reward stores it
    (out / "config.json").write_text(json.dumps(config))
    before = file_tree(tmp_path)
    assert main(_distill_argv(out, "--reward", str(other))) == 2
    one_error_line(capsys.readouterr().err, 2, "reward_sha256", file_sha256(other)[:12])
    assert file_tree(tmp_path) == before


def test_a_resume_over_a_corrupt_episode_is_refused_before_any_work(
    run_mdn, tmp_path, capsys, collected
):
    """A corrupt episode of an earlier round is named before a resumed run collects anything
    (it was found only after the missing episodes had been collected)."""
    res, _ = run_mdn
    out = tmp_path / "run"
    shutil.copytree(res.out, out)
    shutil.rmtree(out / "rounds" / "round-02")  # a round still to collect
    (out / "rounds" / "round-00" / "ep-001.npz").write_bytes(b"truncated")
    before = file_tree(tmp_path)
    assert main(_distill_argv(out)) == 2
    one_error_line(capsys.readouterr().err, 2, "ep-001.npz", "delete that file")
    assert file_tree(tmp_path) == before
    assert collected == []


@pytest.mark.parametrize(
    ("changes", "needle"),
    [
        ({"student": StudentConfig(kind="mlp")}, "student.kind"),
        ({"seed": 1}, "seed"),
        ({"student": StudentConfig(action_mode="mean")}, "student.action_mode"),
        ({"mirror": True}, "mirror"),
    ],
)
def test_rerun_with_other_settings_is_refused(run_mdn, reward_file, changes, needle):
    res, _ = run_mdn
    config_before = (res.out / "config.json").read_bytes()
    with pytest.raises(ConfigError) as err:
        run_dagger(TINY_CFG.replace(**changes), res.out, workers=1, reward=reward_file)
    assert_house_message(str(err.value), needle, "--out")
    assert (res.out / "config.json").read_bytes() == config_before


@pytest.mark.parametrize("extra", [["--student", "mlp"], ["--seed", "3"]])
def test_cli_rerun_with_other_settings_is_one_line_and_exit_2(run_mdn, reward_file, capsys, extra):
    res, _ = run_mdn
    config_before = (res.out / "config.json").read_bytes()
    assert main(_distill_argv(res.out, "--reward", str(reward_file), *extra)) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip("\n").splitlines()
    assert len(lines) == 1 and lines[0].startswith("pioneer: error:"), captured.err
    assert extra[0].removeprefix("--") in lines[0]
    assert captured.out == ""
    assert (res.out / "config.json").read_bytes() == config_before


def test_mirror_trains_every_frame_also_as_its_mirror_image():
    """``mirror``: the aggregate holds every frame and, after all of them, its mirror image —
    checked frame by frame against the observation's mirror (sector k ↔ (K − k) mod K, angles
    negated) and ω negated, for a student reading o_t, o_{t−1} and u_{t−1}."""
    from pioneer.laser import mirror_observation

    rng = np.random.default_rng(5)
    student = StudentConfig(previous_observation=True, previous_command=True)
    episodes = [
        {
            "obs": rng.uniform(-3.0, 5.0, (n, 29)).astype(np.float32),
            "applied": rng.uniform(-0.5, 0.5, (n, 2)),
            "action": rng.uniform(-0.5, 0.5, (n, 2)).astype(np.float32),
            "gap": rng.uniform(0.0, 2.0, n),
        }
        for n in (7, 3)
    ]
    plain = dagger._Students(TINY_CFG.replace(student=student), {})
    mirrored = dagger._Students(TINY_CFG.replace(student=student, mirror=True), {})
    x, y, repeat, _ = plain.aggregate(episodes)
    xm, ym, repeat_m, _ = mirrored.aggregate(episodes)
    n = x.shape[0]
    assert xm.shape == (2 * n, x.shape[1]) and ym.shape == (2 * n, 2)
    np.testing.assert_array_equal(xm[:n], x)
    np.testing.assert_array_equal(ym[:n], y)
    np.testing.assert_array_equal(repeat_m, np.concatenate([repeat, repeat]))
    row = n
    for e in episodes:  # brute force, frame by frame
        for t in range(len(e["obs"])):
            before = e["obs"][max(t - 1, 0)]
            np.testing.assert_array_equal(xm[row, :29], mirror_observation(e["obs"][t]))
            np.testing.assert_array_equal(xm[row, 29:58], mirror_observation(before))
            # u_{t−1} (v, ω) as the robot ran it: ω negated
            np.testing.assert_array_equal(xm[row, 58:], x[row - n, 58:] * np.float32([1, -1]))
            np.testing.assert_array_equal(ym[row], e["action"][t] * np.float32([1.0, -1.0]))
            row += 1
    # mirroring twice is the identity on the data
    assert np.array_equal(
        dagger._mirrored(dagger._mirrored(episodes[0]))["obs"], episodes[0]["obs"]
    )


# ------------------------------------------------------------------------------ MLP student
def test_teacher_label_prev_smooths_with_the_teachers_own_previous_label(tmp_path, reward_file):
    """``label_prev="teacher"``: on student-driven steps the label is the teacher's decision
    smoothed from its own previous label (as if it had been driving), not from the command
    the student applied."""
    cfg = TINY_CFG.replace(label_prev="teacher", teacher_episodes=1, rounds=1, episodes_per_round=1)
    run_dagger(cfg, tmp_path / "tp", workers=1, reward=reward_file, progress=False)
    ep = _load(tmp_path / "tp/rounds/round-01/ep-000.npz")
    teacher = make_teacher(TINY, reward=str(reward_file))
    env = NavEnv(TINY)
    _, info = env.reset(seed=int(ep["env_seed"]))
    teacher.reset(info, np.random.default_rng(0))
    for t in range(len(ep["obs"])):
        state = info["state"]
        label = teacher.decide(info["world"], state).command  # from its own previous label
        np.testing.assert_allclose(ep["action"][t], label, rtol=0, atol=1e-6)
        _, _, _, _, info = env.step(ep["applied"][t].astype(np.float64))
    # the student did not drive the labels, so smoothing from the applied command would differ
    assert not np.allclose(ep["applied"][:-1], ep["action"][:-1], atol=1e-3)


def test_mlp_student_run(tmp_path, reward_file):
    cfg = TINY_CFG.replace(
        student=StudentConfig(kind="mlp"), teacher_episodes=1, rounds=1, episodes_per_round=1
    )
    res = run_dagger(cfg, tmp_path / "mlp", workers=1, reward=reward_file, progress=False)
    model = load_student(res.student)
    assert isinstance(model, MLPStudent)
    info = read_checkpoint_meta(res.student)["info"]
    assert info["source"] == "dagger" and info["uncertainty_quantiles"] == {}
    assert [r["driver"] for r in res.curves] == ["teacher", "student"]
    ep = _load(tmp_path / "mlp/rounds/round-01/ep-000.npz")
    assert np.all(np.isnan(ep["aleatoric"])) and np.all(np.isnan(ep["epistemic"]))
    pol = make_student_policy(tmp_path / "mlp/rounds/round-00/student.safetensors", kind="mlp")
    u = np.stack([pol.act(o, {}) for o in ep["obs"]])
    np.testing.assert_allclose(ep["applied"], u, rtol=0, atol=1e-6)


def test_mean_action_run_drives_and_ships_the_mixture_mean(tmp_path, reward_file):
    cfg = TINY_CFG.replace(
        student=StudentConfig(action_mode="mean"),
        teacher_episodes=1,
        rounds=1,
        episodes_per_round=1,
    )
    res = run_dagger(cfg, tmp_path / "mean", workers=1, reward=reward_file, progress=False)
    for ckpt in (res.student, tmp_path / "mean/rounds/round-00/student.safetensors"):
        assert load_student(ckpt).config.action_mode == "mean"
    pol = make_student_policy(tmp_path / "mean/rounds/round-00/student.safetensors")
    assert pol.action_mode == "mean"
    ep = _load(tmp_path / "mean/rounds/round-01/ep-000.npz")
    model = load_student(tmp_path / "mean/rounds/round-00/student.safetensors")
    with torch.inference_mode():
        logits, mu, _ = model(torch.as_tensor(ep["obs"]))
        mean = (torch.softmax(logits, -1).unsqueeze(-1) * mu).sum(-2).numpy()
    np.testing.assert_allclose(ep["applied"], mean, rtol=0, atol=1e-6)


def _flat_layout(cfg: DaggerConfig) -> dict[str, Any]:
    """``cfg`` as runs stored it before the student's settings were nested."""
    d = cfg.to_dict()
    student = d.pop("student")
    flat = {"action_mode": student["action_mode"], "nll_beta": student["nll_beta"]}
    return {**d, "student": student["kind"], **flat}


def test_a_run_from_before_the_nested_student_resumes(run_mdn, tmp_path):
    """A config.json of the flat layout (``student`` the kind, ``action_mode`` and
    ``nll_beta`` beside it), older still without ``action_mode`` (meaning "mode"), resumes
    and is rewritten in the current layout."""
    res, _ = run_mdn
    out = tmp_path / "old"
    shutil.copytree(res.out, out)
    old = _flat_layout(TINY_CFG)
    del old["action_mode"]
    (out / "config.json").write_text(json.dumps(old))
    again = run_dagger(TINY_CFG, out, workers=1, progress=False)  # its default reward
    assert again.curves == res.curves
    settings = {**TINY_CFG.to_dict(), "reward_sha256": None}  # the default reward
    assert json.loads((out / "config.json").read_text()) == settings


def test_the_flat_layout_of_older_runs_and_checkpoints_reads_as_the_nested_one():
    mlp = TINY_CFG.replace(student=StudentConfig(kind="mlp", action_mode="mean"))
    assert DaggerConfig.from_dict(_flat_layout(mlp)) == mlp
    assert DaggerConfig.from_dict({"student": "mlp"}).student == StudentConfig(kind="mlp")
    assert DaggerConfig.from_dict({"rounds": 3}) == DaggerConfig(rounds=3)
    with pytest.raises(ConfigError) as err:
        DaggerConfig.from_dict({"action_mode": "median"})
    assert_house_message(str(err.value), "StudentConfig.action_mode")


def test_a_run_from_before_the_margin_tiers_reads_as_one_tier():
    """Runs stored before ``SoftMargins.tiers`` were labelled by a one-tier teacher: their
    settings read so, and a rerun with today's default into their folder is refused."""
    old = TINY_CFG.to_dict()
    del old["margins"]["tiers"]
    cfg = DaggerConfig.from_dict(old)
    assert cfg.margins.tiers == 1 != SoftMargins().tiers
    assert cfg == TINY_CFG.replace(margins=SoftMargins(tiers=1))
    assert DaggerConfig.from_dict(TINY_CFG.to_dict()) == TINY_CFG  # today's layout unchanged


def test_the_labelling_teacher_makes_its_assumptions(monkeypatch, reward_file, tmp_path):
    """``assume`` reaches the teacher that labels every episode; a run stored before it
    existed reads as assuming nothing."""
    from pioneer.learn import collect

    assume = Assumptions(human_radius=0.5, a_robot=0.0)
    made: list[Assumptions] = []
    real = collect._teacher

    def spy(
        scenario: str, reward: str, margins: SoftMargins, assumed: Assumptions, patience: Any
    ) -> Any:
        teacher = real(scenario, reward, margins, assumed, patience)
        made.append(teacher.config.assume)
        return teacher

    monkeypatch.setattr(collect, "_teacher", spy)
    cfg = TINY_CFG.replace(rounds=0, assume=assume)
    run_dagger(cfg, tmp_path / "run", workers=1, reward=reward_file, progress=False)
    assert made and set(made) == {assume}
    old = cfg.to_dict()
    del old["assume"]
    assert DaggerConfig.from_dict(old).assume == Assumptions()


def test_a_changed_scenario_definition_is_refused_on_resume(run_mdn, tmp_path):
    """The run records its scenario's full config; a variant redefined under the same name
    (e.g. an edited scenario file) cannot silently resume, and an older run without the
    record resumes and gets one."""
    res, _ = run_mdn
    recorded = json.loads((res.out / SCENARIO_FILE).read_text())
    assert recorded == json.loads(json.dumps(scenarios.get_scenario(TINY).to_dict()))
    out = tmp_path / "changed"
    shutil.copytree(res.out, out)
    longer = _tiny_scenario().replace(sim=SimConfig(time_limit=2 * TIME_LIMIT))
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(scenarios._REGISTRY, TINY, lambda: longer)
        with pytest.raises(ConfigError) as err:
            run_dagger(TINY_CFG, out, workers=1, progress=False)
    assert_house_message(str(err.value), TINY, "sim", "--out")
    (out / SCENARIO_FILE).unlink()
    again = run_dagger(TINY_CFG, out, workers=1, progress=False)  # its default reward
    assert again.curves == res.curves
    assert json.loads((out / SCENARIO_FILE).read_text()) == recorded


# ------------------------------------------------------------------------------ bad settings
@pytest.mark.parametrize(
    ("changes", "needle"),
    [
        ({"rounds": -1}, "rounds"),
        ({"student": "cnn"}, "DaggerConfig.student"),
        ({"teacher_episodes": 0}, "teacher_episodes"),
        ({"episodes_per_round": 0}, "episodes_per_round"),
        ({"epochs_initial": 0}, "epochs_initial"),
        ({"epochs_per_round": -1}, "epochs_per_round"),
        ({"batch": 0}, "batch"),
        ({"seed": -1}, "seed"),
        ({"rounds": 1.5}, "rounds"),
        ({"lr": 0.0}, "lr"),
        ({"lr": math.nan}, "lr"),
        ({"label_prev": "student"}, "label_prev"),
    ],
)
def test_bad_config_values_are_refused(changes, needle):
    with pytest.raises(ConfigError) as err:
        DaggerConfig(**changes)
    assert_house_message(str(err.value), needle)


def test_config_round_trips_and_rejects_unknown_keys():
    assert DaggerConfig.from_dict(TINY_CFG.to_dict()) == TINY_CFG
    assert DaggerConfig().episodes_in(0) == 50 and TINY_CFG.episodes_in(1) == 2
    with pytest.raises(ConfigError) as err:
        DaggerConfig.from_dict({"round": 3})
    assert_house_message(str(err.value), "round")


def test_a_scenario_pattern_draws_each_episode_from_the_matching_variants(
    tmp_path, reward_file, monkeypatch
):
    """One student for many worlds: ``--scenario 'tiny-static-*'`` runs every episode in one
    of the matching variants (drawn by the episode's seed), records all their definitions,
    and refuses a resume that sees another set."""

    def variant(width: float, name: str) -> Any:
        return lambda: dataclasses.replace(
            static_study_scenario(
                StaticStudyLayout(width=width), sim=SimConfig(time_limit=TIME_LIMIT)
            ),
            name=name,
        )

    for name, width in (("tiny-static-a", 4.0), ("tiny-static-b", 5.0)):
        monkeypatch.setitem(scenarios._REGISTRY, name, variant(width, name))
    assert scenario_set("tiny-static-*") == ["tiny-static-a", "tiny-static-b"]
    assert scenario_set(TINY) == [TINY]
    cfg = TINY_CFG.replace(scenario="tiny-static-*", episodes_per_round=3)
    out = tmp_path / "general"
    run_dagger(cfg, out, workers=1, reward=reward_file, progress=False)
    pinned = json.loads((out / "scenario.json").read_text())["scenarios"]
    assert sorted(pinned) == ["tiny-static-a", "tiny-static-b"]
    used = [str(_load(p)["scenario"]) for p in sorted((out / "rounds").glob("*/ep-*.npz"))]
    assert len(used) == 2 + 2 * 3 and set(used) == {"tiny-static-a", "tiny-static-b"}
    for p in sorted((out / "rounds").glob("*/ep-*.npz")):  # the drawn world is the seed's
        ep = _load(p)
        names = ["tiny-static-a", "tiny-static-b"]
        assert str(ep["scenario"]) == names[int(ep["env_seed"]) % 2]
    monkeypatch.setitem(scenarios._REGISTRY, "tiny-static-c", variant(4.5, "tiny-static-c"))
    with pytest.raises(ConfigError) as err:
        run_dagger(cfg, out, workers=1, reward=reward_file, progress=False)
    assert_house_message(str(err.value), "scenarios", "3 matching now")
    with pytest.raises(ConfigError) as err:
        scenario_set("nothing-*")
    assert_house_message(str(err.value), "pattern", "--scenarios FILE")


def test_unknown_scenario_fails_before_writing_anything(tmp_path):
    with pytest.raises(ScenarioError) as err:
        run_dagger(DaggerConfig(scenario="nope"), tmp_path / "x", workers=1, progress=False)
    assert_house_message(str(err.value), "nope")
    assert not (tmp_path / "x").exists()


# ------------------------------------------------------------------------------ selection
@pytest.fixture
def driven(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, int]]:
    """(round folder, env seed) of every selection episode driven from now on (in-process,
    workers=1)."""
    seen: list[tuple[str, int]] = []
    real = dagger._drive_task

    def spy(args: tuple[int, str, str, int]) -> tuple[int, str, float]:
        seen.append((Path(args[2]).parent.name, args[3]))
        return real(args)

    monkeypatch.setattr(dagger, "_drive_task", spy)
    return seen


def _selection(out: Path) -> list[dict[str, str]]:
    with open(out / "selection.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def test_selection_drives_every_rounds_student_on_validation_episodes_and_ships_the_best(
    run_mdn, tmp_path, driven, capsys
):
    """With ``select_episodes`` a finished run (its rounds reused, nothing collected again)
    drives each round's student alone on the same validation episodes; the rows equal those
    episodes run one by one, and the run's student is the best round's (ties: the later)."""
    res, _ = run_mdn
    out = tmp_path / "select"
    shutil.copytree(res.out, out)
    cfg = TINY_CFG.replace(select_episodes=3)
    sel = run_dagger(cfg, out, workers=1, progress=False)
    assert len(driven) == 3 * 3
    seeds = [s for _, s in driven[:3]]
    assert [s for _, s in driven] == seeds * 3  # the same episodes for every round
    assert all(s >= 2**32 and s < 2**33 for s in seeds)  # validation seeds …
    harness = {episode_seed(TINY, 0, k, "validation") for k in range(100)}
    assert not harness & set(seeds)  # … of their own purpose
    rows = _selection(out)
    assert [int(r["round"]) for r in rows] == [0, 1, 2] and sel.chosen in (0, 1, 2)
    for r in rows:  # brute force: the round's student on each episode, one by one
        ckpt = out / "rounds" / f"round-{int(r['round']):02d}" / "student.safetensors"
        events = [dagger._drive_task((k, TINY, str(ckpt), s))[1] for k, s in enumerate(seeds)]
        assert float(r["success_rate"]) == events.count("success") / 3
        assert float(r["timeout_rate"]) == events.count("timeout") / 3
        assert r["student_sha256"] == dagger.file_sha256(ckpt)
    best = max(range(3), key=lambda i: (float(rows[i]["success_rate"]), i))
    assert sel.chosen == best and [int(r["chosen"]) for r in rows] == [
        int(i == best) for i in range(3)
    ]
    chosen = out / "rounds" / f"round-{best:02d}" / "student.safetensors"
    assert sel.student.read_bytes() == chosen.read_bytes()
    assert json.loads((out / "config.json").read_text())["select_episodes"] == 3

    # Resumed: rows kept while their student is the same file; a changed student is driven again.
    driven.clear()
    assert main(_distill_argv(out, "--select-episodes", "3")) == 0
    assert driven == []
    line = capsys.readouterr().out.strip()
    assert f"round {best} chosen: SR " in line and "on 3 validation episodes" in line
    shutil.copy(
        out / "rounds/round-02/student.safetensors", out / "rounds/round-01/student.safetensors"
    )
    run_dagger(cfg, out, workers=1, progress=False)
    assert [d for d, _ in driven] == ["round-01"] * 3
    # Back to the paper's choice: the last round's student.
    last = run_dagger(TINY_CFG, out, workers=1, progress=False)
    assert last.chosen == 2 and last.selection == []
    assert last.student.read_bytes() == (out / "rounds/round-02/student.safetensors").read_bytes()


def test_selection_prefers_the_most_successful_round_and_the_later_on_a_tie(
    run_mdn, tmp_path, monkeypatch
):
    res, _ = run_mdn
    out = tmp_path / "rule"
    shutil.copytree(res.out, out)
    outcome = {"round-00": ["success"] * 2, "round-01": ["success", "collision"],
               "round-02": ["success", "timeout"]}  # fmt: skip

    def fake(args: tuple[int, str, str, int]) -> tuple[int, str, float]:
        return args[0], outcome[Path(args[2]).parent.name][args[0]], 0.5

    monkeypatch.setattr(dagger, "_drive_task", fake)
    cfg = TINY_CFG.replace(select_episodes=2)
    assert run_dagger(cfg, out, workers=1, progress=False).chosen == 0
    outcome["round-02"] = ["success"] * 2
    (out / "selection.csv").unlink()
    sel = run_dagger(cfg, out, workers=1, progress=False)
    assert sel.chosen == 2 and sel.selection[2]["collision_rate"] == 0.0
    assert [r["success_rate"] for r in sel.selection] == [1.0, 0.5, 1.0]


# ------------------------------------------------------------------------------ score targets
def test_score_weights_are_a_softmax_that_ignores_what_could_not_be_chosen():
    scores = np.array([[2.0, 1.9, 1.5, -np.inf], [0.0, -np.inf, -np.inf, -np.inf]])
    w = score_weights(scores, 0.1)
    e = np.exp(np.array([0.0, -1.0, -5.0]))
    np.testing.assert_allclose(w[0, :3], e / e.sum(), rtol=1e-6)
    assert w[0, 3] == 0.0 and w[1].tolist() == [1.0, 0.0, 0.0, 0.0]
    np.testing.assert_array_equal(score_weights(scores, 1e-4)[0], [1.0, 0.0, 0.0, 0.0])


@pytest.mark.parametrize("kind", ["mdn", "mlp"])
def test_one_target_of_weight_one_is_the_label_loss(kind):
    rng = np.random.default_rng(2)
    model = MDN(seed=1) if kind == "mdn" else MLPStudent(seed=1)
    x = torch.as_tensor(rng.uniform(0, 3, (32, 29)).astype(np.float32))
    y = torch.as_tensor(rng.uniform(-0.5, 0.5, (32, 2)).astype(np.float32))
    with torch.no_grad():
        one = model.target_loss(x, y[:, None, :], torch.ones(32, 1))
        assert float(one) == pytest.approx(float(model.loss(x, y)), rel=1e-6)
        # two targets: the weighted sum of the two losses, frame by frame
        y2 = torch.flip(y, dims=[0])
        w = torch.as_tensor(rng.uniform(0, 1, (32, 1)).astype(np.float32))
        both = model.target_loss(x, torch.stack([y, y2], 1), torch.cat([w, 1 - w], 1))
        if kind == "mdn":
            want = -(w[:, 0] * model.log_prob(x, y) + (1 - w[:, 0]) * model.log_prob(x, y2))
        else:
            e1 = (((model(x) - y) / model.act_std) ** 2).mean(-1)
            e2 = (((model(x) - y2) / model.act_std) ** 2).mean(-1)
            want = w[:, 0] * e1 + (1 - w[:, 0]) * e2
        assert float(both) == pytest.approx(float(want.mean()), rel=1e-5)


def test_scores_target_trains_on_the_teachers_candidates(tmp_path):
    """A run with ``target="scores"`` aggregates each frame's best candidates with weights
    that sum to 1, and its loss is the weighted one."""
    cfg = TINY_CFG.replace(target="scores", score_temperature=0.05)
    real = reward_default.default_reward
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(reward_default, "default_reward", lambda scenario: real("static"))
        res = run_dagger(cfg, tmp_path / "scores", workers=1, progress=False)
    eps = list(_episodes(res.out).values())
    method = dagger._Students(cfg, {})
    x, y, _, targets = method.aggregate(eps)
    assert targets is not None
    commands, weights = targets
    assert commands.shape == (len(x), TARGET_CANDIDATES, 2)
    np.testing.assert_allclose(weights.sum(axis=1), 1.0, rtol=1e-5)
    np.testing.assert_allclose(commands[:, 0], y, atol=1e-6)
    meta = read_checkpoint_meta(res.student)
    assert meta["info"]["dagger"]["target"] == "scores"


def test_the_labelling_teachers_patience_is_the_runs_and_old_runs_had_none(
    monkeypatch, reward_file, tmp_path
):
    from pioneer.control.teacher import Patience
    from pioneer.learn import collect

    made: list[Patience] = []
    real = collect._teacher

    def spy(*args: Any) -> Any:
        teacher = real(*args)
        made.append(teacher.config.patience)
        return teacher

    monkeypatch.setattr(collect, "_teacher", spy)
    cfg = TINY_CFG.replace(rounds=0, patience=Patience(after=1.5, progress=0.1))
    run_dagger(cfg, tmp_path / "run", workers=1, reward=reward_file, progress=False)
    assert made and set(made) == {Patience(after=1.5, progress=0.1)}
    old = cfg.to_dict()
    del old["patience"]  # a run folder written before the teacher had patience
    assert DaggerConfig.from_dict(old).patience == Patience(after=0.0)
    assert DaggerConfig().patience == Patience()
