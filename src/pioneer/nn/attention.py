"""Masked dot-product attention over a few nodes, forward and backward in numba.

Two blocks of a graph network whose samples hold N ≤ a few nodes with E-wide features
(CrowdNav++'s human–human and robot–human attention, Liu et al. ICRA 2023; scaled
dot-product attention after Vaswani et al. 2017). For every sample m, with ``scale`` = 1/√E
and softmax taken only over the nodes j with ``mask[m, j]`` (exactly 0 elsewhere; a sample
with no such node gets all-zero weights)::

    node_attention:  A_ij = softmax_j(scale · q_i · k_j),  out_i = relu(s_i + Σ_j A_ij v_j) · mask_i
    pool_attention:  a_i  = softmax_i(scale · k_i · q),    c     = Σ_i a_i u_i

``node_attention`` takes q, k, v side by side as one (M, N, 3E) array — the output of one
linear layer — and ``s`` the residual. In PyTorch operators each is a batched product of
N × E matrices per sample, a softmax of ≈ 8 operators and the residual, forward and
backward: at N = 3 and M ≈ 1,000 the batched products of 3 × 64 matrices dominate a
CrowdNav++ update (0.2–0.4 ms each, ≈ 40 of its ≈ 180 ms), spent dispatching tiny
matrices, not computing. Here each block is one compiled loop over the samples each way
(the backward written out: dA = dout · v, dS = A ⊙ (dA − Σ_j A dA), dq = scale dS k,
dk = scale dSᵀ q, dv = Aᵀ dout). The values equal the operator form's to float32 rounding
(sums grouped differently); the tests compare both and run ``torch.autograd.gradcheck`` on
the hand-written backward in float64. Of ``fastmath`` only ``reassoc``, which lets the
compiler sum the E-wide dot products in SIMD lanes (2× faster here): the order is fixed by the
compiled code, so a seeded run repeats bit for bit on one machine (not across CPUs with other
vector widths).
The attention weights are returned beside the output, without gradients.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from numba import njit
from numpy.typing import NDArray

__all__ = ["masked_softmax", "node_attention", "pool_attention"]

F = NDArray[np.floating]
B = NDArray[np.bool_]


@njit(cache=True, inline="always")
def _softmax_row(scores: F, keep: B, zero: Any, out: F) -> None:  # pragma: no cover - compiled
    """``out[j]`` = the softmax of ``scores`` over the entries with ``keep[j]``, 0 elsewhere,
    all 0 when no entry is kept (``zero``: 0 in the arrays' dtype)."""
    n = scores.shape[0]
    top, found = zero, False
    for j in range(n):
        if keep[j] and (not found or scores[j] > top):
            top, found = scores[j], True
    total = zero
    for j in range(n):
        if keep[j]:
            e = np.exp(scores[j] - top)
            out[j] = e
            total += e
        else:
            out[j] = zero
    if total > zero:
        for j in range(n):
            out[j] = out[j] / total


def masked_softmax(scores: NDArray[np.float32], mask: B) -> NDArray[np.float32]:
    """The softmax of :func:`_softmax_row` over the last axis of ``scores`` in NumPy, masked
    by ``mask`` (broadcast against ``scores``): masked entries exactly 0, a row with no
    unmasked entry all zeros. A second copy on purpose: CrowdNav++'s acting step at a batch
    of one (:mod:`pioneer.baselines.crowdnav.inference`) is faster as NumPy calls than as a
    compiled loop per call; ``tests/nn/test_attention.py`` binds the two to float32 rounding."""
    s = np.where(mask, scores, np.float32(-np.inf))
    top = s.max(axis=-1, keepdims=True)
    top = np.where(np.isfinite(top), top, np.float32(0.0))
    e = np.exp(s - top) * mask
    out: NDArray[np.float32] = e / np.maximum(e.sum(axis=-1, keepdims=True), np.float32(1e-30))
    return out


@njit(cache=True, fastmath={"reassoc"})
def _node_forward(qkv: F, s: F, mask: B, scale: Any, out: F, a: F) -> None:  # pragma: no cover
    """Fill ``out`` (M, N, E) and the weights ``a`` (M, N, N) of :func:`node_attention`."""
    m_len, n, e3 = qkv.shape
    e = e3 // 3
    zero = scale - scale
    scores = np.empty(n, dtype=qkv.dtype)
    acc = np.empty(e, dtype=qkv.dtype)
    for m in range(m_len):
        for i in range(n):
            for j in range(n):
                d = zero
                for c in range(e):
                    d += qkv[m, i, c] * qkv[m, j, e + c]
                scores[j] = d * scale
            _softmax_row(scores, mask[m], zero, a[m, i])
            for c in range(e):
                acc[c] = s[m, i, c]
            for j in range(n):
                w = a[m, i, j]
                if w != zero:
                    for c in range(e):
                        acc[c] += w * qkv[m, j, 2 * e + c]
            if mask[m, i]:
                for c in range(e):
                    out[m, i, c] = max(acc[c], zero)
            else:
                for c in range(e):
                    out[m, i, c] = zero


@njit(cache=True, fastmath={"reassoc"})
def _node_backward(
    dout: F, qkv: F, out: F, a: F, scale: Any, dqkv: F, ds: F
) -> None:  # pragma: no cover - compiled
    """Fill ``dqkv`` (M, N, 3E) and ``ds`` (M, N, E) from ``dout`` = ∂L/∂out.

    Per sample: first the N × N scores' gradients ``g``, then each output row summed in place
    once (dq_i over j, dk_j and dv_j over i, each sum in ascending order) — a row is never
    revisited, so the E-wide loops run in SIMD lanes."""
    m_len, n, e3 = qkv.shape
    e = e3 // 3
    zero = scale - scale
    da = np.empty(n, dtype=qkv.dtype)
    g = np.empty((n, n), dtype=qkv.dtype)
    for m in range(m_len):
        for i in range(n):  # through relu and the mask: out > 0 exactly where both pass
            for c in range(e):
                ds[m, i, c] = dout[m, i, c] if out[m, i, c] > zero else zero
        for i in range(n):
            row = zero
            for j in range(n):
                d = zero
                for c in range(e):
                    d += ds[m, i, c] * qkv[m, j, 2 * e + c]
                da[j] = d
                row += a[m, i, j] * d
            for j in range(n):
                g[i, j] = a[m, i, j] * (da[j] - row) * scale  # ∂L/∂(q_i · k_j)
        for i in range(n):  # dq_i = Σ_j g_ij k_j
            for c in range(e):
                dqkv[m, i, c] = zero
            for j in range(n):
                if a[m, i, j] != zero:
                    w = g[i, j]
                    for c in range(e):
                        dqkv[m, i, c] += w * qkv[m, j, e + c]
        for j in range(n):  # dk_j = Σ_i g_ij q_i, dv_j = Σ_i A_ij ds_i
            for c in range(e):
                dqkv[m, j, e + c] = zero
                dqkv[m, j, 2 * e + c] = zero
            for i in range(n):
                w = a[m, i, j]
                if w != zero:
                    gw = g[i, j]
                    for c in range(e):
                        dqkv[m, j, e + c] += gw * qkv[m, i, c]
                        dqkv[m, j, 2 * e + c] += w * ds[m, i, c]


@njit(cache=True, fastmath={"reassoc"})
def _pool_forward(
    keys: F, query: F, values: F, mask: B, scale: Any, out: F, a: F
) -> None:  # pragma: no cover - compiled
    """Fill ``out`` (M, E) and the weights ``a`` (M, N) of :func:`pool_attention`."""
    m_len, n, e = keys.shape
    zero = scale - scale
    scores = np.empty(n, dtype=keys.dtype)
    for m in range(m_len):
        for i in range(n):
            d = zero
            for c in range(e):
                d += keys[m, i, c] * query[m, c]
            scores[i] = d * scale
        _softmax_row(scores, mask[m], zero, a[m])
        for c in range(e):
            out[m, c] = zero
        for i in range(n):
            w = a[m, i]
            if w != zero:
                for c in range(e):
                    out[m, c] += w * values[m, i, c]


@njit(cache=True, fastmath={"reassoc"})
def _pool_backward(
    dout: F, keys: F, query: F, values: F, a: F, scale: Any, dkeys: F, dquery: F, dvalues: F
) -> None:  # pragma: no cover - compiled
    """Fill the gradients of :func:`pool_attention`'s inputs from ``dout`` = ∂L/∂c (M, E)."""
    m_len, n, e = keys.shape
    zero = scale - scale
    da = np.empty(n, dtype=keys.dtype)
    for m in range(m_len):
        row = zero
        for i in range(n):
            d = zero
            for c in range(e):
                d += dout[m, c] * values[m, i, c]
            da[i] = d
            row += a[m, i] * d
        for c in range(e):
            dquery[m, c] = zero
        for i in range(n):
            w = a[m, i]
            g = w * (da[i] - row) * scale  # ∂L/∂(k_i · q)
            for c in range(e):
                dvalues[m, i, c] = w * dout[m, c]
                dkeys[m, i, c] = g * query[m, c]
                dquery[m, c] += g * keys[m, i, c]


def _np(x: torch.Tensor) -> F:
    return np.ascontiguousarray(x.detach().numpy())


def _bool(mask: torch.Tensor) -> B:
    return np.ascontiguousarray(mask.numpy(), dtype=np.bool_)


def _outputs(
    ctx: Any, out: F, a: F, inputs: tuple[torch.Tensor, ...], sc: Any
) -> tuple[torch.Tensor, torch.Tensor]:
    """Save ``inputs``, the output and the weights for the backward pass (as tensors, so that
    autograd refuses a backward after any of them was changed in place); return the output and
    the weights (no gradient)."""
    out_t, weights = torch.from_numpy(out), torch.from_numpy(a)
    ctx.mark_non_differentiable(weights)
    ctx.save_for_backward(*inputs, out_t, weights)
    ctx.scale = sc
    return out_t, weights


class _NodeAttention(torch.autograd.Function):
    @staticmethod
    def forward(
        ctx: Any, qkv: torch.Tensor, s: torch.Tensor, mask: torch.Tensor, scale: float
    ) -> tuple[torch.Tensor, torch.Tensor]:
        q = _np(qkv)
        m_len, n, _ = q.shape
        out, a = np.empty(s.shape, q.dtype), np.empty((m_len, n, n), q.dtype)
        sc = q.dtype.type(scale)
        _node_forward(q, _np(s), _bool(mask), sc, out, a)
        return _outputs(ctx, out, a, (qkv,), sc)

    @staticmethod
    def backward(
        ctx: Any, dout: torch.Tensor, _da: torch.Tensor | None
    ) -> tuple[torch.Tensor, torch.Tensor, None, None]:
        q, out, a = (_np(t) for t in ctx.saved_tensors)
        dqkv, ds = np.empty_like(q), np.empty_like(out)
        _node_backward(_np(dout), q, out, a, ctx.scale, dqkv, ds)
        return torch.from_numpy(dqkv), torch.from_numpy(ds), None, None


class _PoolAttention(torch.autograd.Function):
    @staticmethod
    def forward(
        ctx: Any,
        keys: torch.Tensor,
        query: torch.Tensor,
        values: torch.Tensor,
        mask: torch.Tensor,
        scale: float,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        k, q = _np(keys), _np(query)
        out, a = np.empty_like(q), np.empty(k.shape[:2], k.dtype)
        sc = k.dtype.type(scale)
        _pool_forward(k, q, _np(values), _bool(mask), sc, out, a)
        return _outputs(ctx, out, a, (keys, query, values), sc)

    @staticmethod
    def backward(
        ctx: Any, dout: torch.Tensor, _da: torch.Tensor | None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, None, None]:
        k, q, v, _, a = (_np(t) for t in ctx.saved_tensors)
        dk, dq, dv = np.empty_like(k), np.empty_like(q), np.empty_like(v)
        _pool_backward(_np(dout), k, q, v, a, ctx.scale, dk, dq, dv)
        return torch.from_numpy(dk), torch.from_numpy(dq), torch.from_numpy(dv), None, None


def node_attention(
    qkv: torch.Tensor, s: torch.Tensor, mask: torch.Tensor, scale: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(out (M, N, E), A (M, N, N))`` of the node block (module docstring) from
    ``qkv (M, N, 3E)`` = [q | k | v], the residual ``s (M, N, E)`` and ``mask (M, N)`` (bool),
    with gradients to ``qkv`` and ``s`` (CPU tensors of one floating dtype)."""
    out, a = _NodeAttention.apply(qkv, s, mask, scale)
    return out, a


def pool_attention(
    keys: torch.Tensor, query: torch.Tensor, values: torch.Tensor, mask: torch.Tensor, scale: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(c (M, E), a (M, N))`` of the pooling block (module docstring) from ``keys`` and
    ``values (M, N, E)``, ``query (M, E)`` and ``mask (M, N)`` (bool), with gradients to the
    three tensors (CPU tensors of one floating dtype)."""
    c, a = _PoolAttention.apply(keys, query, values, mask, scale)
    return c, a
