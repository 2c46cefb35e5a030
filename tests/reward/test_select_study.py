"""Held-out validation of the density reward on the shipped demos, length selection, AUROC,
and the static-study property (paper Fig. 3)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pioneer.errors import DataError
from pioneer.reward.dataset import Dataset
from pioneer.reward.density import DensityConfig, DensityReward
from pioneer.reward.features import feature_map
from pioneer.reward.length_scale import episode_split, select_length_scale
from pioneer.sim.scenarios import get_scenario
from pioneer.stats import auroc

SHIPPED = Path(__file__).resolve().parents[2] / "src" / "pioneer" / "data" / "demos"


@pytest.fixture(scope="module")
def shipped() -> dict[str, Dataset]:
    return {n: Dataset.load(SHIPPED / f"{n}.npz") for n in ("hr-rl", "hl-rr", "static")}


# --------------------------------------------------------------------------- auroc
def test_auroc_known_values():
    assert auroc([0.9, 0.8, 0.1, 0.2], [True, True, False, False]) == 1.0
    assert auroc([0.1, 0.2, 0.9, 0.8], [True, True, False, False]) == 0.0
    assert auroc([0.5, 0.5, 0.5], [True, False, True]) == 0.5
    assert auroc([3.0, 1.0, 2.0], [True, False, False]) == 1.0
    assert auroc([2.0, 1.0, 3.0], [True, False, False]) == 0.5
    assert np.isnan(auroc([1.0, 2.0], [True, True]))
    assert np.isnan(auroc([1.0, 2.0], [False, False]))


@settings(max_examples=50, deadline=None)
@given(
    st.lists(st.tuples(st.integers(0, 5), st.booleans()), min_size=2, max_size=30).filter(
        lambda xs: any(b for _, b in xs) and not all(b for _, b in xs)
    )
)
def test_auroc_is_the_pairwise_win_rate(pairs):
    s = np.array([p[0] for p in pairs], dtype=float)
    y = np.array([p[1] for p in pairs])
    wins = [(1.0 if a > b else 0.5 if a == b else 0.0) for a in s[y] for b in s[~y]]
    assert auroc(s, y) == pytest.approx(np.mean(wins), abs=1e-12)


# --------------------------------------------------------------------------- episode split
def test_episode_split_holds_out_whole_episodes():
    episode = np.repeat(np.arange(20), np.arange(1, 21))
    val = episode_split(episode, 0.3, np.random.default_rng(5))
    held = np.unique(episode[val])
    assert held.size == 6
    assert not np.isin(episode[~val], held).any()  # no episode on both sides
    assert np.all(val[np.isin(episode, held)])
    again = episode_split(episode, 0.3, np.random.default_rng(5))
    np.testing.assert_array_equal(val, again)
    # at least one episode is always held out
    assert np.unique(episode[episode_split(episode, 0.0, np.random.default_rng(0))]).size == 1


# --------------------------------------------------------------------------- shipped demos
@pytest.mark.parametrize("name", ["hr-rl", "hl-rr"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_reward_ranks_held_out_positives_above_negatives(shipped, name, seed, record_property):
    d = shipped[name]
    fm = feature_map("obs_action")
    z = fm.from_dataset(d)
    val = episode_split(d.episode, 0.3, np.random.default_rng(seed))
    assert (d.gamma[val] > 0).any() and (d.gamma[val] < 0).any()
    assert not np.isin(d.episode[~val], d.episode[val]).any()
    model = DensityReward().fit(z[~val], d.gamma[~val], list(fm.names))
    score = auroc(model(z[val]), d.gamma[val] > 0)
    record_property("auroc", score)
    print(
        f"\nheld-out AUROC {name} seed {seed}: {score:.4f} "
        f"({int((d.gamma[val] > 0).sum())} pos / {int((d.gamma[val] < 0).sum())} neg)"
    )
    # The default l (median pairwise distance) is broad on purpose (docs/reward.md): it ranks
    # held-out demos above chance while giving the teacher a graded reward (measured: 0.79-0.95
    # on the compact world's demos, 0.66-0.8 on the paper world's, whose 5 positive episodes
    # per scenario differ more from each other); --select-length trades that for AUROC ~0.99.
    assert score > 0.6
    # and the positives' held-out mean reward is above the negatives'
    r = model(z[val])
    assert r[d.gamma[val] > 0].mean() > r[d.gamma[val] < 0].mean()


def test_select_length_scale_records_every_candidate(shipped):
    d = shipped["hr-rl"]
    z = feature_map("obs_action").from_dataset(d)
    factors = (0.5, 1.0, 2.0)
    length, records = select_length_scale(z, d.gamma, d.episode, factors=factors)
    assert [r["factor"] for r in records] == list(factors)
    base = records[1]["length_scale"]
    for r in records:
        assert r["length_scale"] == pytest.approx(r["factor"] * base)
        assert 0.0 <= r["val_auroc"] <= 1.0
    best = max(r["val_auroc"] for r in records)
    assert length in [r["length_scale"] for r in records if r["val_auroc"] == best]
    assert best > 0.8


def test_select_length_scale_needs_negatives(rng):
    z = rng.normal(size=(30, 2))
    with pytest.raises(DataError) as exc:
        select_length_scale(z, np.ones(30), np.repeat(np.arange(6), 5))
    msg = str(exc.value)
    assert "negative" in msg and "expected" in msg and "received" in msg and "fix" in msg


# --------------------------------------------------------------------------- static study
def test_negatives_lower_the_reward_around_the_static_human(shipped):
    d = shipped["static"]
    fm = feature_map("xy")
    z, g = fm.from_dataset(d), d.gamma
    pos = g > 0
    cfg = DensityConfig(length_scale_factor=0.35)  # as in run_static_study
    m_pos = DensityReward(cfg).fit(z[pos], g[pos], list(fm.names))
    m_all = DensityReward(cfg).fit(z, g, list(fm.names))
    xmin, xmax, ymin, ymax = get_scenario("static").bounds
    xx, yy = np.meshgrid(np.linspace(xmin, xmax, 61), np.linspace(ymin, ymax, 91))
    pts = np.column_stack([xx.ravel(), yy.ravel()])
    near = np.linalg.norm(pts, axis=1) < 0.9  # the human stands at the origin, radius 0.6
    assert near.sum() > 10
    r_pos, r_all = m_pos(pts[near]).mean(), m_all(pts[near]).mean()
    print(
        f"\nstatic study: mean reward within 0.9 m of the human: "
        f"positives only {r_pos:.4f}, positives + negatives {r_all:.4f}"
    )
    assert r_all < r_pos
    assert r_all < 0  # the negatives were recorded there
    # on the demonstrated corridors the reward stays positive with the negatives included
    corridor = z[pos & (np.abs(z[:, 0]) > 1.0)]
    assert corridor.shape[0] > 20
    assert np.mean(m_all(corridor) > 0) > 0.9
