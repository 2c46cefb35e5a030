"""A GRU run over a whole sequence with episode resets, forward and backward in numba.

PyTorch's :class:`torch.nn.GRUCell` (Cho et al. 2014, in PyTorch's form)::

    r_t = σ(W_ir x_t + b_ir + W_hr h + b_hr)
    z_t = σ(W_iz x_t + b_iz + W_hz h + b_hz)
    n_t = tanh(W_in x_t + b_in + r_t ⊙ (W_hn h + b_hn))
    h_t = (1 − z_t) ⊙ n_t + z_t ⊙ h

with ``h = h_{t−1} ⊙ keep_t`` here: ``keep_t`` is 0 where an episode starts at step t (the
state is reset) and 1 elsewhere, so one call runs sequences that hold several episodes, as
PPO's recurrent minibatches do. A step-by-step loop of ``GRUCell`` under autograd costs ≈ 30
PyTorch operators per step forward and backward; at 64-wide layers a training step is bound
by their dispatch, not by arithmetic. :func:`gru_sequence` computes the input side
``W_i x + b_i`` of every step in one product (autograd), then runs the recurrence in one
numba kernel (the gates fused into one loop, one matrix product per step) and
differentiates it by hand in another: one matrix product per step back, the recurrent
weights' gradient in one product over the sequence. The gates' e^x are taken a row at a time,
in float32 by :mod:`pioneer.vecmath` (in SIMD lanes, where numba calls libm once a value), and
the candidate state's tanh from the same e^x (:func:`_tanh_from_exp`: numba's own tanh took
16 ns a value, most of the recurrence's time). The result equals the loop of ``GRUCell`` to
float32 rounding (sums grouped differently; the tests compare both, with
``torch.autograd.gradcheck`` on the hand-written backward in float64). No ``fastmath`` but the
float32 e^x's ``contract``: a seeded run repeats bit for bit on one machine.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from numba import njit
from numpy.typing import NDArray
from torch import nn

from pioneer.vecmath import exp_where

__all__ = ["gru_sequence"]

F = NDArray[np.floating]


_TANH_SERIES = (1.0 / 3.0, 2.0 / 15.0, 17.0 / 315.0)  # tanh x = x (1 − x²/3 + 2x⁴/15 − 17x⁶/315 …)


def _tanh_constants(dtype: np.dtype[Any]) -> F:
    """:func:`_tanh_from_exp`'s ``c``: the series' coefficients and where it takes over —
    below 1/8 in float32 (its next term, 62x⁹/2835, is 10⁻⁹ relative there), 2⁻¹⁰ in
    float64."""
    return np.array([*_TANH_SERIES, 0.125 if dtype == np.float32 else 2.0**-10], dtype)


@njit(cache=True, inline="always")
def _tanh_from_exp(x: Any, e: Any, one: Any, c: F) -> Any:  # pragma: no cover - compiled
    """tanh x given e = e^{−2|x|}: (1 − e)/(1 + e) · sign x, and where |x| < ``c[3]`` (1 − e
    would cancel there) the series with coefficients ``c[:3]`` (:data:`_TANH_SERIES`; ``c`` in
    the arrays' dtype, :func:`_tanh_constants`). With libm's e^x within 4·10⁻⁷ relative of the
    exact value in float32 and 10⁻¹³ in float64, with :mod:`pioneer.vecmath`'s float32 e^x within
    6·10⁻⁷ (tested); numba's own ``np.tanh`` (libm's) took 16 ns a value."""
    t = math.copysign((one - e) / (one + e), x)
    x2 = x * x
    series = x * (one - x2 * (c[0] - x2 * (c[1] - x2 * c[2])))
    return series if abs(x) < c[3] else t  # both computed: a select, not a branch to mispredict


@njit(cache=True)
def _forward(
    gi: F,
    h0: F,
    keep: F,
    w_t: F,
    b: F,
    one: Any,
    tanh_c: F,
    vector: bool,
    hp: F,
    rz: F,
    n: F,
    ghn: F,
    hs: F,
) -> None:  # pragma: no cover - compiled
    """Fill ``hs`` (T, B, H) and what the backward pass needs: ``hp`` the state each step
    starts from (after its reset), ``rz`` the gates r, z (T, B, 2H), ``n`` and
    ``ghn = W_hn h + b_hn``. ``w_t`` is W_hhᵀ (H, 3H), contiguous; ``one`` is 1 and ``tanh_c``
    :func:`_tanh_from_exp`'s constants in the arrays' dtype (float32 arithmetic stays
    float32); ``vector``: the e^x of :mod:`pioneer.vecmath` (float32 only). The gates' e^x
    are taken a row of a step at a time, so that they can fill SIMD vectors."""
    t_len, batch, h3 = gi.shape
    hidden = h3 // 3
    h = h0.copy()
    ex = np.empty(2 * hidden, dtype=gi.dtype)  # a row's arguments of e^x, then its values
    shift = np.empty(2 * hidden, dtype=np.int32)
    x_n = np.empty(hidden, dtype=gi.dtype)
    for t in range(t_len):
        for i in range(batch):
            k = keep[t, i]
            for j in range(hidden):
                hp[t, i, j] = h[i, j] * k
        gh = np.dot(hp[t], w_t)
        for i in range(batch):
            for j in range(2 * hidden):
                ex[j] = -(gi[t, i, j] + (gh[i, j] + b[j]))
            exp_where(ex, None, ex, shift, 2 * hidden, vector)
            for j in range(2 * hidden):
                rz[t, i, j] = one / (one + ex[j])  # σ
            for j in range(hidden):
                g = gh[i, 2 * hidden + j] + b[2 * hidden + j]
                ghn[t, i, j] = g
                x = gi[t, i, 2 * hidden + j] + rz[t, i, j] * g
                x_n[j] = x
                a = abs(x)
                ex[j] = -(a + a)
            exp_where(ex, None, ex, shift, hidden, vector)
            for j in range(hidden):
                v_n = _tanh_from_exp(x_n[j], ex[j], one, tanh_c)
                n[t, i, j] = v_n
                v = v_n + rz[t, i, hidden + j] * (hp[t, i, j] - v_n)  # (1 − z) n + z h
                hs[t, i, j] = v
                h[i, j] = v


@njit(cache=True)
def _backward(
    dhs: F, keep: F, w: F, one: Any, hp: F, rz: F, n: F, ghn: F, dgi: F, dgh: F
) -> F:  # pragma: no cover - compiled
    """Fill ``dgi`` = ∂L/∂(W_ih x + b_ih) and ``dgh`` = ∂L/∂(W_hh h + b_hh) (T, B, 3H) from
    ``dhs`` = ∂L/∂h_t; return ∂L/∂h_0. ``w`` is W_hh (3H, H), contiguous."""
    t_len, batch, hidden = hp.shape
    dh = np.zeros((batch, hidden), dtype=hp.dtype)
    for t in range(t_len - 1, -1, -1):
        for i in range(batch):
            for j in range(hidden):
                d = dh[i, j] + dhs[t, i, j]
                r = rz[t, i, j]
                z = rz[t, i, hidden + j]
                v_n = n[t, i, j]
                dan = d * (one - z) * (one - v_n * v_n)  # through n's tanh
                dar = dan * ghn[t, i, j] * r * (one - r)  # through r's σ
                daz = d * (hp[t, i, j] - v_n) * z * (one - z)  # through z's σ
                dgi[t, i, j] = dar
                dgi[t, i, hidden + j] = daz
                dgi[t, i, 2 * hidden + j] = dan
                dgh[t, i, j] = dar
                dgh[t, i, hidden + j] = daz
                dgh[t, i, 2 * hidden + j] = dan * r
                dh[i, j] = d * z  # h_t's direct term z ⊙ h
        back = np.dot(dgh[t], w)
        for i in range(batch):
            k = keep[t, i]
            for j in range(hidden):
                dh[i, j] = (dh[i, j] + back[i, j]) * k
    return dh


class _GRUSequence(torch.autograd.Function):
    """``hs (T, B, H)`` from the input projections ``gi (T, B, 3H)``, the first state
    ``h0 (B, H)``, the masks ``keep (T, B)`` and the recurrent weights ``w_hh (3H, H)``,
    ``b_hh (3H,)``."""

    @staticmethod
    def forward(
        ctx: Any,
        gi: torch.Tensor,
        h0: torch.Tensor,
        keep: torch.Tensor,
        w_hh: torch.Tensor,
        b_hh: torch.Tensor,
    ) -> torch.Tensor:
        t_len, batch, h3 = gi.shape
        hidden = h3 // 3
        dtype = gi.detach().numpy().dtype
        hp, n, ghn, hs = (np.empty((t_len, batch, hidden), dtype) for _ in range(4))
        rz = np.empty((t_len, batch, 2 * hidden), dtype)
        w = w_hh.detach().numpy()
        _forward(
            np.ascontiguousarray(gi.detach().numpy()),
            np.ascontiguousarray(h0.detach().numpy()),
            np.ascontiguousarray(keep.numpy()),
            np.ascontiguousarray(w.T),
            b_hh.detach().numpy(),
            dtype.type(1.0),
            _tanh_constants(dtype),
            bool(dtype == np.float32),
            hp,
            rz,
            n,
            ghn,
            hs,
        )
        ctx.save_for_backward(keep, w_hh)
        ctx.arrays = (hp, rz, n, ghn)
        return torch.from_numpy(hs)

    @staticmethod
    def backward(
        ctx: Any, dhs: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, None, torch.Tensor, torch.Tensor]:
        keep, w_hh = ctx.saved_tensors
        hp, rz, n, ghn = ctx.arrays
        t_len, batch, hidden = hp.shape
        dgi = np.empty((t_len, batch, 3 * hidden), hp.dtype)
        dgh = np.empty_like(dgi)
        dh0 = _backward(
            np.ascontiguousarray(dhs.numpy()),
            np.ascontiguousarray(keep.numpy()),
            np.ascontiguousarray(w_hh.detach().numpy()),
            hp.dtype.type(1.0),
            hp,
            rz,
            n,
            ghn,
            dgi,
            dgh,
        )
        flat = torch.from_numpy(dgh).reshape(-1, 3 * hidden)
        dw = flat.t() @ torch.from_numpy(hp).reshape(-1, hidden)
        return torch.from_numpy(dgi), torch.from_numpy(dh0), None, dw, flat.sum(dim=0)


def gru_sequence(
    cell: nn.GRUCell, x: torch.Tensor, h0: torch.Tensor, keep: torch.Tensor
) -> torch.Tensor:
    """States ``(T, B, H)`` of ``cell`` run over inputs ``x (T, B, I)`` from ``h0 (B, H)``,
    the state multiplied by ``keep (T, B)`` before each step (0 resets it): the same as
    ``h = cell(x[t], h * keep[t, :, None])`` step by step, to rounding, with gradients to
    ``x``, ``h0`` and the cell's weights (CPU tensors)."""
    gi = torch.nn.functional.linear(x, cell.weight_ih, cell.bias_ih)
    out: torch.Tensor = _GRUSequence.apply(gi, h0, keep, cell.weight_hh, cell.bias_hh)
    return out
