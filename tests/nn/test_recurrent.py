"""The numba GRU over a sequence against its oracle, PyTorch's ``GRUCell`` run step by step."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from pioneer.nn.recurrent import gru_sequence


def _cell_loop(
    cell: nn.GRUCell, x: torch.Tensor, h0: torch.Tensor, keep: torch.Tensor
) -> torch.Tensor:
    h, hs = h0, []
    for t in range(x.shape[0]):
        h = cell(x[t], h * keep[t, :, None])
        hs.append(h)
    return torch.stack(hs)


def _case(dtype: torch.dtype, seed: int, t_len: int = 12, batch: int = 5, n_in: int = 7):
    gen = torch.Generator().manual_seed(seed)
    cell = nn.GRUCell(n_in, 6).to(dtype)
    with torch.no_grad():
        for p in cell.parameters():
            p.copy_(torch.randn(p.shape, generator=gen, dtype=dtype) * 0.5)
    x = torch.randn(t_len, batch, n_in, generator=gen, dtype=dtype, requires_grad=True)
    h0 = torch.randn(batch, 6, generator=gen, dtype=dtype, requires_grad=True)
    keep = (torch.rand(t_len, batch, generator=gen) > 0.25).to(dtype)  # resets mid-sequence
    keep[0, 0] = 0.0
    return cell, x, h0, keep


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_equals_the_cell_loop_with_resets_and_its_gradients(seed):
    cell, x, h0, keep = _case(torch.float64, seed)
    want = _cell_loop(cell, x, h0, keep)
    got = gru_sequence(cell, x, h0, keep)
    torch.testing.assert_close(got, want, rtol=0, atol=1e-12)
    upstream = torch.randn(
        want.shape, dtype=torch.float64, generator=torch.Generator().manual_seed(9)
    )
    inputs = [x, h0, *cell.parameters()]
    g_want = torch.autograd.grad((want * upstream).sum(), inputs)
    g_got = torch.autograd.grad((got * upstream).sum(), inputs)
    for a, b in zip(g_got, g_want, strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=1e-11)


def test_hand_written_backward_passes_gradcheck():
    """The numba backward against finite differences, for every input of the recurrence."""
    from pioneer.nn.recurrent import _GRUSequence

    gen = torch.Generator().manual_seed(3)
    t_len, batch, hidden = 6, 3, 4

    def rand(*shape: int) -> torch.Tensor:
        x = torch.randn(*shape, generator=gen, dtype=torch.float64) * 0.7
        return x.requires_grad_(True)

    keep = (torch.rand(t_len, batch, generator=gen) > 0.3).to(torch.float64)
    args = (rand(t_len, batch, 3 * hidden), rand(batch, hidden), keep)
    assert torch.autograd.gradcheck(
        _GRUSequence.apply, (*args, rand(3 * hidden, hidden), rand(3 * hidden))
    )


def test_float32_equals_the_cell_loop_to_rounding_and_repeats_bit_for_bit():
    cell, x, h0, keep = _case(torch.float32, 4, t_len=30, batch=8)
    got = gru_sequence(cell, x, h0, keep)
    torch.testing.assert_close(got, _cell_loop(cell, x, h0, keep), rtol=0, atol=1e-5)
    grads = torch.autograd.grad(got.sum(), [x, *cell.parameters()])
    again = gru_sequence(cell, x, h0, keep)
    assert torch.equal(again, got)
    for a, b in zip(torch.autograd.grad(again.sum(), [x, *cell.parameters()]), grads, strict=True):
        assert torch.equal(a, b)


@pytest.mark.parametrize(
    ("dtype", "vector", "rel"),
    [("float32", False, 4e-7), ("float32", True, 6e-7), ("float64", False, 1e-13)],
)
def test_tanh_from_one_exp_is_within_its_stated_error(dtype, vector, rel):
    """The recurrence's tanh (one e^x — libm's, or the float32 one in SIMD lanes — and a
    series near 0) against longdouble tanh, over normal values, the series' range and its
    edges, ±0, tiny and saturated inputs."""
    import numpy as np
    from numba import njit

    from pioneer.nn.recurrent import _tanh_constants, _tanh_from_exp
    from pioneer.vecmath import exp_where

    @njit
    def run(x, one, c, vec, out):
        e = np.empty_like(x)
        shift = np.empty(x.size, np.int32)
        for i in range(x.size):
            e[i] = -(abs(x[i]) + abs(x[i]))
        exp_where(e, None, e, shift, x.size, vec)
        for i in range(x.size):
            out[i] = _tanh_from_exp(x[i], e[i], one, c)

    dt = np.dtype(dtype)
    r = np.random.default_rng(0)
    edge = [0.0, -0.0, 1e-30, -1e-8, 0.125, -0.125, 2.0**-10, 20.0, -20.0, 100.0, -100.0]
    x = np.concatenate([r.standard_normal(50_000) * 3, r.uniform(-0.2, 0.2, 50_000), edge])
    x = x.astype(dt)
    x = np.concatenate([x, np.nextafter(x[-11:], dt.type(0.0))])
    out = np.empty_like(x)
    run(x, dt.type(1.0), _tanh_constants(dt), vector, out)
    exact = np.tanh(x.astype(np.longdouble))
    err = np.abs(out - exact) / np.maximum(np.abs(exact), np.finfo(dt).tiny)
    assert float(err.max()) <= rel
    assert np.array_equal(np.signbit(out), np.signbit(x))
