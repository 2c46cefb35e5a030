"""The students' reinforcement-learning fine-tuning: its environments, the critic's privileged
view, the reward it is paid, the schedule of the pull, resuming and the command line."""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from safetensors import safe_open
from safetensors.torch import load_file, save_file

from finetune_testutils import TINY_FINETUNE, tiny_student
from pioneer.control.teacher import make_teacher
from pioneer.learn import finetune_trainer as trainer_module
from pioneer.learn.finetune import FINETUNE_REWARD, finetune_student
from pioneer.learn.finetune_trainer import CURVE_COLUMNS, FinetuneTrainer
from pioneer.learn.layout_env import HUMAN_FEATURES, ROBOT_FEATURES, LayoutEnvs, privileged
from pioneer.learn.models import (
    load_student,
    read_checkpoint_meta,
)
from pioneer.nn.critic import lower_tail_mean
from pioneer.nn.ppo import lagrangian_advantage
from pioneer.reward.crowdnav import crowdnav_reward_terms
from pioneer.sim.events import Event
from pioneer.sim.scenarios import get_scenario, sample_state
from pioneer.sim.world import State
from pioneer_testutils import file_tree, one_error_line, run_cli

TINY = dataclasses.replace(TINY_FINETUNE, kl_fade=2 * 2 * 2 * 8)  # the pull: 2 updates


def _student(tmp_path: Path, symmetric: bool = False) -> Path:
    return tiny_student(tmp_path, seed=3, normalizer_seed=0, symmetric=symmetric)


def test_privileged_matches_a_brute_force_frame_change() -> None:
    sc = get_scenario("hr-rl")
    st = State.concat([sample_state(sc, np.random.default_rng(s)) for s in range(3)])
    st.t[:] = [0.0, 3.0, 100.0]
    out = privileged(st, 30.0, 6)
    for b in range(3):
        x, y, th = st.robot[b]
        rot = np.array([[math.cos(th), math.sin(th)], [-math.sin(th), math.cos(th)]])
        assert out[b, 0] == pytest.approx(st.t[b] / 30.0)
        np.testing.assert_allclose(out[b, 1:3], rot @ (st.goal[b] - [x, y]), atol=1e-5)
        for i in range(st.n_humans):
            row = out[b, ROBOT_FEATURES + HUMAN_FEATURES * i :][:HUMAN_FEATURES]
            present = bool(st.humans_present[b, i])
            np.testing.assert_allclose(
                row[:2], rot @ (st.h_pos[b, i] - [x, y]) if present else 0.0, atol=1e-5
            )
            np.testing.assert_allclose(row[2:4], rot @ st.h_vel[b, i] if present else 0, atol=1e-5)
            assert row[5] == present
            assert row[6] == (st.t[b] < st.h_delay[b, i])
    assert not out[:, ROBOT_FEATURES + HUMAN_FEATURES * st.n_humans :].any()  # unused slots


def test_the_reward_pays_arriving_and_charges_collisions_without_intrusion() -> None:
    assert FINETUNE_REWARD.intrusion == 0.0
    sc = get_scenario("hr-rl")
    world = sc.world()
    prev = sample_state(sc, np.random.default_rng(0))
    new = prev.copy()
    new.robot[0, :2] += (
        0.1 * (prev.goal[0] - prev.robot[0, :2]) / np.linalg.norm(prev.goal[0] - prev.robot[0, :2])
    )
    new.command[0] = (0.5, 0.0)
    new.gap[0] = np.inf
    new.h_pos[0] += 50.0  # every person far from the robot
    for event, want in ((Event.NONE, 3.0 * 0.1), (Event.SUCCESS, 10.0), (Event.COLLISION, -20.0)):
        terms, total = crowdnav_reward_terms(
            world, prev, new, np.array([event], dtype=np.int8), FINETUNE_REWARD
        )
        assert terms["intrusion"][0] == 0.0
        assert total[0] == pytest.approx(want)


