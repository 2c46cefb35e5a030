"""The numba attention blocks against their oracle, the same formulas in PyTorch operators
(the form CrowdNav++'s network had before), with ``gradcheck`` on the hand-written backward."""

from __future__ import annotations

import math

import pytest

torch = pytest.importorskip("torch")

from pioneer.nn.attention import node_attention, pool_attention  # noqa: E402


def _masked_softmax(scores: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    s = scores.masked_fill(~mask, -math.inf)
    top = s.amax(dim=-1, keepdim=True)
    top = torch.where(torch.isfinite(top), top, torch.zeros_like(top))
    e = torch.exp(s - top) * mask
    return e / e.sum(dim=-1, keepdim=True).clamp_min(1e-30)


def _node_oracle(qkv, s, mask, scale):
    q, k, v = qkv.chunk(3, dim=-1)
    a = _masked_softmax(torch.einsum("mie,mje->mij", q, k) * scale, mask.unsqueeze(-2))
    return torch.relu(s + torch.einsum("mij,mje->mie", a, v)) * mask.unsqueeze(-1), a


def _pool_oracle(keys, query, values, mask, scale):
    a = _masked_softmax(torch.einsum("mie,me->mi", keys, query) * scale, mask)
    return (a.unsqueeze(-1) * values).sum(dim=-2), a


def _mask(gen: torch.Generator, m: int, n: int) -> torch.Tensor:
    mask = torch.rand(m, n, generator=gen) > 0.3
    mask[0] = False  # a sample with no node: all-zero weights, no NaN
    mask[1] = True
    mask[2] = False
    mask[2, 1] = True  # one node alone
    return mask


def _rand(gen: torch.Generator, dtype: torch.dtype, *shape: int) -> torch.Tensor:
    return torch.randn(*shape, generator=gen, dtype=dtype).requires_grad_(True)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_node_attention_equals_the_operator_form_and_its_gradients(seed):
    gen = torch.Generator().manual_seed(seed)
    m, n, e = 9, 4, 5
    qkv, s = _rand(gen, torch.float64, m, n, 3 * e), _rand(gen, torch.float64, m, n, e)
    mask = _mask(gen, m, n)
    got, a_got = node_attention(qkv, s, mask, 0.4)
    want, a_want = _node_oracle(qkv, s, mask, 0.4)
    torch.testing.assert_close(got, want, rtol=0, atol=1e-13)
    torch.testing.assert_close(a_got, a_want, rtol=0, atol=1e-13)
    assert not a_got.requires_grad
    assert torch.all(got[0] == 0) and torch.all(a_got[0] == 0)
    up = torch.randn(got.shape, generator=gen, dtype=torch.float64)
    for g, w in zip(
        torch.autograd.grad((got * up).sum(), [qkv, s]),
        torch.autograd.grad((want * up).sum(), [qkv, s]),
        strict=True,
    ):
        torch.testing.assert_close(g, w, rtol=0, atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pool_attention_equals_the_operator_form_and_its_gradients(seed):
    gen = torch.Generator().manual_seed(seed)
    m, n, e = 9, 4, 5
    keys, values = _rand(gen, torch.float64, m, n, e), _rand(gen, torch.float64, m, n, e)
    query = _rand(gen, torch.float64, m, e)
    mask = _mask(gen, m, n)
    got, a_got = pool_attention(keys, query, values, mask, 0.4)
    want, a_want = _pool_oracle(keys, query, values, mask, 0.4)
    torch.testing.assert_close(got, want, rtol=0, atol=1e-13)
    torch.testing.assert_close(a_got, a_want, rtol=0, atol=1e-13)
    assert torch.all(got[0] == 0)
    up = torch.randn(got.shape, generator=gen, dtype=torch.float64)
    inputs = [keys, query, values]
    for g, w in zip(
        torch.autograd.grad((got * up).sum(), inputs),
        torch.autograd.grad((want * up).sum(), inputs),
        strict=True,
    ):
        torch.testing.assert_close(g, w, rtol=0, atol=1e-12)


def test_hand_written_backwards_pass_gradcheck():
    """Against finite differences, masked nodes and an empty sample included."""
    gen = torch.Generator().manual_seed(5)
    m, n, e = 5, 3, 4
    mask = _mask(gen, m, n)
    qkv, s = _rand(gen, torch.float64, m, n, 3 * e), _rand(gen, torch.float64, m, n, e)
    assert torch.autograd.gradcheck(lambda a, b: node_attention(a, b, mask, 0.7)[0], (qkv, s))
    keys, values = _rand(gen, torch.float64, m, n, e), _rand(gen, torch.float64, m, n, e)
    query = _rand(gen, torch.float64, m, e)
    assert torch.autograd.gradcheck(
        lambda k, q, v: pool_attention(k, q, v, mask, 0.7)[0], (keys, query, values)
    )


def test_float32_to_rounding_and_repeats_bit_for_bit():
    gen = torch.Generator().manual_seed(7)
    m, n, e = 64, 3, 64  # CrowdNav++'s sizes
    qkv, s = _rand(gen, torch.float32, m, n, 3 * e), _rand(gen, torch.float32, m, n, e)
    mask = _mask(gen, m, n)
    scale = 1.0 / math.sqrt(e)
    out, a = node_attention(qkv, s, mask, scale)
    assert out.dtype == a.dtype == torch.float32
    want, _ = _node_oracle(qkv, s, mask, scale)
    torch.testing.assert_close(out, want, rtol=0, atol=1e-5)
    query = _rand(gen, torch.float32, m, e)
    c, _ = pool_attention(out, query, out, mask, scale)
    c_want, _ = _pool_oracle(want, query, want, mask, scale)
    torch.testing.assert_close(c, c_want, rtol=0, atol=1e-5)
    grads = torch.autograd.grad(c.sum(), [qkv, s, query])
    out2, _ = node_attention(qkv, s, mask, scale)
    c2, _ = pool_attention(out2, query, out2, mask, scale)
    assert torch.equal(c2, c)
    for g2, g in zip(torch.autograd.grad(c2.sum(), [qkv, s, query]), grads, strict=True):
        assert torch.equal(g2, g)


def test_a_backward_after_an_in_place_change_is_refused():
    """What the backward pass reads is saved as tensors: autograd notices an in-place change."""
    gen = torch.Generator().manual_seed(8)
    qkv, s = _rand(gen, torch.float32, 4, 3, 6), _rand(gen, torch.float32, 4, 3, 2)
    mask = torch.ones(4, 3, dtype=torch.bool)
    out, a = node_attention(qkv * 1.0, s * 1.0, mask, 0.5)
    a.mul_(2.0)  # the weights the backward pass would use
    with pytest.raises(RuntimeError, match="modified by an inplace operation"):
        out.sum().backward()
    keys = _rand(gen, torch.float32, 4, 3, 2)
    values = keys * 1.0
    c, _ = pool_attention(keys, _rand(gen, torch.float32, 4, 2), values, mask, 0.5)
    values.add_(1.0)
    with pytest.raises(RuntimeError, match="modified by an inplace operation"):
        c.sum().backward()


def test_numpy_masked_softmax_equals_the_compiled_rows():
    """:func:`masked_softmax` (NumPy, CrowdNav++'s acting step) against the compiled loops'
    row softmax, row by row: float32 rounding apart (e^x from other libraries), exact zeros
    where masked and for a row with no unmasked entry."""
    import numpy as np
    from numba import njit

    from pioneer.nn.attention import _softmax_row, masked_softmax

    @njit
    def rows(scores, mask, out):
        zero = scores[0, 0] - scores[0, 0]
        for m in range(scores.shape[0]):
            _softmax_row(scores[m], mask[m], zero, out[m])

    rng = np.random.default_rng(3)
    scores = (rng.standard_normal((64, 6)) * 4).astype(np.float32)
    mask = rng.random((64, 6)) > 0.4
    mask[0] = False
    mask[1] = True
    want = np.empty_like(scores)
    rows(scores, mask, want)
    got = masked_softmax(scores, mask)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got[~mask], 0.0)
    np.testing.assert_array_equal(got[0], 0.0)
    np.testing.assert_allclose(got, want, rtol=2e-6, atol=1e-7)
