"""The density reward (paper §IV-A.1, eqs. 6–10) against first-principles oracles."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.distance import pdist

import pioneer_testutils as tu
from pioneer.errors import ConfigError, DataError
from pioneer.reward.density import (
    DensityConfig,
    DensityReward,
    farthest_point_indices,
    kmeans_medoid_indices,
)
from pioneer.stats import auroc


# --------------------------------------------------------------------------- oracles
def k_sl(a, ga, b, gb, g2, length):
    """k_SL((a, γa), (b, γb)) = cos(π/2 (γa − γb)) g² exp(−‖a − b‖² / (2 l²)), pair by pair."""
    out = np.empty((a.shape[0], b.shape[0]))
    for i in range(a.shape[0]):
        d2 = ((b - a[i]) ** 2).sum(axis=1)
        out[i] = np.cos(np.pi / 2 * (ga[i] - gb)) * g2 * np.exp(-d2 / (2 * length**2))
    return out


def closed_form(z, g, u, gu, queries, lam, beta, g2, length):
    """α = (λ K_UU + β I)⁻¹ (1/N) K_UD 1 by a dense solve; r(q) = Σ α_i k_SL((q,+1),(u_i,γ_i))."""
    k_uu = k_sl(u, gu, u, gu, g2, length)
    k_ud = k_sl(u, gu, z, g, g2, length)
    alpha = np.linalg.solve(lam * k_uu + beta * np.eye(len(u)), k_ud @ np.ones(len(z)) / len(z))
    k_qu = k_sl(queries, np.ones(len(queries)), u, gu, g2, length)
    return k_qu @ alpha


def se(a, b, g2, length):
    return g2 * np.exp(-((a[:, None, :] - b[None, :, :]) ** 2).sum(-1) / (2 * length**2))


def signed_density_oracles(z, g, queries, lam, beta, g2, length):
    """Two forms of the ±1 oracle: with Γ = diag(γ) and the plain SE Gram matrix K,

    (i)  α = (λ Γ K Γ + β I)⁻¹ (1/N) Γ K γ,   r(q) = Σ α_i γ_i k(q, z_i);
    (ii) r(q) = k(q, Z) (λ K + β I)⁻¹ (1/N) K γ  — a regularised (positive − negative) density,
         since (1/N) K γ = (1/N) (Σ_{pos} k(·, z_j) − Σ_{neg} k(·, z_j)).
    """
    n = len(z)
    k = se(z, z, g2, length)
    kq = se(queries, z, g2, length)
    big_g = np.diag(g)
    alpha = np.linalg.solve(lam * big_g @ k @ big_g + beta * np.eye(n), big_g @ k @ g / n)
    r1 = kq @ (alpha * g)
    pos, neg = g > 0, g < 0
    density_diff = (k[:, pos].sum(1) - k[:, neg].sum(1)) / n
    r2 = kq @ np.linalg.solve(lam * k + beta * np.eye(n), density_diff)
    return r1, r2


def assert_close_to_max(got, want, rtol=1e-4):
    """float32 evaluation: agree to ``rtol`` relative to the largest |r|."""
    scale = max(float(np.max(np.abs(want))), 1e-12)
    np.testing.assert_allclose(got, want, rtol=0, atol=rtol * scale)


# --------------------------------------------------------------------------- closed form
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize(
    ("lam", "beta", "g2", "length"), [(1e-2, 1e-3, 1.0, 0.8), (0.5, 0.05, 2.0, 1.5)]
)
def test_fit_matches_a_dense_solve_with_continuous_gamma(seed, lam, beta, g2, length):
    rng = np.random.default_rng(seed)
    n, d = 25, 2
    z = rng.normal(size=(n, d))
    g = rng.uniform(-1.0, 1.0, n)
    cfg = DensityConfig(length_scale=length, lam=lam, beta=beta, gain2=g2, standardize=False)
    model = DensityReward(cfg).fit(z, g)
    queries = np.vstack([z, rng.normal(size=(30, d)) * 1.5])
    want = closed_form(z, g, z, g, queries, lam, beta, g2, length)
    assert_close_to_max(model.raw(queries), want)
    assert model.length_ == length
    assert model.n_train_ == n and model.info_["n_inducing"] == n
    np.testing.assert_array_equal(model.inducing_, z)
    np.testing.assert_array_equal(model.leverage_, g)


def _signed_data(draw: Any) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    n = draw(st.integers(2, 14))
    d = draw(st.integers(1, 3))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    z = rng.normal(size=(n, d)) * draw(st.sampled_from([0.5, 1.0, 2.0]))
    g = rng.choice([-1.0, 1.0], n)
    params = {
        "lam": draw(st.sampled_from([1e-2, 0.1, 1.0])),
        "beta": draw(st.sampled_from([1e-3, 1e-2, 0.1])),
        "g2": draw(st.sampled_from([0.5, 1.0, 3.0])),
        "length": draw(st.sampled_from([0.5, 1.0, 2.0])),
    }
    return z, g, params


@settings(max_examples=50, deadline=None)
@given(st.data())
def test_signed_gamma_reward_is_a_regularised_density_difference(data):
    z, g, p = _signed_data(data.draw)
    cfg = DensityConfig(
        length_scale=p["length"], lam=p["lam"], beta=p["beta"], gain2=p["g2"], standardize=False
    )
    model = DensityReward(cfg).fit(z, g)
    rng = np.random.default_rng(len(z))
    queries = np.vstack([z, z + rng.normal(size=z.shape) * 0.3])
    r1, r2 = signed_density_oracles(z, g, queries, p["lam"], p["beta"], p["g2"], p["length"])
    np.testing.assert_allclose(r1, r2, rtol=0, atol=1e-9 * max(1.0, np.abs(r2).max()))
    assert_close_to_max(model.raw(queries), r2)
    # the scaled reward divides by the largest |r| over the training demos
    assert model.scale_ == pytest.approx(np.abs(model.raw(z)).max(), rel=1e-12)
    assert np.abs(model(z)).max() == pytest.approx(1.0, rel=1e-12)


def test_all_negative_demos_give_a_negated_positive_reward(rng):
    z = rng.normal(size=(15, 2))
    cfg = DensityConfig(length_scale=0.7, standardize=False)
    pos = DensityReward(cfg).fit(z, np.ones(15))
    neg = DensityReward(cfg).fit(z, -np.ones(15))
    q = rng.normal(size=(20, 2))
    assert_close_to_max(neg.raw(q), -pos.raw(q), rtol=1e-5)


def test_zero_fidelity_demos_do_not_move_the_reward(rng):
    # k_SL((q, +1), (u, 0)) = cos(π/2) k = 0: a γ = 0 demo only changes the 1/N normalisation
    z = rng.normal(size=(12, 2))
    g = rng.choice([-1.0, 1.0], 12)
    cfg = DensityConfig(length_scale=0.8, standardize=False)
    base = DensityReward(cfg).fit(z, g)
    extra = np.vstack([z, rng.normal(size=(4, 2))])
    with_zeros = DensityReward(cfg).fit(extra, np.concatenate([g, np.zeros(4)]))
    q = rng.normal(size=(25, 2))
    # the zero-γ points are decoupled from the ±1 ones in K_UU as well (cos(π/2) = 0)
    assert_close_to_max(with_zeros.raw(q) * 16 / 12, base.raw(q), rtol=1e-5)


# --------------------------------------------------------------------------- qualitative
def _clusters(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    a = rng.normal(size=(20, 2)) * 0.3
    b = np.array([5.0, 0.0]) + rng.normal(size=(20, 2)) * 0.3
    neg = np.array([5.0, 0.6]) + rng.normal(size=(15, 2)) * 0.2
    return a, b, neg


def test_negatives_lower_the_reward_only_near_themselves(rng):
    a, b, neg = _clusters(rng)
    cfg = DensityConfig(length_scale=0.5, standardize=False)
    pos_z = np.vstack([a, b])
    only_pos = DensityReward(cfg).fit(pos_z, np.ones(len(pos_z)))
    both = DensityReward(cfg).fit(
        np.vstack([pos_z, neg]), np.concatenate([np.ones(len(pos_z)), -np.ones(len(neg))])
    )
    # positives only: positive at every demo and at the cluster centres, ~0 far away
    assert np.all(only_pos.raw(pos_z) > 0)
    centres = np.array([[0.0, 0.0], [5.0, 0.0]])
    assert np.all(only_pos.raw(centres) > 0.3 * only_pos.scale_)
    far = np.array([[20.0, 20.0], [-15.0, 3.0]])
    assert np.all(np.abs(only_pos.raw(far)) < 1e-6 * only_pos.scale_)
    # 1/N_D: with N_D = 55 instead of 40 every far-from-negatives value shrinks by 40/55
    ratio = len(pos_z) / (len(pos_z) + len(neg))
    near_a = np.vstack([a, [[0.0, 0.0], [0.2, -0.1]]])
    np.testing.assert_allclose(both.raw(near_a), ratio * only_pos.raw(near_a), rtol=1e-4)
    # near the negatives: lower than the rescaled positive-only reward, negative on them
    np.testing.assert_array_less(both.raw(neg), ratio * only_pos.raw(neg))
    assert np.mean(both.raw(neg)) < 0
    assert both.raw(np.array([[5.0, 0.6]]))[0] < 0 < only_pos.raw(np.array([[5.0, 0.6]]))[0]
    # far away from everything both vanish
    assert np.all(np.abs(both.raw(far)) < 1e-6 * both.scale_)


# --------------------------------------------------------------------------- standardisation
def _pairwise_median_length(zs: np.ndarray) -> float:
    return float(np.median(pdist(zs)))  # the default: the median pairwise distance


def test_default_length_scale_is_the_median_pairwise_distance(rng):
    z = rng.normal(size=(60, 4)) * np.array([1.0, 10.0, 0.1, 3.0]) + 7.0
    model = DensityReward(DensityConfig()).fit(z, rng.choice([-1.0, 1.0], 60))
    zs = (z - z.mean(0)) / z.std(0)
    assert model.length_ == pytest.approx(_pairwise_median_length(zs), rel=1e-12)
    np.testing.assert_allclose(model.mean_, z.mean(0))
    np.testing.assert_allclose(model.std_, z.std(0))
    half = DensityReward(DensityConfig(length_scale_factor=0.5)).fit(z, np.ones(60))
    assert half.length_ == pytest.approx(0.5 * model.length_, rel=1e-12)


def test_constant_feature_gets_unit_std(rng):
    z = np.column_stack([rng.normal(size=20), np.full(20, 3.0)])
    model = DensityReward().fit(z, np.ones(20))
    assert model.std_[1] == 1.0
    assert np.all(np.isfinite(model(z)))


def test_standardised_reward_is_invariant_to_affine_feature_changes(rng):
    z = rng.normal(size=(40, 3))
    g = rng.choice([-1.0, 1.0], 40)
    scale, shift = np.array([5.0, 0.01, 300.0]), np.array([-2.0, 100.0, 0.5])
    m1 = DensityReward().fit(z, g)
    m2 = DensityReward().fit(z * scale + shift, g)
    q = rng.normal(size=(30, 3)) * 1.2
    assert m1.length_ == pytest.approx(m2.length_, rel=1e-9)
    np.testing.assert_allclose(m2(q * scale + shift), m1(q), rtol=0, atol=1e-4)


def test_standardised_fit_equals_a_plain_fit_on_standardised_data(rng):
    z = rng.normal(size=(30, 2)) * [3.0, 0.5] + [1.0, -4.0]
    g = rng.uniform(-1, 1, 30)
    m = DensityReward(DensityConfig(length_scale=0.9)).fit(z, g)
    zs = (z - z.mean(0)) / z.std(0)
    q = rng.normal(size=(10, 2)) * [3.0, 0.5] + [1.0, -4.0]
    qs = (q - z.mean(0)) / z.std(0)
    want = closed_form(zs, g, zs, g, qs, 1e-2, 1e-3, 1.0, 0.9)
    assert_close_to_max(m.raw(q), want)


# --------------------------------------------------------------------------- evaluation
def test_single_rows_and_chunks_agree(rng):
    z = rng.normal(size=(50, 3))
    model = DensityReward().fit(z, rng.choice([-1.0, 1.0], 50))
    q = rng.normal(size=(5000, 3))  # more than one 4096-row evaluation chunk
    full = model(q)
    parts = np.concatenate([model(q[s : s + 700]) for s in range(0, 5000, 700)])
    np.testing.assert_allclose(full, parts, rtol=1e-6, atol=1e-9)
    assert model(q[7]).shape == (1,)
    np.testing.assert_allclose(model(q[7]), full[7:8], rtol=1e-6)
    np.testing.assert_allclose(model(q) * model.scale_, model.raw(q), rtol=1e-12)


def test_one_dimensional_features(rng):
    z = rng.normal(size=12)
    model = DensityReward(DensityConfig(length_scale=0.5, standardize=False)).fit(z, np.ones(12))
    want = closed_form(
        z[:, None], np.ones(12), z[:, None], np.ones(12), z[:, None], 1e-2, 1e-3, 1.0, 0.5
    )
    assert_close_to_max(model.raw(z), want)


def test_wrong_feature_dimension_is_refused(rng):
    model = DensityReward().fit(rng.normal(size=(10, 3)), np.ones(10))
    with pytest.raises(DataError) as exc:
        model(rng.normal(size=(4, 2)))
    tu.assert_house_message(str(exc.value), "features", "(M, 3)")


def test_unfitted_model_is_refused(tmp_path):
    with pytest.raises(ConfigError) as exc:
        DensityReward().raw(np.zeros((1, 2)))
    tu.assert_house_message(str(exc.value), "fit")
    with pytest.raises(ConfigError):
        DensityReward().save(tmp_path / "never-written.npz")
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- fit validation
@pytest.mark.parametrize(
    ("case", "needle"),
    [
        ("nan_feature", "features[3]"),
        ("inf_feature", "features[0]"),
        ("gamma_high", "gamma[2]"),
        ("gamma_low", "gamma[5]"),
        ("gamma_nan", "gamma[1]"),
        ("gamma_shape", "gamma"),
        ("empty", "features"),
        ("names", "feature_names"),
    ],
)
def test_fit_refuses_bad_training_data(rng, case, needle):
    z = rng.normal(size=(8, 2))
    g = np.ones(8)
    names = None
    if case == "nan_feature":
        z[3, 1] = np.nan
    elif case == "inf_feature":
        z[0, 0] = np.inf
    elif case == "gamma_high":
        g[2] = 1.2
    elif case == "gamma_low":
        g[5] = -3.0
    elif case == "gamma_nan":
        g[1] = np.nan
    elif case == "gamma_shape":
        g = np.ones(7)
    elif case == "empty":
        z, g = np.zeros((0, 2)), np.zeros(0)
    elif case == "names":
        names = ["a", "b", "c"]
    with pytest.raises(DataError) as exc:
        DensityReward().fit(z, g, names)
    tu.assert_house_message(str(exc.value), needle)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("lam", 0.0),
        ("beta", -1.0),
        ("gain2", float("nan")),
        ("length_scale", 0.0),
        ("length_scale_factor", -2.0),
        ("jitter", 0.0),
        ("max_inducing", 0),
        ("max_inducing", 2.5),
        ("inducing", "random"),
    ],
)
def test_config_is_validated(field, value):
    with pytest.raises(ConfigError) as exc:
        DensityConfig(**{field: value})
    tu.assert_house_message(str(exc.value), field)


# --------------------------------------------------------------------------- inducing points
@pytest.mark.parametrize("method", ["kmeans", "fps"])
def test_inducing_subset_is_distinct_training_rows_and_fit_is_exact(method):
    rng = np.random.default_rng(3)
    n = 4500  # also more than one 4096-column chunk of K_UD
    z = np.vstack([rng.normal(size=(n // 2, 2)) * 0.5, rng.normal(size=(n // 2, 2)) * 0.5 + 3.0])
    z = z * [2.0, 0.5] + [1.0, 1.0]
    g = np.concatenate([np.ones(n // 2), -np.ones(n // 2)])
    cfg = DensityConfig(max_inducing=40, inducing=method, length_scale=0.4)
    model = DensityReward(cfg).fit(z, g)
    u = model.inducing_
    assert 1 <= u.shape[0] <= 40
    assert model.info_["n_inducing"] == u.shape[0] == model.alpha_.shape[0]
    assert np.unique(u, axis=0).shape[0] == u.shape[0]
    zs = (z - model.mean_) / model.std_
    for row, lev in zip(u, model.leverage_, strict=True):
        hits = np.flatnonzero(np.all(zs == row, axis=1))
        assert hits.size >= 1
        assert lev == g[hits[0]]
    assert (model.leverage_ > 0).any() and (model.leverage_ < 0).any()
    # α uses K_UD over *all* N demos (eq. 8), not only the inducing ones
    q = np.vstack([z[::300], rng.normal(size=(10, 2)) + 1.0])
    qs = (q - model.mean_) / model.std_
    want = closed_form(zs, g, u, model.leverage_, qs, 1e-2, 1e-3, 1.0, 0.4)
    assert_close_to_max(model.raw(q), want)
    assert auroc(model(z), g > 0) > 0.95


def test_farthest_point_indices_are_distinct_and_spread(rng):
    z = rng.normal(size=(200, 3))
    idx = farthest_point_indices(z, 30, np.random.default_rng(1))
    assert idx.shape == (30,) and np.unique(idx).size == 30
    assert idx.min() >= 0 and idx.max() < 200
    # each new point is the farthest from the ones before it
    for i in range(2, 30):
        d_prev = ((z[:, None, :] - z[idx[:i]][None]) ** 2).sum(-1).min(1)
        assert d_prev[idx[i]] == pytest.approx(d_prev.max())
    np.testing.assert_array_equal(idx, farthest_point_indices(z, 30, np.random.default_rng(1)))


def test_kmeans_medoids_are_sorted_distinct_rows(rng):
    z = rng.normal(size=(300, 2))
    idx = kmeans_medoid_indices(z, 25, np.random.default_rng(0))
    assert 1 <= idx.size <= 25
    np.testing.assert_array_equal(idx, np.unique(idx))
    np.testing.assert_array_equal(idx, kmeans_medoid_indices(z, 25, np.random.default_rng(0)))


def test_fps_with_repeated_rows_still_gives_distinct_points():
    rng = np.random.default_rng(0)
    z = np.repeat(rng.normal(size=(5, 2)), 10, axis=0)  # 50 rows, 5 distinct points
    model = DensityReward(DensityConfig(max_inducing=8, inducing="fps")).fit(z, np.ones(50))
    u = model.inducing_
    assert np.unique(u, axis=0).shape[0] == u.shape[0]


def test_jitter_fallback_on_identical_points():
    z = np.ones((50, 2))
    cfg = DensityConfig(beta=1e-300, length_scale=1.0)
    model = DensityReward(cfg).fit(z, np.ones(50))
    assert model.info_["jitter"] >= 0
    r = model(np.array([[1.0, 1.0], [1.5, 1.0], [9.0, 9.0]]))
    assert np.all(np.isfinite(r))
    assert r[0] == pytest.approx(1.0, rel=1e-5)
    assert 0 < r[1] < r[0] and abs(r[2]) < 1e-6


def test_tiny_beta_on_a_singular_kernel_still_fits():
    # λ K with K = all ones is singular; β ≈ 0 leaves it numerically semi-definite
    z = np.zeros((40, 1))
    model = DensityReward(DensityConfig(beta=1e-300, standardize=False, length_scale=1.0))
    model.fit(z, np.ones(40))
    assert model.info_["jitter"] >= 0
    assert np.all(np.isfinite(model.alpha_))
    # r(z) = K α ≈ b / λ = 1 / λ (every b_i = 1) up to the regularisation
    assert model.raw(np.zeros((1, 1)))[0] == pytest.approx(1.0 / 1e-2, rel=1e-2)


def test_cholesky_solve_grows_the_jitter_until_it_factorises():
    from pioneer.reward.density import _cholesky_solve

    a = np.array([[1.0, 1.0], [1.0, 1.0 - 1e-12]])  # indefinite: det = −1e-12
    b = np.array([1.0, 2.0])
    x, eps = _cholesky_solve(a, b, 1e-10)
    assert eps in (1e-10, 1e-9, 1e-8, 1e-7, 1e-6)
    assert eps > 0
    scale = np.mean(np.diag(a))
    np.testing.assert_allclose((a + eps * scale * np.eye(2)) @ x, b, rtol=1e-6)
    spd = np.array([[2.0, 0.5], [0.5, 1.0]])
    x, eps = _cholesky_solve(spd, b, 1e-10)
    assert eps == 0.0
    np.testing.assert_allclose(x, np.linalg.solve(spd, b), atol=1e-12)


# _median_difference takes np.median of an empty pair list for N = 1 (numpy warns; harmless)
@pytest.mark.filterwarnings("ignore:Mean of empty slice:RuntimeWarning")
@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
def test_a_single_demo_is_enough(rng):
    z = rng.normal(size=(1, 3))
    model = DensityReward().fit(z, np.ones(1))
    assert model.length_ == 1.0  # no pairwise differences: the heuristic falls back to 1
    assert model(z)[0] == pytest.approx(1.0)
    assert 0 < model(z + 0.5)[0] < 1.0


# --------------------------------------------------------------------------- save / load
def _fit_small(rng: np.random.Generator) -> tuple[DensityReward, np.ndarray]:
    z = rng.normal(size=(30, 3)) * [1.0, 2.0, 0.5]
    g = rng.uniform(-1, 1, 30)
    m = DensityReward(DensityConfig(lam=0.05, seed=4)).fit(z, g, ["a", "b", "c"])
    return m, z


def test_save_load_round_trip_is_identical(tmp_path, rng):
    model, z = _fit_small(rng)
    model.info_["features"] = "custom"
    p = tmp_path / "deep" / "model.npz"
    model.save(p)
    back = DensityReward.load(p)
    q = np.vstack([z, rng.normal(size=(20, 3))])
    np.testing.assert_array_equal(back.raw(q), model.raw(q))
    np.testing.assert_array_equal(back(q), model(q))
    assert back.config == model.config
    assert back.feature_names == ["a", "b", "c"]
    assert (back.length_, back.scale_, back.n_train_) == (model.length_, model.scale_, 30)
    assert back.info_ == model.info_
    for k in ("mean_", "std_", "inducing_", "leverage_", "alpha_"):
        np.testing.assert_array_equal(getattr(back, k), getattr(model, k))
    with np.load(p, allow_pickle=False) as f:
        assert set(f.files) == {"mean", "std", "inducing", "leverage", "alpha", "metadata"}
    assert [x.name for x in p.parent.iterdir()] == ["model.npz"]


def _model_arrays(tmp_path: Path, rng: np.random.Generator) -> tuple[dict[str, Any], dict]:
    model, _ = _fit_small(rng)
    model.save(tmp_path / "good.npz")
    with np.load(tmp_path / "good.npz", allow_pickle=False) as f:
        arrays = {k: f[k] for k in f.files}
    return arrays, json.loads(str(arrays["metadata"]))


def _write_model(path: Path, arrays: dict[str, Any], meta: dict | None) -> Path:
    payload = dict(arrays)
    if meta is not None:
        payload["metadata"] = np.array(json.dumps(meta))
    with open(path, "wb") as fh:
        np.savez(fh, **payload)
    return path


def _break(arrays: dict[str, Any], meta: dict, case: str) -> None:
    if case == "nan_alpha":
        arrays["alpha"] = arrays["alpha"].copy()
        arrays["alpha"][4] = np.nan
    elif case == "inf_mean":
        arrays["mean"] = arrays["mean"].copy()
        arrays["mean"][0] = np.inf
    elif case == "nan_inducing":
        arrays["inducing"] = arrays["inducing"].copy()
        arrays["inducing"][2, 1] = np.nan
    elif case == "leverage_out_of_range":
        arrays["leverage"] = arrays["leverage"].copy()
        arrays["leverage"][0] = 1.5
    elif case == "std_zero":
        arrays["std"] = np.zeros_like(arrays["std"])
    elif case == "inducing_shape":
        arrays["inducing"] = arrays["inducing"][:, :2]
    elif case == "leverage_shape":
        arrays["leverage"] = arrays["leverage"][:-1]
    elif case == "std_shape":
        arrays["std"] = arrays["std"][:2]
    elif case == "missing_alpha":
        del arrays["alpha"]
    elif case == "format":
        meta["format"] = "pioneer.density_reward/0"


MODEL_CASES = [
    ("nan_alpha", "alpha"),
    ("inf_mean", "mean"),
    ("nan_inducing", "inducing"),
    ("leverage_out_of_range", "leverage"),
    ("std_zero", "std"),
    ("inducing_shape", "inducing"),
    ("leverage_shape", "leverage"),
    ("std_shape", "std"),
    ("missing_alpha", "alpha"),
    ("format", "format"),
]


@pytest.mark.parametrize(("case", "needle"), MODEL_CASES)
def test_load_refuses_bad_model_files(tmp_path, rng, case, needle):
    arrays, meta = _model_arrays(tmp_path, rng)
    _break(arrays, meta, case)
    p = _write_model(tmp_path / "bad.npz", arrays, meta)
    with pytest.raises(DataError) as exc:
        DensityReward.load(p)
    tu.assert_house_message(str(exc.value), needle)


def test_load_refuses_a_model_without_metadata(tmp_path, rng):
    arrays, _ = _model_arrays(tmp_path, rng)
    del arrays["metadata"]
    with pytest.raises(DataError) as exc:
        DensityReward.load(_write_model(tmp_path / "bad.npz", arrays, None))
    tu.assert_house_message(str(exc.value), "metadata")


def test_load_refuses_a_truncated_model(tmp_path, rng):
    model, _ = _fit_small(rng)
    p = tmp_path / "m.npz"
    model.save(p)
    raw = p.read_bytes()
    p.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(DataError) as exc:
        DensityReward.load(p)
    tu.assert_house_message(str(exc.value), "truncated")


def test_load_refuses_missing_files_and_datasets(tmp_path):
    with pytest.raises(DataError) as exc:
        DensityReward.load(tmp_path / "missing.npz")
    tu.assert_house_message(str(exc.value), "missing.npz")
    shipped = Path(__file__).resolve().parents[2] / "src/pioneer/data/demos/static.npz"
    with pytest.raises(DataError) as exc:
        DensityReward.load(shipped)  # a dataset, not a model
    tu.assert_house_message(str(exc.value), "alpha")


def test_load_refuses_a_model_without_samples_naming_alpha(tmp_path, rng):
    arrays, meta = _model_arrays(tmp_path, rng)
    for k in ("alpha", "leverage"):
        arrays[k] = arrays[k][:0]
    arrays["inducing"] = arrays["inducing"][:0]
    with pytest.raises(DataError) as exc:
        DensityReward.load(_write_model(tmp_path / "empty.npz", arrays, meta))
    tu.assert_house_message(str(exc.value), "alpha")


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("scale", math.nan),
        ("scale", 0.0),
        ("scale", -2.0),
        ("length_scale", math.nan),
        ("length_scale", 0.0),
        ("length_scale", -1.0),
    ],
)
def test_load_refuses_bad_metadata_scalars(tmp_path, rng, key, value):
    arrays, meta = _model_arrays(tmp_path, rng)
    meta[key] = value
    with pytest.raises(DataError) as exc:
        DensityReward.load(_write_model(tmp_path / "bad.npz", arrays, meta))
    tu.assert_house_message(str(exc.value), key)


@pytest.mark.parametrize("key", ["config", "feature_names", "length_scale", "scale", "n_train"])
def test_load_refuses_incomplete_metadata(tmp_path, rng, key):
    arrays, meta = _model_arrays(tmp_path, rng)
    del meta[key]
    with pytest.raises(DataError) as exc:
        DensityReward.load(_write_model(tmp_path / "bad.npz", arrays, meta))
    tu.assert_house_message(str(exc.value), key)
