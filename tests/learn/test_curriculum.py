"""The fine-tuning's curriculum of hard layouts practised to mastery: who joins, when a layout
leaves (against a brute-force oracle), its saved state, and the environments' draws."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pioneer.learn.curriculum import Curriculum
from pioneer.learn.finetune_config import FINETUNE_REWARD
from pioneer.learn.layout_env import LayoutEnvs
from pioneer.learn.models import StudentConfig, build_student

POOLS = [["a0", "a1", "a2", "a3"], ["solo"], ["b0", "b1"]]


def test_layouts_join_from_pools_of_several_by_their_failure_rate() -> None:
    picks = {"a0": 0, "a1": 0}
    for seed in range(400):
        cur = Curriculum([["a0", "a1"], ["solo"]], 1, 0.9, 5, 100)
        cur.fill(np.random.default_rng(seed), {"a0": 1.0, "a1": 0.25})
        assert len(cur.active) == 1 and cur.active[0] != "solo"  # a pool of one never joins
        picks[cur.active[0]] += 1
    # in proportion to the failure rates (+ 1e-3): a0 four times as often as a1
    assert picks["a0"] / 400 == pytest.approx(1.0 / 1.25, abs=0.06)
    cur = Curriculum(POOLS, 10, 0.9, 5, 100)
    cur.fill(np.random.default_rng(0), {})
    assert sorted(cur.active) == ["a0", "a1", "a2", "a3", "b0", "b1"]  # every candidate, once


def test_with_a_ceiling_only_layouts_the_teacher_masters_join_by_regret() -> None:
    # a0: teacher 100 %, student fails (regret 1); a1: teacher 95 %, student 90 % (regret
    # 0.05); a2: the teacher itself 50 % (never joins); "solo": a pool of one (never joins)
    ceiling = {"a0": 1.0, "a1": 0.95, "a2": 0.5}
    failure = {"a0": 1.0, "a1": 0.1, "a2": 1.0}
    picks = {"a0": 0, "a1": 0}
    for seed in range(400):
        cur = Curriculum([["a0", "a1", "a2"], ["solo"]], 1, 0.9, 5, 100, ceiling)
        cur.fill(np.random.default_rng(seed), failure)
        picks[cur.active[0]] += 1
    w = np.array([1.0, 0.05]) + 1e-3  # the regrets (+ 1e-3)
    assert picks["a0"] / 400 == pytest.approx(w[0] / w.sum(), abs=0.03)
    cur = Curriculum([["a0", "a1", "a2"], ["solo"]], 5, 0.9, 5, 100, ceiling)
    cur.fill(np.random.default_rng(0), failure)
    assert sorted(cur.active) == ["a0", "a1"]  # every layout the teacher masters, no other
    for _ in range(5):  # a0 mastered: its history names the teacher's success there
        cur.record("a0", True, 1, np.random.default_rng(0), failure)
    assert cur.history[0]["outcome"] == "mastered" and cur.history[0]["ceiling"] == 1.0
    with pytest.raises(ValueError, match=r"no ceiling for 1 layouts, e\.g\. a2"):
        Curriculum([["a0", "a1", "a2"]], 1, 0.9, 5, 100, {"a0": 1.0, "a1": 1.0})


def _oracle(outcomes: list[bool], threshold: float, window: int, limit: int) -> tuple[int, str]:
    """The episode (1-based) at which a layout that joined with no history leaves, and how."""
    for k in range(1, len(outcomes) + 1):
        last = outcomes[max(0, k - window) : k]
        if len(last) == window and sum(last) / window >= threshold:
            return k, "mastered"
        if k >= limit:
            return k, "dropped"
    return 0, ""


@settings(max_examples=60, deadline=None)
@given(
    outcomes=st.lists(st.booleans(), min_size=1, max_size=40),
    window=st.integers(1, 8),
    threshold=st.sampled_from([0.5, 0.75, 0.9, 1.0]),
    limit=st.integers(1, 50),
)
def test_a_layout_leaves_when_its_recent_episodes_master_it_or_its_limit_is_spent(
    outcomes: list[bool], window: int, threshold: float, limit: int
) -> None:
    cur = Curriculum([["x", "y"]], 1, threshold, window, limit)
    rng = np.random.default_rng(0)
    cur.fill(rng, {"x": 1.0, "y": 0.0})
    first = cur.active[0]
    left_at, how = 0, ""
    for k, ok in enumerate(outcomes, 1):
        cur.record(first, ok, k, rng, {})
        if first not in cur.active:
            left_at, how = k, cur.history[0]["outcome"]
            break
    assert (left_at, how) == _oracle(outcomes, threshold, window, limit)
    if left_at:  # the other layout joins at once; the one that left does not come back
        assert cur.active == [n for n in ("x", "y") if n != first]
        assert cur.history[0]["episodes_in_set"] == left_at


def test_a_layout_that_left_never_joins_again_and_the_set_empties() -> None:
    cur = Curriculum([["x", "y"]], 2, 1.0, 1, 10)
    rng = np.random.default_rng(0)
    cur.fill(rng, {})
    cur.record("x", True, 1, rng, {})  # mastered: no candidate is left to take its place
    cur.record("y", True, 2, rng, {})
    assert cur.active == [] and [h["layout"] for h in cur.history] == ["x", "y"]
    cur.record("x", False, 3, rng, {})  # outside the set: counted, nothing moves
    assert cur.active == [] and cur.count == {"x": 2, "y": 1}


def test_the_state_survives_json() -> None:
    cur = Curriculum(POOLS, 2, 0.5, 2, 3)
    rng = np.random.default_rng(1)
    cur.fill(rng, {})
    for k in range(7):
        cur.record(cur.active[k % 2], k % 3 == 0, k, rng, {})
    again = Curriculum(POOLS, 2, 0.5, 2, 3)
    again.restore(json.loads(json.dumps(cur.state())))
    assert again.state() == cur.state() and cur.history


def test_the_environments_draw_the_replayed_share_from_the_active_set(tmp_path: Path) -> None:
    cfg = StudentConfig(hidden=(8,))
    model = build_student(cfg, seed=0)
    model.set_normalizer(torch.zeros(4, cfg.input_dim), torch.ones(4, 2))
    pools = [["hr-rl", "hl-rr", "hr-rl-compact", "hl-rr-compact"]]

    def envs(replay: float) -> LayoutEnvs:
        cur = Curriculum(pools, 1, 0.9, 50, 4000)
        rng = np.random.default_rng(0)
        return LayoutEnvs(
            pools, 2, 1, cfg.inputs, FINETUNE_REWARD, rng, 0, 6, replay, "mastery", cur
        )

    e = envs(1.0)
    assert e.curriculum is not None and len(e.curriculum.active) == 1
    active = e.curriculum.active[0]
    assert {e._new_group().name for _ in range(30)} == {active}
    e0 = envs(0.0)
    assert len({e0._new_group().name for _ in range(60)}) == 4  # replay 0: uniformly, all four
    with pytest.raises(ValueError, match="mastery"):
        LayoutEnvs(
            pools, 1, 1, cfg.inputs, FINETUNE_REWARD, np.random.default_rng(0), 0, 6, 0.5, "mastery"
        )