def test_inputs_start_each_episode_afresh_and_carry_the_command_run(tmp_path: Path) -> None:
    model = load_student(_student(tmp_path))
    rng = np.random.default_rng(0)
    envs = LayoutEnvs([["hr-rl"]], 1, 3, model.config.inputs, FINETUNE_REWARD, rng, 0, 6)
    x = envs.student_inputs()
    obs_dim = envs.obs.shape[1]
    np.testing.assert_array_equal(x[:, :obs_dim], x[:, obs_dim : 2 * obs_dim])
    assert not x[:, 2 * obs_dim :].any()
    before = envs.obs.copy()
    envs.step(np.tile([0.3, 0.2], (3, 1)))
    x = envs.student_inputs()
    np.testing.assert_array_equal(x[:, obs_dim : 2 * obs_dim], before)
    np.testing.assert_allclose(x[:, 2 * obs_dim :], np.tile([0.3, 0.2], (3, 1)), atol=1e-6)


def test_the_pull_fades_linearly_to_zero(tmp_path: Path) -> None:
    tr = FinetuneTrainer(load_student(_student(tmp_path)), [["hr-rl"]], dataclasses.replace(TINY))
    betas = []
    for u in range(TINY.updates + 1):
        tr.env_steps = u * TINY.steps_per_update
        betas.append(tr.kl_coef())
    assert betas == pytest.approx([1.0, 0.5, 0.0, 0.0, 0.0])


def test_a_symmetric_student_stays_mirror_equivariant(tmp_path: Path) -> None:
    src = _student(tmp_path, symmetric=True)
    finetune_student(src, ["hr-rl", "hl-rr"], tmp_path / "run", TINY, progress=False)
    model = load_student(tmp_path / "run" / "student.safetensors")
    before = load_student(src).state_dict()["mu_head.weight"]
    assert not torch.equal(model.state_dict()["mu_head.weight"], before)
    rng = np.random.default_rng(1)
    envs = LayoutEnvs([["hr-rl"]], 1, 8, model.config.inputs, FINETUNE_REWARD, rng, 0, 6)
    rows = []
    for _ in range(4):  # inputs as the robot reads them
        envs.step(np.tile([0.4, 0.3], (8, 1)))
        rows.append(envs.student_inputs())
    x = torch.from_numpy(np.concatenate(rows))
    with torch.no_grad():
        u = model.deterministic_action(x)
        um = model.deterministic_action(model.mirror(x))
    torch.testing.assert_close(um, u * torch.tensor([1.0, -1.0]), atol=1e-5, rtol=1e-5)


def test_the_lagrangian_advantage_weighs_the_cost_by_lambda() -> None:
    adv, cost = np.array([1.0, -2.0, 0.5]), np.array([0.0, 1.0, 2.0])
    np.testing.assert_array_equal(lagrangian_advantage(adv, cost, 0.0), adv)
    np.testing.assert_allclose(lagrangian_advantage(adv, cost, 3.0), [0.25, -1.25, -1.375])


