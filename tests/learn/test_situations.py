"""Layouts drawn by situation (the fine-tuning's ``stratify``): what a situation is, the split
against a brute-force oracle, and the draws following the situations' weights."""

from __future__ import annotations

import collections
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pioneer.learn import situations as situations_module
from pioneer.learn.finetune import FINETUNE_REWARD
from pioneer.learn.layout_env import LayoutEnvs
from pioneer.learn.models import StudentConfig, build_student
from pioneer.learn.situations import MIN_LAYOUTS, by_situation, situation
from pioneer.sim.scenarios import ElevatorLayout, elevator_scenario


def test_a_situation_counts_the_people_by_role_and_flags_a_shallow_lobby(
    scenario_registry: Any,  # the registration leaves no trace for other tests
) -> None:
    assert situation("hr-rl") == situation("hl-rr") == (2, 1, False)  # the paper's 4 m lobby
    assert situation("hr-rl-compact") == (2, 1, True)  # its 1.3 m lobby
    assert situation("static")[:2] == (0, 0)
    lay = ElevatorLayout(  # a crowded layout in a shallow lobby, as the sampler draws one
        lobby_width=5.0, lobby_depth=3.3, n_boarding=3, n_exiting=2, human_radius=0.45,
        robot_start_y=(-2.0, -1.7), boarder_x=(1.5, 1.6), boarder_y=(-3.7, -2.25),
        exit_start_y=(0.6, 2.3), exit_waypoints=((1.5, -1.3),),
    )  # fmt: skip
    scenario_registry.register_scenario("situation-test-crowded", lambda: elevator_scenario(lay))
    assert situation("situation-test-crowded") == (3, 2, True)


SITUATIONS = st.tuples(st.integers(1, 3), st.integers(0, 2), st.booleans())


@settings(max_examples=60, deadline=None)
@given(st.lists(st.lists(SITUATIONS, min_size=1, max_size=40), min_size=1, max_size=4))
def test_the_split_matches_a_brute_force_grouping(pools_situations: list[list[tuple]]) -> None:
    names = [[f"p{i}-{j}" for j in range(len(p))] for i, p in enumerate(pools_situations)]
    pairs = zip(names, pools_situations, strict=True)
    of = {n: s for p, ss in pairs for n, s in zip(p, ss, strict=True)}
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(situations_module, "situation", of.__getitem__)
        strata, weights = by_situation(names)
    assert sum(weights) == pytest.approx(1.0)
    assert sorted(n for s in strata for n in s) == sorted(of)  # every layout exactly once
    start = 0
    for pool in names:  # a pool's situations follow one another and share its share
        count = collections.Counter(of[n] for n in pool)
        mine = [s for s in strata if s[0] in pool]
        assert strata[start : start + len(mine)] == mine
        share = [1 / len(names) / len(mine)] * len(mine)
        assert weights[start : start + len(mine)] == pytest.approx(share)
        start += len(mine)
        big = {k for k, c in count.items() if c >= MIN_LAYOUTS}
        small = sum(c for k, c in count.items() if c < MIN_LAYOUTS)
        # brute force: one stratum per large situation, holding all of it; the small ones
        # together as one more if they make MIN_LAYOUTS (or are all there is), else folded in
        assert len(mine) == len(big) + (small >= MIN_LAYOUTS or not big)
        for s in mine:
            kinds = {of[n] for n in s}
            assert len(kinds & big) <= 1
            for k in kinds & big:
                assert sum(of[n] == k for n in s) == count[k]
            if not kinds & big:
                assert len(s) >= MIN_LAYOUTS or len(mine) == 1


def test_the_draws_follow_the_situations_weights(tmp_path: Path) -> None:
    model = build_student(StudentConfig(hidden=(8,)), seed=0)
    rng = np.random.default_rng(0)
    names = [["hr-rl"], ["hl-rr"]]
    inputs = model.config.inputs
    envs = LayoutEnvs(names, 1, 1, inputs, FINETUNE_REWARD, rng, 0, 6, weights=[0.8, 0.2])
    picks = [envs._new_group().name for _ in range(600)]
    assert picks.count("hr-rl") / len(picks) == pytest.approx(0.8, abs=0.05)
    with pytest.raises(ValueError, match="summing to 1"):
        LayoutEnvs(names, 1, 1, inputs, FINETUNE_REWARD, rng, 0, 6, weights=[0.5])
