"""Kernels of the density reward (paper §IV-A.1, eqs. 9–10) against direct formulas."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from pioneer.reward.kernels import leverage_factor, se_kernel, sl_kernel, sq_dists


def _direct_se(a, b, g2, length):
    out = np.empty((a.shape[0], b.shape[0]))
    for i, x in enumerate(a):
        for j, y in enumerate(b):
            out[i, j] = g2 * math.exp(-float(np.sum((x - y) ** 2)) / (2 * length**2))
    return out


def _direct_sl(a, ga, b, gb, g2, length):
    se = _direct_se(a, b, g2, length)
    lev = np.array([[math.cos(math.pi / 2 * (p - q)) for q in gb] for p in ga])
    return lev * se


def test_se_kernel_matches_the_formula(rng):
    a, b = rng.normal(size=(5, 3)), rng.normal(size=(4, 3))
    for g2, length in [(1.0, 1.0), (2.5, 0.7), (0.3, 3.0)]:
        np.testing.assert_allclose(
            se_kernel(a, b, g2, length), _direct_se(a, b, g2, length), rtol=1e-12
        )


def test_se_kernel_is_a_symmetric_psd_gram_matrix(rng):
    a = rng.normal(size=(12, 2))
    k = se_kernel(a, a, 1.7, 0.8)
    np.testing.assert_allclose(k, k.T, rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.diag(k), 1.7)
    assert np.linalg.eigvalsh(k).min() > -1e-10
    assert np.all(k <= 1.7 + 1e-15) and np.all(k > 0)


def test_leverage_factor_values():
    g = np.array([1.0, -1.0, 0.0, 0.5])
    lev = leverage_factor(g, g)
    np.testing.assert_allclose(np.diag(lev), 1.0)
    assert lev[0, 1] == pytest.approx(-1.0)  # opposite signs: cos(π) = −1
    assert lev[0, 2] == pytest.approx(0.0, abs=1e-15)  # γ' = 0 is orthogonal to ±1
    assert lev[0, 3] == pytest.approx(math.cos(math.pi / 4))
    assert lev[1, 3] == pytest.approx(math.cos(3 * math.pi / 4))
    np.testing.assert_allclose(lev, lev.T)


def test_leverage_factor_is_the_outer_product_for_signs(rng):
    ga = rng.choice([-1.0, 1.0], 9)
    gb = rng.choice([-1.0, 1.0], 6)
    np.testing.assert_allclose(leverage_factor(ga, gb), np.outer(ga, gb), atol=1e-15)


def test_sl_kernel_for_signs_is_gamma_k_gamma(rng):
    z = rng.normal(size=(10, 2))
    g = rng.choice([-1.0, 1.0], 10)
    k = se_kernel(z, z, 1.3, 0.9)
    big_g = np.diag(g)
    np.testing.assert_allclose(sl_kernel(z, g, z, g, 1.3, 0.9), big_g @ k @ big_g, atol=1e-14)


def test_sl_kernel_matches_the_formula_for_continuous_gamma(rng):
    a, b = rng.normal(size=(6, 2)), rng.normal(size=(5, 2))
    ga, gb = rng.uniform(-1, 1, 6), rng.uniform(-1, 1, 5)
    np.testing.assert_allclose(
        sl_kernel(a, ga, b, gb, 0.8, 1.1),
        _direct_sl(a, ga, b, gb, 0.8, 1.1),
        rtol=1e-12,
        atol=1e-15,
    )


def test_sl_kernel_is_psd_for_continuous_gamma(rng):
    # cos(a − b) = cos a cos b + sin a sin b is a rank-2 PSD kernel; Schur product with k_SE
    z = rng.normal(size=(25, 3))
    g = rng.uniform(-1, 1, 25)
    k = sl_kernel(z, g, z, g, 1.0, 1.0)
    assert np.linalg.eigvalsh(k).min() > -1e-10


def test_sq_dists_keeps_dtype_and_clips(rng):
    a = rng.normal(size=(7, 4)).astype(np.float32)
    d = sq_dists(a, a)
    assert d.dtype == np.float32
    assert np.all(d >= 0)
    # far from the origin the expansion cancels badly; identical points must still give ≥ 0
    far = np.full((3, 2), 1e4) + rng.normal(size=(3, 2)) * 1e-3
    assert np.all(sq_dists(far, far) >= 0)


@settings(max_examples=40, deadline=None)
@given(
    hnp.arrays(np.float64, (4, 3), elements=st.floats(-10, 10)),
    hnp.arrays(np.float64, (5, 3), elements=st.floats(-10, 10)),
)
def test_sq_dists_property(a, b):
    direct = ((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)
    got = sq_dists(a, b)
    assert got.shape == (4, 5)
    scale = 1.0 + (a**2).sum(1)[:, None] + (b**2).sum(1)[None, :]
    assert np.all(np.abs(got - direct) <= 1e-12 * scale)
    assert np.all(got >= 0)
