"""A float32 exponential that LLVM vectorises, for the density reward's kernel matrix.

The teacher evaluates ≈ 1.1 M kernel values per decision, and numpy's float32 ``exp`` took
≈ 2.4 ns per element on our AVX2 host; this kernel takes ≈ 1 ns (docs/performance.md). The
method and its error bound are :mod:`pioneer.vecmath`'s (:func:`~pioneer.vecmath.exp32_row`,
inlined on each row after the row and column offsets are added). Multiply–add pairs may be
fused (``fastmath={"contract"}``: one FMA instead of a rounded product and a sum — the only
fast-math flag, so no reassociation; 30 % faster on AVX2 with the same error bound,
docs/performance.md).

Accuracy: relative error ≤ 3e−7 against float64 ``exp`` for x ∈ [−86, 88] (tested), below
the float32 evaluation error the density reward already accepts (docs/reward.md, ~1e−6). Inputs
at or below −86 give exactly 0 (e^−86 ≈ 4e−38 is negligible beside the kernel sums, and the
cut keeps 2^n a normal float); inputs above 88 are clamped (e^88 ≈ 1.7e38; the kernel's
arguments are ≤ 0 up to round-off).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

from pioneer.vecmath import exp32_row

__all__ = ["exp_shifted_inplace"]


@njit(cache=True, error_model="numpy", fastmath={"contract"})
def exp_shifted_inplace(
    k: NDArray[np.float32],  # (M, N), C-contiguous, overwritten
    a: NDArray[np.float32],  # (M,) row offsets
    b: NDArray[np.float32],  # (N,) column offsets
) -> None:
    """``k[i, j] ← exp((k[i, j] + a[i]) + b[j])`` in place (float32, see the module notes)."""
    rows, cols = k.shape
    shift = np.empty(cols, dtype=np.int32)  # scratch of exp32_row
    for i in range(rows):
        row = k[i]
        ai = a[i]
        for j in range(cols):
            row[j] = (row[j] + ai) + b[j]
        exp32_row(row, shift, cols)
