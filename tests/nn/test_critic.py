"""The value network and the distributional pieces: quantile levels, the quantile Huber loss
(by hand, and its minimiser against NumPy's empirical quantiles) and CVaR read from quantiles
(against a brute-force oracle of equal atoms)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pioneer.nn.critic import Critic, lower_tail_mean, quantile_huber, quantile_levels


def test_quantile_levels_are_the_midpoints() -> None:
    assert torch.allclose(quantile_levels(4), torch.tensor([0.125, 0.375, 0.625, 0.875]))


def test_the_critic_gives_a_value_or_quantiles_per_row() -> None:
    x = torch.zeros(5, 3)
    one = Critic(3, (8,), torch.Generator().manual_seed(0))
    many = Critic(3, (8,), torch.Generator().manual_seed(0), n_out=6)
    assert one(x).shape == (5,) and many(x).shape == (5, 6)
    # the hidden layers are drawn alike: only the output layer's width differs
    assert torch.equal(one.state_dict()["net.0.weight"], many.state_dict()["net.0.weight"])


def test_the_quantile_huber_loss_by_hand() -> None:
    pred = torch.tensor([[0.0, 2.0]])  # levels 0.25, 0.75
    target = torch.tensor([0.5])
    # u = 0.5 (≥ 0): weight 0.25, Huber 0.125; u = −1.5 (< 0): weight |0.75 − 1| = 0.25,
    # Huber 1.5 − 0.5 = 1.0 (κ = 1)
    expected = (0.25 * 0.125 + 0.25 * 1.0) / 2
    assert float(quantile_huber(pred, target)) == pytest.approx(expected)


def test_the_loss_is_minimised_by_the_targets_quantiles() -> None:
    rng = np.random.default_rng(4)
    sample = rng.gamma(2.0, 1.5, size=4000)  # skewed, so mean ≠ median
    target = torch.from_numpy(sample).to(torch.float32)
    n = 5
    pred = torch.zeros(1, n, requires_grad=True)
    opt = torch.optim.Adam([pred], lr=0.05)
    for _ in range(1500):
        loss = quantile_huber(pred.expand(len(target), n), target, kappa=0.01)
        opt.zero_grad()
        loss.backward()
        opt.step()
    want = np.quantile(sample, quantile_levels(n).numpy().astype(np.float64))
    np.testing.assert_allclose(pred.detach().numpy()[0], want, atol=0.05)


@settings(max_examples=60, deadline=None)
@given(
    values=st.lists(st.floats(-50, 50, allow_nan=False), min_size=2, max_size=12),
    k=st.integers(1, 40),
)
def test_cvar_equals_the_mean_of_the_lowest_atoms(values: list[float], k: int) -> None:
    n, m = len(values), 40  # each quantile as m equal atoms; α a multiple of 1/(n m)
    alpha = min(1.0, k * (n + 1) / (n * m))
    atoms = np.sort(np.repeat(np.asarray(values), m))
    lowest = round(alpha * n * m)
    want = atoms[:lowest].mean()
    q = torch.tensor(values, dtype=torch.float64)[torch.randperm(n)]  # order does not matter
    got = float(lower_tail_mean(q, alpha))
    assert got == pytest.approx(want, rel=1e-9, abs=1e-9)


def test_cvar_at_one_is_the_mean_and_falls_with_alpha() -> None:
    q = torch.tensor([[3.0, -1.0, 7.0, 1.0]])
    assert float(lower_tail_mean(q, 1.0)) == pytest.approx(2.5)
    assert float(lower_tail_mean(q, 0.25)) == pytest.approx(-1.0)
    assert float(lower_tail_mean(q, 0.5)) == pytest.approx(0.0)
    with pytest.raises(ValueError, match="alpha"):
        lower_tail_mean(q, 0.0)
