"""``pioneer.nn.layers``: layers drawn from an explicit generator, never the global RNG."""

from __future__ import annotations

import math

import pytest

torch = pytest.importorskip("torch")

from pioneer.nn.layers import seeded_linear  # noqa: E402


def test_the_same_generator_seed_gives_the_same_layer():
    a = seeded_linear(6, 4, torch.Generator().manual_seed(3))
    b = seeded_linear(6, 4, torch.Generator().manual_seed(3))
    c = seeded_linear(6, 4, torch.Generator().manual_seed(4))
    assert a.weight.shape == (4, 6) and a.bias.shape == (4,)
    assert torch.equal(a.weight, b.weight) and torch.equal(a.bias, b.bias)
    assert not torch.equal(a.weight, c.weight)


def test_the_global_rng_is_left_alone():
    torch.manual_seed(0)
    expected = torch.rand(3)
    torch.manual_seed(0)
    seeded_linear(8, 8, torch.Generator().manual_seed(1))
    assert torch.equal(torch.rand(3), expected)


def test_weights_within_pytorchs_default_bounds():
    layer = seeded_linear(50, 20, torch.Generator().manual_seed(0)).requires_grad_(False)
    bound = 1.0 / math.sqrt(50)  # kaiming_uniform with a = √5 gives the same bound
    assert float(layer.weight.abs().max()) <= bound
    assert float(layer.bias.abs().max()) <= bound
    assert bool(torch.isfinite(layer.weight).all())


def test_numpy_tanh_matches_torch_tanh_and_its_gradient():
    from pioneer.nn.layers import Tanh

    gen = torch.Generator().manual_seed(0)
    x = (torch.randn(7, 5, 9, generator=gen, dtype=torch.float64) * 3).requires_grad_(True)
    y = Tanh()(x)
    torch.testing.assert_close(y, torch.tanh(x), rtol=0, atol=1e-15)
    up = torch.randn(y.shape, generator=gen, dtype=torch.float64)
    (g,) = torch.autograd.grad((y * up).sum(), x)
    (want,) = torch.autograd.grad((torch.tanh(x) * up).sum(), x)
    torch.testing.assert_close(g, want, rtol=0, atol=1e-14)
    assert torch.autograd.gradcheck(Tanh(), (x[:2, :2, :3].detach().requires_grad_(True),))
    x32 = x.detach().to(torch.float32)[:, ::2]  # a strided view
    y32 = Tanh()(x32)
    assert y32.dtype == torch.float32
    torch.testing.assert_close(y32, torch.tanh(x32), rtol=0, atol=2e-7)
