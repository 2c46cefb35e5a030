"""Vectorised e^x for loops compiled by numba, in float32 and float64, and the one switch
between them and libm (:func:`exp_where`).

numba calls libm's ``exp`` once per value (no vector math library in the pip build of
llvmlite), ≈ 2–4 ns a value; these forms fill SIMD vectors instead (≈ 1 ns on AVX2). Both
compute e^x as 2^n · e^r with n = round(x / ln 2) (by adding 1.5 · 2^23, or 1.5 · 2^52, whose
last bits then hold n) and r = x − n ln 2 (Cody–Waite split of ln 2 into a short high part and
a low part, so n ln 2 is exact enough), e^r by a Taylor polynomial on |r| ≤ ln 2 / 2 (Estrin's
scheme, a short dependency chain), and 2^n by adding n to the float's exponent bits. Every
step is branch-free, so a loop of it becomes SIMD on any vector width. The two precisions are
two kernels because their constants, polynomial degree and bit widths differ, not only types:

- :func:`exp32_row`, float32, degree 7: relative error ≤ 3e−7 against float64 ``exp`` for
  x ∈ [−86, 88] (tested with the density reward's kernel, :mod:`pioneer.reward.fastexp`).
  Inputs at or below −86 give exactly 0 (e^−86 ≈ 4e−38; the cut keeps 2^n a normal float);
  inputs above 88 are clamped (e^88 ≈ 1.7e38). Users: the density reward's kernel matrix
  (:mod:`pioneer.reward.fastexp`) and the gates of the GRU of CrowdNav++'s training
  (:mod:`pioneer.nn.recurrent`).
- :func:`exp64_lanes`, float64, degree 13 (the remainder below 4e−18 relative; fdlibm's
  ln2_hi has its 32 low bits zero, so n · ln2_hi is exact): within 2 ulp of ``math.exp`` for
  |x| ≤ 700 (tested). User: the social forces of the teacher's rollout in SIMD lanes
  (:mod:`pioneer.sim.kernel_simd`, ``precision="fast"``).

:func:`exp_where` is what their users call: the kernel of the arrays' dtype when ``vector``,
libm one value at a time otherwise (the reference, bit for bit as before).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import float32, int32, njit, types
from numba.extending import overload
from numpy.typing import NDArray

__all__ = ["exp32_row", "exp64_lanes", "exp_where"]


@njit(cache=True, error_model="numpy", fastmath={"contract"}, inline="always")
def exp32_row(
    buf: NDArray[np.float32], shift: NDArray[np.int32], count: int
) -> None:  # pragma: no cover - compiled
    """``buf[:count] ← e^buf[:count]`` in place (float32, contiguous); ``shift`` is scratch of
    at least ``count`` int32 values. Multiply–add pairs may fuse (``contract``, the only
    fast-math flag: deterministic on one machine)."""
    log2e = float32(1.4426950408889634)
    ln2_hi = float32(0.693359375)  # 8 significant bits: n · ln2_hi is exact for |n| < 2^15
    ln2_lo = float32(-2.12194440e-4)
    magic = float32(12582912.0)  # 1.5 · 2^23: adding it rounds to the nearest integer
    cut = float32(-86.0)  # at or below: e^x is taken as exactly 0
    hi = float32(88.0)  # above: clamped
    zero = float32(0.0)
    one = float32(1.0)
    c2 = float32(1.0 / 2.0)
    c3 = float32(1.0 / 6.0)
    c4 = float32(1.0 / 24.0)
    c5 = float32(1.0 / 120.0)
    c6 = float32(1.0 / 720.0)
    c7 = float32(1.0 / 5040.0)
    for j in range(count):
        x = buf[j]
        keep = x > cut
        xc = min(max(x, cut), hi)
        n = (xc * log2e + magic) - magic
        r = (xc - n * ln2_hi) - n * ln2_lo
        r2 = r * r  # Estrin's scheme: a short dependency chain pipelines better
        p = ((one + r) + (c2 + c3 * r) * r2) + ((c4 + c5 * r) + (c6 + c7 * r) * r2) * (r2 * r2)
        buf[j] = p if keep else zero
        shift[j] = (int32(n) << 23) if keep else int32(0)  # 2^n, added to the exponent bits
    bits = buf.view(np.int32)
    for j in range(count):
        bits[j] += shift[j]


_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_ROUND = 6755399441055744.0  # 1.5 · 2^52
_ROUND_BITS = np.float64(_ROUND).view(np.int64).item()
_TAYLOR = tuple(1.0 / math.factorial(k) for k in range(14))


@njit(cache=True, error_model="numpy", fastmath={"contract"})
def exp64_lanes(
    z: NDArray[np.float64],
    ok: NDArray[np.bool_],
    out: NDArray[np.float64],
    scratch: NDArray[np.float64],
    n: int,
) -> None:  # pragma: no cover - compiled
    """``out[l] = e^z[l]`` where ``ok[l]``, else 0, for ``|z| ≤ 700``: within 2 ulp of
    ``math.exp`` and branch-free (module notes); ``scratch`` holds at least ``n`` values.
    Products and sums may fuse (``contract``, the only fast-math flag: one FMA instead of a
    rounded product and a sum, deterministic on one machine; twice as fast)."""
    c = _TAYLOR
    for ln in range(n):
        zc = min(max(z[ln], -700.0), 700.0)
        tn = zc * _LOG2E + _ROUND
        nf = tn - _ROUND
        r = (zc - nf * _LN2_HI) - nf * _LN2_LO
        r2 = r * r
        r4 = r2 * r2
        r8 = r4 * r4
        p0 = (c[0] + c[1] * r) + (c[2] + c[3] * r) * r2
        p1 = (c[4] + c[5] * r) + (c[6] + c[7] * r) * r2
        p2 = (c[8] + c[9] * r) + (c[10] + c[11] * r) * r2
        p3 = c[12] + c[13] * r
        p = (p0 + p1 * r4) + (p2 + p3 * r4) * r8
        out[ln] = p if ok[ln] else 0.0
        scratch[ln] = tn if ok[ln] else _ROUND  # n = 0 where not ok: 0 stays 0
    bits = out.view(np.int64)
    nbits = scratch.view(np.int64)
    for ln in range(n):
        bits[ln] += (nbits[ln] - _ROUND_BITS) << 52


def exp_where(z: Any, ok: Any, out: Any, scratch: Any, n: int, vector: bool) -> None:
    """``out[l] = e^z[l]`` for ``l < n`` where ``ok[l]`` (every ``l`` when ``ok`` is
    ``None``), else 0. With ``vector`` by the SIMD kernel of the arrays' dtype — float32:
    :func:`exp32_row` (``scratch`` int32), float64: :func:`exp64_lanes` (``scratch``
    float64) — else by libm one value at a time. For numba-compiled callers only (the
    implementation is chosen by the arrays' dtype when the caller is compiled)."""
    raise NotImplementedError("exp_where is called from numba-compiled code only")


@overload(exp_where)
def _exp_where_impl(z, ok, out, scratch, n, vector):  # type: ignore[no-untyped-def]
    # The implementation for the arrays' dtype and for a mask or none, chosen at compile time.
    every = isinstance(ok, types.NoneType)
    if out.dtype == types.float32:
        lowest, zero32 = np.float32(-np.inf), np.float32(0.0)  # exp32_row: e^−∞ is exactly 0
        if every:

            def all32(z, ok, out, scratch, n, vector):  # type: ignore[no-untyped-def]
                if vector:
                    for j in range(n):
                        out[j] = z[j]
                    exp32_row(out, scratch, n)
                else:
                    for j in range(n):
                        out[j] = np.exp(z[j])

            return all32

        def where32(z, ok, out, scratch, n, vector):  # type: ignore[no-untyped-def]
            if vector:
                for j in range(n):
                    out[j] = z[j] if ok[j] else lowest
                exp32_row(out, scratch, n)
            else:
                for j in range(n):
                    out[j] = np.exp(z[j]) if ok[j] else zero32

        return where32
    if every:

        def all64(z, ok, out, scratch, n, vector):  # type: ignore[no-untyped-def]
            if vector:
                exp64_lanes(z, np.ones(n, np.bool_), out, np.empty(n), n)
            else:
                for j in range(n):
                    out[j] = np.exp(z[j])

        return all64

    def where64(z, ok, out, scratch, n, vector):  # type: ignore[no-untyped-def]
        if vector:
            exp64_lanes(z, ok, out, scratch, n)
        else:
            for j in range(n):
                out[j] = math.exp(z[j]) if ok[j] else 0.0

    return where64
