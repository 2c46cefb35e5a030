"""The SIMD float32 exponential of the density reward against float64 ``exp`` (the oracle)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pioneer.reward.fastexp import exp_shifted_inplace


def fast_exp(x: np.ndarray) -> np.ndarray:
    k = np.ascontiguousarray(x, dtype=np.float32).reshape(1, -1).copy()
    exp_shifted_inplace(k, np.zeros(1, np.float32), np.zeros(k.shape[1], np.float32))
    return k[0]


def test_relative_error_over_the_whole_range():
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(-86.0, 88.0, 200_000), np.linspace(-85.99, 88.0, 50_001)])
    x = x.astype(np.float32)
    ref = np.exp(x.astype(np.float64))
    rel = np.abs(fast_exp(x).astype(np.float64) - ref) / ref
    assert rel.max() < 3e-7


def test_exact_points_and_the_ends_of_the_range():
    got = fast_exp(np.array([0.0, -86.0, -86.5, -1e30, -np.inf, 89.0, 1e30], np.float32))
    assert got[0] == 1.0
    assert np.all(got[1:5] == 0.0)  # at and below the cut: exactly 0
    assert np.all(got[5:] == got[5]) and np.isfinite(got[5])  # clamped, no overflow


@settings(max_examples=50, deadline=None)
@given(
    st.integers(1, 7),
    st.integers(1, 70),
    st.integers(0, 2**32 - 1),
)
def test_row_and_column_offsets_match_numpy(rows, cols, seed):
    """k ← exp((k + a_i) + b_j), added in that order in float32, for any shape."""
    rng = np.random.default_rng(seed)
    k = rng.uniform(-40.0, 1.0, (rows, cols)).astype(np.float32)
    a = rng.uniform(-20.0, 0.0, rows).astype(np.float32)
    b = rng.uniform(-20.0, 0.0, cols).astype(np.float32)
    arg = (k + a[:, None]) + b[None, :]
    want = np.exp(arg.astype(np.float64))
    got = k.copy()
    exp_shifted_inplace(got, a, b)
    live = arg > -86.0
    np.testing.assert_allclose(got[live], want[live], rtol=3e-7, atol=0)
    assert np.all(got[~live] == 0.0)