def test_risk_sensitive_advantages_bootstrap_from_the_cvar_of_the_quantiles(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    cfg = dataclasses.replace(TINY, risk_alpha=0.25, quantiles=8)
    tr = FinetuneTrainer(load_student(_student(tmp_path)), [["hr-rl"]], cfg)
    assert tr.risky and tr.critic.n_out == 8
    calls: list[tuple[np.ndarray, np.ndarray]] = []
    gae = trainer_module.compute_gae

    def spy(rewards: Any, values: Any, dones: Any, last: Any, *gl: float) -> Any:
        calls.append((values.copy(), last.copy()))
        return gae(rewards, values, dones, last, *gl)

    monkeypatch.setattr(trainer_module, "compute_gae", spy)
    batch = tr.rollout()
    seen = tr._critic_in(batch["x"], batch["priv"])
    last = tr._critic_in(
        torch.from_numpy(tr.envs.student_inputs()), torch.from_numpy(tr.envs.privileged())
    )
    with torch.no_grad():
        q, q_last = tr.critic(seen), tr.critic(last)
    shape = (cfg.rollout, cfg.envs)
    (v_mean, l_mean), (v_risk, l_risk) = calls  # the targets' GAE, then the advantages'
    # float32 forwards over other batch shapes sum in another order (AVX-512 vs AVX2 kernels):
    # equal to a few ulps of the values (|v| ≲ 0.1), so an absolute tolerance of 1e-6
    tol = {"rtol": 1e-5, "atol": 1e-6}
    np.testing.assert_allclose(v_mean, q.mean(-1).reshape(shape).numpy(), **tol)
    np.testing.assert_allclose(l_mean, q_last.mean(-1).numpy(), **tol)
    want = lower_tail_mean(q, 0.25).reshape(shape).numpy()
    np.testing.assert_allclose(v_risk, want, **tol)
    np.testing.assert_allclose(l_risk, lower_tail_mean(q_last, 0.25).numpy(), **tol)
    assert (v_risk <= v_mean + 1e-6).all()  # the worst quarter lies below the mean
    stats = tr.learn(batch)  # the critic regresses with the quantile loss
    assert math.isfinite(stats["value_loss"])


def test_the_multiplier_rises_while_collisions_exceed_the_limit(tmp_path: Path) -> None:
    start = load_student(_student(tmp_path))
    cfg = dataclasses.replace(TINY, collision_limit=0.1, lagrange_lr=0.5)
    tr = FinetuneTrainer(start, [["hr-rl"]], cfg)
    assert tr.constrained and tr.cost_critic is not None and tr.lagrange == 0.0
    column = CURVE_COLUMNS.index("lagrange")
    tr.win_event = [int(Event.COLLISION)] * 10 + [int(Event.SUCCESS)] * 10  # 50 % > 10 %
    assert tr.end_update()[column] == pytest.approx(0.5 * (0.5 - 0.1))
    tr.win_event = [int(Event.SUCCESS)] * 20  # 0 % < 10 %: λ falls, never below 0
    lams = [tr.end_update()[column] for _ in range(6)]
    assert lams == pytest.approx([0.15, 0.1, 0.05, 0.0, 0.0, 0.0])
    plain = FinetuneTrainer(start, [["hr-rl"]], TINY)  # the default: unconstrained
    plain.win_event = [int(Event.COLLISION)] * 20
    assert not plain.constrained and plain.cost_critic is None
    assert plain.end_update()[column] == 0.0


@pytest.mark.parametrize(
    "change",
    [
        {"replay": 0.5},  # "h?-r?": both paper worlds, prioritised
        {"collision_limit": 0.0},  # PPO-Lagrangian: its cost critic and λ are saved too
        {"replay": 0.5, "replay_mode": "plr"},  # level replay: the layouts seen are saved
        {"teacher_coef": 1.0, "teacher_alpha": 2.0},  # teacher guidance
        {"risk_alpha": 0.25, "quantiles": 8},  # risk-sensitive: a distributional critic
        # a curriculum of layouts practised to mastery: its active set and history are saved
        {"replay": 0.5, "replay_mode": "mastery", "mastery_layouts": 1, "mastery_window": 2},
        # the same following regret (the teacher's success per layout)
        {
            "replay": 0.5,
            "replay_mode": "mastery",
            "mastery_layouts": 1,
            "mastery_window": 2,
            "teacher": {"hr-rl": 1.0, "hl-rr": 0.95},
        },
        # drawn by situation (one here: both worlds hold two boarders and one passenger)
        {"stratify": True, "replay": 0.5, "replay_mode": "mastery", "mastery_layouts": 1},
        {"average_horizon": 3 * 2 * 2 * 8},  # the actor's weights averaged: the average saved
    ],
    ids=[
        "prioritised",
        "constrained",
        "level-replay",
        "teacher-guided",
        "risk-sensitive",
        "mastery",
        "regret",
        "stratified",
        "averaged",
    ],
)
def test_a_resumed_run_equals_an_uninterrupted_one(tmp_path: Path, change: dict[str, Any]) -> None:
    src = _student(tmp_path)
    change = dict(change)
    table = change.pop("teacher", None)
    cfg = dataclasses.replace(TINY, **change)
    run = functools.partial(finetune_student, src, ["h?-r?"], progress=False, mastery_teacher=table)
    whole = run(tmp_path / "a", cfg)
    half = dataclasses.replace(cfg, total_steps=cfg.total_steps // 2)
    run(tmp_path / "b", half)
    if table is not None:  # another teacher table is another run
        with pytest.raises(Exception, match="settings"):
            finetune_student(src, ["h?-r?"], tmp_path / "b", cfg, progress=False,
                             mastery_teacher={**table, "hl-rr": 1.0})  # fmt: skip
    resumed = run(tmp_path / "b", cfg)
    assert resumed["resumed_from_update"] == 2 and resumed["updates"] == whole["updates"] == 4
    assert resumed.get("curriculum") == whole.get("curriculum")  # "mastery": its set, saved
    assert ("curriculum" in whole) == (change.get("replay_mode") == "mastery")
    a = load_file(tmp_path / "a" / "student.safetensors")
    b = load_file(tmp_path / "b" / "student.safetensors")
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    a = load_file(tmp_path / "a" / "checkpoint.safetensors")  # the whole training state
    b = load_file(tmp_path / "b" / "checkpoint.safetensors")
    state = [k for k in a if k != "curve"]  # the curve (its wall times differ): below
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in state)
    assert any(k.startswith("cost_critic/") for k in a) == ("collision_limit" in change)
    curves = [(tmp_path / d / "curve.csv").read_text().splitlines() for d in "ab"]
    assert [r.rsplit(",", 1)[0] for r in curves[0]] == [r.rsplit(",", 1)[0] for r in curves[1]]
    with pytest.raises(Exception, match="settings"):
        run(tmp_path / "b", dataclasses.replace(cfg, lr=1e-3))


def test_a_checkpoint_written_before_newer_settings_resumes_with_them_at_their_defaults(
    tmp_path: Path,
) -> None:
    src = _student(tmp_path)
    half = dataclasses.replace(TINY, total_steps=TINY.total_steps // 2)
    finetune_student(src, ["hr-rl"], tmp_path / "b", half, progress=False)
    ckpt = tmp_path / "b" / "checkpoint.safetensors"
    with safe_open(str(ckpt), "pt") as f:
        meta, tensors = f.metadata(), {k: f.get_tensor(k) for k in f.keys()}  # noqa: SIM118
    settings = json.loads(meta["settings"])
    for k in ("risk_alpha", "quantiles", "teacher_coef"):  # as an older version wrote it
        del settings["finetune"][k]
    save_file(tensors, str(ckpt), {**meta, "settings": json.dumps(settings)})
    resumed = finetune_student(src, ["hr-rl"], tmp_path / "b", TINY, progress=False)
    assert resumed["resumed_from_update"] == 2
    with pytest.raises(Exception, match="settings"):  # a new setting away from its default
        risky = dataclasses.replace(TINY, total_steps=8 * TINY.steps_per_update, risk_alpha=0.5)
        finetune_student(src, ["hr-rl"], tmp_path / "b", risky, progress=False)


def test_the_teacher_labels_are_its_decisions_in_those_copies(tmp_path: Path) -> None:
    model = load_student(_student(tmp_path))
    rng = np.random.default_rng(2)
    envs = LayoutEnvs([["hl-rr"]], 2, 3, model.config.inputs, FINETUNE_REWARD, rng, 0, 6)
    for _ in range(5):  # people moving, a command run
        envs.step(np.tile([0.5, -0.2], (6, 1)))
    copies = np.array([0, 4])
    labels = envs.teacher_labels(copies)
    teacher = make_teacher("hl-rr")  # brute force: a fresh teacher per copy
    for k, i in enumerate(copies):
        grp = envs.groups[i // 3]
        state = grp.state.take(int(i) % 3)
        np.testing.assert_array_equal(state.command[0], [0.5, -0.2])
        want = make_teacher("hl-rr").decide(grp.world, state, prev=state.command[0]).command
        np.testing.assert_array_equal(labels[k], want)
        # the label is DAgger's: half the teacher's best, half the command run
        best = teacher.decide(grp.world, state, prev=np.zeros(2)).best
        np.testing.assert_allclose(labels[k], 0.5 * best + 0.5 * np.array([0.5, -0.2]))


def test_the_guidance_weighs_each_label_by_the_dagger_students_distance(tmp_path: Path) -> None:
    start = load_student(_student(tmp_path))
    cfg = dataclasses.replace(TINY, teacher_coef=1.0, teacher_alpha=2.0, teacher_groups=5)
    tr = FinetuneTrainer(start, [["hr-rl"]], cfg)
    assert tr.guided and list(tr._taught()) == [0, 2]  # one copy per group, two groups
    assert not FinetuneTrainer(start, [["hr-rl"]], TINY).guided  # the default: off
    s_u = start.act_std
    ref = torch.zeros(2 * 4, 2)  # T = 2 steps, B = 4 copies
    labels = np.zeros((2, 4, 2))
    labels[0, 0] = (0.5 * s_u).numpy()  # d² = 0.25 + 0.25
    labels[1, 2] = (torch.tensor([1.0, 0.0]) * s_u).numpy()  # d² = 1
    g = tr._guidance(labels, tr._taught(), ref)
    assert g["taught"].tolist() == [True, False, True, False] * 2
    want = torch.ones(8)
    want[0], want[6] = math.exp(-2.0 * 0.5), math.exp(-2.0 * 1.0)
    torch.testing.assert_close(g["label_w"], want)
    # the loss: the weighted mean over the labelled rows of the pull's ½ ‖·/(s_u σ_0)‖²
    scale = s_u * cfg.init_std
    mean = torch.zeros(8, 2)
    mean[2] = 0.4 * scale  # a labelled row 0.4 σ_0 off its label (0) in each command
    got = FinetuneTrainer._imitation(mean, g, torch.arange(8), scale)
    errs = [0.5 * ((labels.reshape(8, 2)[i] / scale.numpy()) ** 2).sum() for i in (0, 4, 6)]
    errs.append(0.5 * 2 * 0.4**2)  # row 2
    weights = [float(want[0]), 1.0, float(want[6]), 1.0]
    expected = sum(w * e for w, e in zip(weights, errs, strict=True)) / 4
    assert float(got) == pytest.approx(expected, rel=1e-5)
    none = FinetuneTrainer._imitation(mean, g, torch.tensor([1, 3]), scale)
    assert float(none) == 0.0  # no labelled row in the minibatch


def test_the_command_refuses_bad_input_in_one_line_leaving_no_trace(tmp_path: Path) -> None:
    src = _student(tmp_path)
    (tmp_path / "student.safetensors").write_bytes(src.read_bytes())  # a run's own output
    (tmp_path / "student-last.safetensors").write_bytes(src.read_bytes())  # an averaged run's
    before = file_tree(tmp_path)
    missing = run_cli("finetune", "--out", str(tmp_path / "run"), "--student",
                      str(tmp_path / "none.safetensors"), "--scenario", "hr-rl")  # fmt: skip
    one_error_line(missing.stderr, missing.returncode, "none.safetensors")
    onto = run_cli("finetune", "--out", str(tmp_path), "--student", str(tmp_path /
                   "student.safetensors"), "--scenario", "hr-rl")  # fmt: skip
    one_error_line(onto.stderr, onto.returncode, "input")
    last = run_cli("finetune", "--out", str(tmp_path), "--student", str(tmp_path /
                   "student-last.safetensors"), "--scenario", "hr-rl")  # fmt: skip
    one_error_line(last.stderr, last.returncode, "input")
    unknown = run_cli("finetune", "--out", str(tmp_path / "run"), "--student", str(src),
                      "--scenario", "no-such-world")  # fmt: skip
    one_error_line(unknown.stderr, unknown.returncode, "no-such-world")
    assert file_tree(tmp_path) == before
    # teacher guidance in a layout whose teacher has no reward (a variant with no base)
    variants = tmp_path / "variants.json"
    variants.write_text(json.dumps({"format": "pioneer.scenarios/1",
                                    "scenarios": {"lobby-x": {"elevator": {}}}}))  # fmt: skip
    proc = run_cli("--scenarios", str(variants), "finetune", "--out", str(tmp_path / "g"),
                   "--student", str(src), "--scenario", "lobby-x",
                   "--teacher-coef", "1")  # fmt: skip
    one_error_line(proc.stderr, proc.returncode, "--teacher-coef")
    variants.unlink()
    # the teacher's table: without the curriculum, or from evaluation seeds
    folder = tmp_path / "teacher-eval"
    folder.mkdir()
    rec = {"scenario": "hr-rl", "policy": "teacher", "seed": 0, "trial": 0, "event": "success"}
    rec |= {"time_s": 9.0, "path_length_m": 3.0, "min_gap_m": 0.4, "format": 2}
    (folder / "episodes.jsonl").write_text(json.dumps(rec) + "\n")
    before = file_tree(tmp_path)
    for extra in (["--scenario", "hr-rl"], ["--scenario", "hr-rl", "--replay-mode", "mastery"]):
        proc = run_cli("finetune", "--out", str(tmp_path / "t"), "--student", str(src),
                       "--mastery-teacher", str(folder), *extra)  # fmt: skip
        one_error_line(proc.stderr, proc.returncode, "validation")  # evaluation seeds refused
    assert file_tree(tmp_path) == before
    (folder / "episodes.jsonl").write_text(json.dumps({**rec, "seed_set": "validation"}) + "\n")
    before = file_tree(tmp_path)
    proc = run_cli("finetune", "--out", str(tmp_path / "t"), "--student", str(src),
                   "--mastery-teacher", str(folder), "--scenario", "hr-rl")  # fmt: skip
    one_error_line(proc.stderr, proc.returncode, "--replay-mode mastery")
    proc = run_cli("finetune", "--out", str(tmp_path / "t"), "--student", str(src),
                   "--mastery-window", "20", "--scenario", "h?-r?")  # fmt: skip
    one_error_line(proc.stderr, proc.returncode, "--mastery-window")  # not silently ignored
    proc = run_cli("finetune", "--out", str(tmp_path / "t"), "--student", str(src),
                   "--mastery-teacher", str(folder), "--scenario", "h?-r?", "--replay", "0.5",
                   "--replay-mode", "mastery")  # fmt: skip
    one_error_line(proc.stderr, proc.returncode, "e.g. hl-rr")  # no teacher success there
    proc = run_cli("finetune", "--out", str(folder), "--student", str(src),
                   "--mastery-teacher", str(folder), "--scenario", "hr-rl")  # fmt: skip
    one_error_line(proc.stderr, proc.returncode, "input")  # the output onto an input
    assert file_tree(tmp_path) == before
    failed = {**rec, "seed_set": "validation", "event": "collision"}
    lines = [json.dumps({**failed, "scenario": n}) + "\n" for n in ("hr-rl", "hl-rr")]
    (folder / "episodes.jsonl").write_text("".join(lines))
    before = file_tree(tmp_path)
    proc = run_cli("finetune", "--out", str(tmp_path / "t"), "--student", str(src),
                   "--mastery-teacher", str(folder), "--scenario", "h?-r?", "--replay", "0.5",
                   "--replay-mode", "mastery")  # fmt: skip
    one_error_line(proc.stderr, proc.returncode, "a layout the teacher drives")  # none to practise
    assert file_tree(tmp_path) == before
    # a curriculum with nothing to practise: no share drawn from it, or single layouts only
    for extra in (["--scenario", "h?-r?"], ["--scenario", "hr-rl", "hl-rr", "--replay", "0.5"]):
        proc = run_cli("finetune", "--out", str(tmp_path / "m"), "--student", str(src),
                       "--replay-mode", "mastery", *extra)  # fmt: skip
        one_error_line(proc.stderr, proc.returncode, "--replay-mode mastery")
    assert file_tree(tmp_path) == before


def test_the_command_fine_tunes_and_writes_its_outputs(tmp_path: Path) -> None:
    src = _student(tmp_path)
    out = tmp_path / "run"
    args = ["--steps", "64", "--groups", "1", "--group-size", "2", "--rollout", "16"]
    args += ["--collision-limit", "0.05", "--replay", "0.5", "--replay-mode", "plr"]
    args += ["--teacher-coef", "0.5", "--teacher-alpha", "2", "--teacher-groups", "1"]
    proc = run_cli("finetune", "--out", str(out), "--student", str(src), "--scenario", "h?-r?",
                   "--critic-warmup", "0", *args)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout.splitlines()[0])["updates"] == 2
    settings = json.loads((out / "train.json").read_text())["settings"]["finetune"]
    assert (settings["collision_limit"], settings["replay_mode"]) == (0.05, "plr")
    assert (settings["teacher_coef"], settings["teacher_alpha"]) == (0.5, 2.0)
    for name in ("student.safetensors", "checkpoint.safetensors", "curve.csv", "train.json"):
        assert (out / name).is_file()
    assert load_student(out / "student.safetensors").config == load_student(src).config
    info = read_checkpoint_meta(out / "student.safetensors")["info"]
    assert info["dagger"] == {"seed": 7} and info["finetune"]["updates"] == 2  # both records
    # fine-tuned again: the first fine-tuning's record is kept beside the second's
    again = tmp_path / "again"
    proc = run_cli("finetune", "--out", str(again), "--student", str(out / "student.safetensors"),
                   "--scenario", "hr-rl", "--critic-warmup", "0", *args[:8])  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    info2 = read_checkpoint_meta(again / "student.safetensors")["info"]
    assert info2["dagger"] == {"seed": 7} and info2["finetune_earlier"] == [info["finetune"]]
    assert info2["finetune"]["settings"]["scenarios"] == [["hr-rl"]]  # one pool


def test_the_weights_average_follows_every_update_and_leaves_training_alone(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    src = _student(tmp_path)
    plain = finetune_student(src, ["h?-r?"], tmp_path / "plain", TINY, progress=False)
    horizon = 3 * TINY.steps_per_update  # each update moves the average a third of the way
    iterates: list[dict[str, torch.Tensor]] = []
    end_update = FinetuneTrainer.end_update

    def recording(tr: FinetuneTrainer) -> list[float]:
        iterates.append({k: v.detach().clone() for k, v in tr.actor.named_parameters()})
        return end_update(tr)

    monkeypatch.setattr(FinetuneTrainer, "end_update", recording)
    cfg = dataclasses.replace(TINY, average_horizon=horizon)
    averaged = finetune_student(src, ["h?-r?"], tmp_path / "avg", cfg, progress=False)
    assert averaged["updates"] == plain["updates"] == len(iterates) == 4
    last = load_file(tmp_path / "avg" / "student-last.safetensors")  # training is unchanged
    same = load_file(tmp_path / "plain" / "student.safetensors")
    assert last.keys() == same.keys() and all(torch.equal(last[k], same[k]) for k in last)
    # brute force: θ̄_0 the starting student's weights, θ̄_k = θ̄_{k−1} + (θ_k − θ̄_{k−1}) / 3
    mean = dict(load_student(src).named_parameters())
    for theta in iterates:
        mean = {k: mean[k] + (theta[k] - mean[k]) / 3 for k in mean}
    got = dict(load_student(tmp_path / "avg" / "student.safetensors").named_parameters())
    for k, v in mean.items():
        torch.testing.assert_close(got[k], v.detach(), rtol=1e-6, atol=1e-7)  # lerp's rounding
    assert any(not torch.equal(got[k], iterates[-1][k]) for k in mean)  # not the last iterate


def test_prioritised_layouts_are_drawn_by_their_failure_rate(tmp_path: Path) -> None:
    model = load_student(_student(tmp_path))
    pool = [["hr-rl", "hl-rr"]]

    def draws(replay: float, failure: dict[str, float]) -> float:
        rng = np.random.default_rng(0)
        envs = LayoutEnvs(pool, 1, 1, model.config.inputs, FINETUNE_REWARD, rng, 0, 6, replay)
        envs.failure = failure
        return float(np.mean([envs._draw(pool[0]) == 0 for _ in range(2000)]))

    assert draws(0.0, {"hr-rl": 1.0, "hl-rr": 0.0}) == pytest.approx(0.5, abs=0.05)
    # replay 0.5: ½ · ½ uniform + ½ · (1 / 1.001) by failure ≈ 0.75 for the failing layout
    assert draws(0.5, {"hr-rl": 1.0, "hl-rr": 0.0}) == pytest.approx(0.75, abs=0.05)
    assert draws(1.0, {}) == pytest.approx(0.5, abs=0.05)  # unseen layouts weigh alike


def test_level_replay_explores_unseen_layouts_and_replays_the_failing(tmp_path: Path) -> None:
    model = load_student(_student(tmp_path))
    pool = ["hr-rl", "hl-rr", "hr-rl-compact", "hl-rr-compact"]

    def shares(failure: dict[str, float]) -> list[float]:
        rng = np.random.default_rng(0)
        envs = LayoutEnvs([pool], 1, 1, model.config.inputs, FINETUNE_REWARD, rng, 0, 6, 0.5, "plr")
        envs.failure = failure
        picks = np.array([envs._draw(pool) for _ in range(4000)])
        return [float(np.mean(picks == i)) for i in range(len(pool))]

    assert shares({}) == pytest.approx([0.25] * 4, abs=0.03)  # nothing seen: uniformly
    # half the draws replay the seen layouts by failure (hr-rl: 3 of 4 parts), half explore the
    # two never seen
    seen = {"hr-rl": 0.75, "hl-rr": 0.25}
    assert shares(seen) == pytest.approx([0.375, 0.125, 0.25, 0.25], abs=0.03)
    # all seen: half replayed by failure, half uniformly over the pool
    every = {"hr-rl": 1.0, "hl-rr": 0.0, "hr-rl-compact": 0.0, "hl-rr-compact": 0.0}
    assert shares(every) == pytest.approx([0.5 + 0.125, 0.125, 0.125, 0.125], abs=0.03)
