"""Rehearsal in fine-tuning: the starting student's own states on layouts a stage does not
practise, and the pull towards it there (pioneer.learn.rehearsal)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors.torch import load_file

from finetune_testutils import TINY_FINETUNE, tiny_student
from pioneer.learn.finetune import finetune_student
from pioneer.learn.finetune_trainer import MAX_HUMANS, FinetuneTrainer
from pioneer.learn.models import load_student
from pioneer.learn.rehearsal import Rehearsal
from pioneer_testutils import file_tree, one_error_line, run_cli

TINY = dataclasses.replace(TINY_FINETUNE, rehearse_states=40)  # 10 steps of the 4 copies


def _student(tmp_path: Path) -> Path:
    return tiny_student(tmp_path, seed=5, normalizer_seed=1)


def test_the_states_are_the_starting_students_own_and_drawn_again_identically(
    tmp_path: Path,
) -> None:
    start = load_student(_student(tmp_path))
    a = Rehearsal.collect(start, [["hl-rr"]], TINY, MAX_HUMANS)
    b = Rehearsal.collect(start, [["hl-rr"]], TINY, MAX_HUMANS)
    assert len(a) == 40 and a.inputs.shape == (40, start.config.input_dim)
    assert torch.equal(a.inputs, b.inputs) and torch.equal(a.commands, b.commands)
    with torch.no_grad():
        assert torch.equal(a.commands, start.deterministic_action(a.inputs, "mode"))
    other = Rehearsal.collect(start, [["hr-rl"]], TINY, MAX_HUMANS)  # the layouts named
    assert not torch.equal(a.inputs, other.inputs)
    seeded = Rehearsal.collect(start, [["hl-rr"]], dataclasses.replace(TINY, seed=1), MAX_HUMANS)
    assert not torch.equal(a.inputs, seeded.inputs)


def test_the_pull_is_the_mean_kl_on_the_rows_drawn(tmp_path: Path) -> None:
    start = load_student(_student(tmp_path))
    r = Rehearsal.collect(start, [["hl-rr"]], TINY, MAX_HUMANS)
    scale = start.act_std * TINY.init_std
    with torch.no_grad():
        assert float(r.loss(start, 16, scale, torch.Generator().manual_seed(0))) == 0.0
        moved = load_student(_student(tmp_path))
        for p in moved.parameters():
            p.add_(0.05)
        got = float(r.loss(moved, 16, scale, torch.Generator().manual_seed(0)))
        j = torch.randint(len(r), (16,), generator=torch.Generator().manual_seed(0))
        mu = moved.deterministic_action(r.inputs[j], "mode").numpy().astype(np.float64)
        z = (mu - r.commands[j].numpy()) / scale.numpy()
        assert got == pytest.approx(float(np.mean(0.5 * (z**2).sum(-1))), rel=1e-5)
    with pytest.raises(ValueError, match="rows"):
        Rehearsal(torch.zeros(0, 3), torch.zeros(0, 2))


def _drift(tr: FinetuneTrainer, probe: Rehearsal) -> float:
    with torch.no_grad():
        mu = tr.actor.deterministic_action(probe.inputs, "mode")
        return float(((mu - probe.commands) / tr.actor.act_std).pow(2).sum(-1).mean())


def test_the_pull_keeps_the_rehearsed_layouts_where_the_start_drove_them(tmp_path: Path) -> None:
    src = _student(tmp_path)
    probe = Rehearsal.collect(load_student(src), [["hl-rr"]], TINY, MAX_HUMANS)
    drift = {}
    for coef in (0.0, 100.0):
        cfg = dataclasses.replace(TINY, lr=1e-3, kl_coef=0.0, rehearse_coef=coef)
        tr = FinetuneTrainer(load_student(src), [["hr-rl"]], cfg, rehearse=[["hl-rr"]])
        for _ in range(cfg.updates):
            tr.learn(tr.rollout())
            tr.end_update()
        drift[coef] = _drift(tr, probe)
    assert drift[100.0] < 0.25 * drift[0.0]


def test_a_resumed_rehearsing_run_equals_an_uninterrupted_one(tmp_path: Path) -> None:
    src = _student(tmp_path)
    whole = finetune_student(src, ["hr-rl"], tmp_path / "a", TINY, progress=False,
                             rehearse=["hl-rr"])  # fmt: skip
    half = dataclasses.replace(TINY, total_steps=TINY.total_steps // 2)
    finetune_student(src, ["hr-rl"], tmp_path / "b", half, progress=False, rehearse=["hl-rr"])
    resumed = finetune_student(src, ["hr-rl"], tmp_path / "b", TINY, progress=False,
                               rehearse=["hl-rr"])  # fmt: skip
    assert resumed["resumed_from_update"] == 2 and whole["updates"] == 4
    assert whole["settings"]["rehearse"] == [["hl-rr"]]
    for name in ("student.safetensors", "checkpoint.safetensors"):
        a, b = load_file(tmp_path / "a" / name), load_file(tmp_path / "b" / name)
        keys = [k for k in a if k != "curve"]  # the curve's wall times differ
        assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in keys)
    longer = dataclasses.replace(TINY, total_steps=2 * TINY.total_steps)
    for other in ((), ["h?-r?"]):  # without the rehearsal, or of other layouts: another run
        with pytest.raises(Exception, match="rehearse"):
            finetune_student(src, ["hr-rl"], tmp_path / "b", longer, progress=False,
                             rehearse=other)  # fmt: skip


def test_the_command_rehearses_and_refuses_an_unknown_layout_in_one_line(tmp_path: Path) -> None:
    src = _student(tmp_path)
    before = file_tree(tmp_path)
    unknown = run_cli("finetune", "--out", str(tmp_path / "run"), "--student", str(src),
                      "--scenario", "hr-rl", "--rehearse", "no-such-world")  # fmt: skip
    one_error_line(unknown.stderr, unknown.returncode, "no-such-world")
    assert file_tree(tmp_path) == before
    out = tmp_path / "ok"
    proc = run_cli("finetune", "--out", str(out), "--student", str(src), "--scenario", "hr-rl",
                   "--rehearse", "hl-rr", "--rehearse-coef", "2", "--rehearse-states", "64",
                   "--steps", "64", "--groups", "1", "--group-size", "2", "--rollout", "16",
                   "--critic-warmup", "0")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    settings = json.loads((out / "train.json").read_text())["settings"]
    assert settings["rehearse"] == [["hl-rr"]]
    assert (settings["finetune"]["rehearse_coef"], settings["finetune"]["rehearse_states"]) == (
        2.0,
        64,
    )
