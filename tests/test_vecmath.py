"""The one e^x switch (:func:`pioneer.vecmath.exp_where`): by the SIMD kernel of the arrays'
dtype or by libm, only where asked, zeros elsewhere; libm's values bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

from pioneer.vecmath import exp_where


@njit(cache=False)
def _masked(z, ok, out, scratch, vector):
    exp_where(z, ok, out, scratch, z.shape[0], vector)


@njit(cache=False)
def _every(z, out, scratch, vector):
    exp_where(z, None, out, scratch, z.shape[0], vector)


@njit(cache=False)
def _libm(z):
    out = np.empty_like(z)  # the loops before the switch was shared: libm one value at a time
    for j in range(z.size):
        out[j] = np.exp(z[j])
    return out


# float32: the kernel's stated 3e-7 relative; float64: 2 ulp of libm's
RTOL = {np.float32: 3e-7, np.float64: 5e-16}


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("vector", [False, True])
def test_exp_where_takes_e_to_the_x_where_asked_and_zero_elsewhere(dtype, vector):
    rng = np.random.default_rng(5)
    z = rng.uniform(-20.0, 5.0, 257).astype(dtype)
    ok = rng.random(z.size) < 0.6
    scratch = np.empty(z.size, np.int32 if dtype == np.float32 else np.float64)
    out = np.full(z.size, 7.0, dtype)
    _masked(z, ok, out, scratch, vector)
    want = np.array([math.exp(float(x)) for x in z])
    assert out.dtype == dtype
    np.testing.assert_array_equal(out[~ok], 0.0)
    np.testing.assert_allclose(out[ok], want[ok], rtol=RTOL[dtype], atol=0)
    every = np.empty_like(z)
    _every(z, every, scratch, vector)
    np.testing.assert_allclose(every, want, rtol=RTOL[dtype], atol=0)
    if not vector:  # libm's values, bit for bit
        np.testing.assert_array_equal(every, _libm(z))
        np.testing.assert_array_equal(out[ok], _libm(z)[ok])
