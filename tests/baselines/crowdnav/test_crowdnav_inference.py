"""CrowdNav++'s acting step in NumPy against the module's own forward (the reference): the
same means, attention and GRU states to float32 rounding, step by step along episodes, for a
fresh network and the shipped weights; the policy with either forward; bad settings refused."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pioneer.baselines.crowdnav.inference import CrowdNavInference
from pioneer.baselines.crowdnav.network import CrowdNavConfig, CrowdNavNet, load_crowdnav
from pioneer.baselines.crowdnav.observation import build_observation, obs_tensors
from pioneer.baselines.crowdnav.policy import CrowdNavPolicy
from pioneer.control.registry import build_policy
from pioneer.data import shipped_crowdnav_weights
from pioneer.envs.env import NavEnv
from pioneer.envs.episode import Episode
from pioneer.errors import ConfigError
from pioneer.eval.episode import run_episode
from pioneer_testutils import assert_house_message

# float32 products and e^x / tanh from other libraries: a few units in the last place of
# values of order 1, through 10 layers (measured: ≤ 3e-6 on the shipped weights' episodes).
ATOL = 2e-5


def _reference_step(model: CrowdNavNet, obs, h):
    with torch.inference_mode():
        x, a_rh, _ = model.encode(*obs_tensors(obs))
        h_new = model.gru(x, torch.from_numpy(h))
        mean, _ = model.heads(h_new)
    return mean.numpy(), a_rh.numpy(), h_new.numpy()


def _compare_along_episode(model: CrowdNavNet, scenario: str, seed: int) -> int:
    """Drive ``model`` (torch) for one episode; at every step the NumPy step from the same
    observation and GRU state must give the same outputs. Returns the steps compared."""
    fast = CrowdNavInference(model)
    policy = CrowdNavPolicy(model, forward="torch")
    steps = 0

    def act(obs, info):
        nonlocal steps
        o = build_observation(info["state"], info["world"], model.config)
        h = policy.h.copy()
        want = _reference_step(model, o, h)
        got = fast.step(o, h)
        for g, w in zip(got, want, strict=True):
            assert g.dtype == np.float32 and g.shape == w.shape
            np.testing.assert_allclose(g, w, rtol=0, atol=ATOL)
        steps += 1
        return CrowdNavPolicy.act(policy, obs, info)

    policy.act = act  # type: ignore[method-assign]
    Episode(NavEnv(scenario), policy, seed).run(lambda step: None)
    return steps


def test_numpy_step_equals_the_module_for_a_fresh_network():
    model = CrowdNavNet(CrowdNavConfig(max_humans=3), seed=6)
    assert _compare_along_episode(model, "hr-rl", seed=3) > 10


@pytest.mark.parametrize("scenario", ["hr-rl", "hl-rr"])
def test_numpy_step_equals_the_module_for_the_shipped_weights(scenario):
    model = load_crowdnav(shipped_crowdnav_weights(scenario))
    assert _compare_along_episode(model, scenario, seed=21) > 10


def test_a_training_rollouts_step_equals_the_module_with_the_value():
    """:meth:`CrowdNavInference.act`, the trainer's acting step for a batch of worlds: the
    module's mean, value and GRU state (``encode``, ``gru``, ``heads``) to float32 rounding."""
    model = CrowdNavNet(CrowdNavConfig(max_humans=3), seed=4)
    with torch.no_grad():  # a critic whose values are not ≈ 0
        for p in model.parameters():
            p.add_(0.1 * torch.randn(p.shape, generator=torch.Generator().manual_seed(p.numel())))
    env = NavEnv("hr-rl")
    infos = [env.reset(seed=s)[1] for s in range(5)]
    obs = [build_observation(i["state"], i["world"], model.config) for i in infos]
    batch = type(obs[0])(*(np.concatenate(parts) for parts in zip(*obs, strict=True)))
    h = np.random.default_rng(1).normal(size=(5, model.config.hidden)).astype(np.float32)
    mean, value, h_new = CrowdNavInference(model).act(batch, h)
    with torch.inference_mode():
        x, _, _ = model.encode(*obs_tensors(batch))
        h_ref = model.gru(x, torch.from_numpy(h))
        mean_ref, value_ref = model.heads(h_ref)
    assert mean.shape == (5, 2) and value.shape == (5,) and h_new.shape == h.shape
    for got, want in ((mean, mean_ref), (value, value_ref), (h_new, h_ref)):
        assert got.dtype == np.float32
        np.testing.assert_allclose(got, want.numpy(), rtol=0, atol=ATOL)
    assert np.ptp(value) > 1e-3  # the critic sees the worlds apart


def test_masked_rows_and_an_empty_scene():
    """No human in range: the attention rows are all zero, as the module's, and padded slots
    never change the result."""
    model = CrowdNavNet(CrowdNavConfig(max_humans=4), seed=2)
    env = NavEnv("hr-rl")
    _, info = env.reset(seed=5)
    obs = build_observation(info["state"], info["world"], model.config)
    h = np.random.default_rng(0).normal(size=(1, model.config.hidden)).astype(np.float32)
    empty = obs._replace(mask=np.zeros_like(obs.mask), spatial=np.zeros_like(obs.spatial))
    mean, a_rh, h_new = CrowdNavInference(model).step(empty, h)
    assert not a_rh.any()
    want = _reference_step(model, empty, h)
    np.testing.assert_allclose(mean, want[0], rtol=0, atol=ATOL)
    np.testing.assert_allclose(h_new, want[2], rtol=0, atol=ATOL)
    junk = obs._replace(spatial=np.where(obs.mask[..., None], obs.spatial, 99.0).astype(np.float32))
    a = CrowdNavInference(model).step(obs, h)
    b = CrowdNavInference(model).step(junk, h)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)


def test_both_forwards_drive_alike_and_each_repeats_itself():
    fast = build_policy("crowdnav++", "hr-rl")
    ref = build_policy("crowdnav++", "hr-rl", forward="torch")
    assert fast.forward == "numpy" and ref.forward == "torch"
    a, _ = run_episode("hr-rl", fast, seed=8)
    b, _ = run_episode("hr-rl", ref, seed=8)
    assert run_episode("hr-rl", fast, seed=8)[0] == a
    assert run_episode("hr-rl", ref, seed=8)[0] == b
    assert a.event == b.event
    assert abs(a.path_length_m - b.path_length_m) < 1e-3
    assert fast.attention.dtype == np.float32


def test_an_unknown_forward_is_refused():
    with pytest.raises(ConfigError) as e:
        CrowdNavPolicy(CrowdNavNet(), forward="jax")  # type: ignore[arg-type]
    assert_house_message(str(e.value), "forward", "jax")
