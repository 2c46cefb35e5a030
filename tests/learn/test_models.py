"""Student networks: MDN likelihood, uncertainty decomposition, training, checkpoints, policy."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from pioneer.control.registry import build_policy, policy_names
from pioneer.deploy.mixture import mixture_action, mixture_uncertainty
from pioneer.errors import ConfigError, DataError
from pioneer.learn import (
    MDN,
    MLPStudent,
    StudentConfig,
    StudentPolicy,
    build_student,
    load_student,
    read_checkpoint_meta,
    save_student,
    train_student,
    uncertainty,
)
from pioneer_testutils import assert_house_message

torch.set_num_threads(1)

SD = 0.05  # label noise of the bimodal toy [m/s]
OBS0 = np.linspace(0.5, 3.0, 29, dtype=np.float32)  # one fixed observation


def bimodal(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Action = (±1, 0) with equal probability, plus N(0, SD²) noise; independent of obs."""
    s = rng.choice([-1.0, 1.0], size=n)
    a = np.stack([s, np.zeros(n)], axis=1) + SD * rng.normal(size=(n, 2))
    return np.tile(OBS0, (n, 1)), a.astype(np.float32)


def true_nll(a: np.ndarray) -> float:
    """−mean log p(a) under the data-generating mixture (the optimum any model can reach)."""
    a = a.astype(np.float64)
    log_norm = -math.log(SD) - 0.5 * math.log(2.0 * math.pi)
    lp1 = -0.5 * (a[:, 1] / SD) ** 2 + log_norm
    lp0 = (
        np.logaddexp(-0.5 * ((a[:, 0] - 1) / SD) ** 2, -0.5 * ((a[:, 0] + 1) / SD) ** 2)
        + math.log(0.5)
        + log_norm
    )
    return float(-(lp0 + lp1).mean())


def random_obs(rng: np.random.Generator, n: int) -> np.ndarray:
    return (rng.normal(size=(n, 29)) * 2.0).astype(np.float32)


def perturbed_mdn(k: int = 10, seed: int = 0) -> MDN:
    """An untrained MDN with spread-out heads, so the mixture is far from degenerate."""
    m = MDN(StudentConfig(n_components=k), seed=seed)
    gen = torch.Generator().manual_seed(seed + 100)
    with torch.no_grad():
        for head in (m.logits_head, m.mu_head, m.sigma_head):
            head.bias.copy_(torch.randn(head.bias.shape, generator=gen) * 1.5)
    return m


@pytest.fixture(scope="module")
def trained_pair() -> tuple[MDN, MLPStudent, np.ndarray]:
    rng = np.random.default_rng(7)
    x = random_obs(rng, 300)
    y = np.stack([np.tanh(x[:, 0]), 0.5 * np.sin(x[:, 1])], axis=1).astype(np.float32)
    mdn = MDN(seed=1)
    mlp = MLPStudent(seed=2)
    train_student(mdn, x, y, epochs=3, seed=3)
    train_student(mlp, x, y, epochs=3, seed=3)
    return mdn, mlp, x


# ------------------------------------------------------------------------- config and shapes
def test_config_defaults_match_spec():
    cfg = StudentConfig()
    assert (cfg.kind, cfg.obs_dim, cfg.hidden, cfg.dropout, cfg.n_components) == (
        "mdn",
        29,
        (128, 128),
        0.1,
        10,
    )
    assert cfg.action_mode == "mode"
    assert StudentConfig.from_dict(cfg.to_dict()) == cfg


@pytest.mark.parametrize(
    ("changes", "needle"),
    [
        ({"kind": "gp"}, "kind"),
        ({"action_mode": "median"}, "action_mode"),
        ({"n_components": 0}, "n_components"),
        ({"hidden": ()}, "hidden"),
        ({"dropout": 1.0}, "dropout"),
        ({"sigma_floor": -1.0}, "sigma_floor"),
        ({"nll_beta": -0.5}, "nll_beta"),
        ({"nll_beta": 1.5}, "nll_beta"),
    ],
)
def test_config_rejects_bad_values(changes, needle):
    with pytest.raises(ConfigError) as err:
        StudentConfig(**changes)
    assert_house_message(str(err.value), needle)


def test_mdn_shapes_and_positive_sigma(rng):
    m = perturbed_mdn()
    logits, mu, sigma = m(torch.from_numpy(random_obs(rng, 5)))
    assert logits.shape == (5, 10) and mu.shape == (5, 10, 2) and sigma.shape == (5, 10, 2)
    assert bool((sigma >= m.config.sigma_floor).all())
    assert m.deterministic_action(torch.from_numpy(random_obs(rng, 5))).shape == (5, 2)
    assert not m.training  # built in eval mode: dropout off for inference


def test_construction_is_seeded_and_leaves_global_rng_alone():
    state = torch.get_rng_state()
    a, b, c = MDN(seed=4), MDN(seed=4), MDN(seed=5)
    assert torch.equal(torch.get_rng_state(), state)
    for (ka, va), vb in zip(a.state_dict().items(), b.state_dict().values(), strict=True):
        assert torch.equal(va, vb), ka
    assert not torch.equal(a.mu_head.weight, c.mu_head.weight)


def test_nll_matches_direct_mixture_density(rng):
    m = perturbed_mdn(k=3)
    x = torch.from_numpy(random_obs(rng, 4))
    a = torch.from_numpy(rng.normal(size=(4, 2)).astype(np.float32))
    with torch.no_grad():
        logits, mu, sigma = (t.double() for t in m(x))
        pi = torch.softmax(logits, -1)
        dens = torch.exp(-0.5 * (((a.double()[:, None] - mu) / sigma) ** 2).sum(-1)) / (
            2 * math.pi * sigma.prod(-1)
        )
        expected = -torch.log((pi * dens).sum(-1)).mean()
        assert float(m.nll(x, a)) == pytest.approx(float(expected), rel=1e-5)


def test_nll_is_stable_far_from_every_component(rng):
    m = perturbed_mdn()
    x = torch.from_numpy(random_obs(rng, 3))
    far = torch.full((3, 2), 1e4)
    loss = m.nll(x, far)
    assert torch.isfinite(loss) and float(loss.detach()) > 1e6
    loss.backward()
    assert all(torch.isfinite(p.grad).all() for p in m.parameters() if p.grad is not None)


def _standardised_total_variance(m: MDN, x: torch.Tensor) -> torch.Tensor:
    """Trace of the mixture covariance in standardised action units, from its definition."""
    logits, mu, sigma = (t.double() for t in m(x))
    std = m.act_std.double()
    pi = torch.softmax(logits, -1)
    z_mu, z_sigma = mu / std, sigma / std
    mbar = (pi[..., None] * z_mu).sum(1, keepdim=True)
    per_k = (z_sigma**2).sum(-1) + ((z_mu - mbar) ** 2).sum(-1)
    return (pi * per_k).sum(-1)


@pytest.mark.parametrize("beta", [0.5, 1.0])
def test_beta_nll_weights_each_frame_by_its_detached_total_variance(rng, beta):
    """β-NLL (Seitzer et al., ICLR 2022): −mean(w_i log p_i), w_i ∝ Var_i^β with mean 1 and no
    gradient through w — brute force against the mixture's own definition."""
    m = perturbed_mdn(k=3)
    m.config = StudentConfig(n_components=3, nll_beta=beta)
    x = torch.from_numpy(random_obs(rng, 16))
    a = torch.from_numpy(rng.normal(size=(16, 2)).astype(np.float32))
    with torch.no_grad():
        v = _standardised_total_variance(m, x) ** beta
        w = (v / v.mean()).float()
    expected = -(w * m.log_prob(x, a)).mean()
    got = m.loss(x, a)
    assert float(got.detach()) == pytest.approx(float(expected.detach()), rel=1e-5)
    # The weights matter:
    assert float(got.detach()) != pytest.approx(float(m.nll(x, a).detach()), rel=1e-3)
    g_got = torch.autograd.grad(got, list(m.parameters()), allow_unused=True)
    g_exp = torch.autograd.grad(expected, list(m.parameters()), allow_unused=True)
    for p, q in zip(g_got, g_exp, strict=True):
        if p is None or q is None:
            assert p is None and q is None
        else:
            torch.testing.assert_close(p, q, rtol=1e-4, atol=1e-6)


def test_beta_nll_is_the_nll_when_beta_is_zero_or_the_variance_constant(rng):
    m = perturbed_mdn(k=3)
    x = torch.from_numpy(random_obs(rng, 8))
    a = torch.from_numpy(rng.normal(size=(8, 2)).astype(np.float32))
    assert m.config.nll_beta == 0.0
    with torch.no_grad():
        assert float(m.loss(x, a)) == float(m.nll(x, a))
    m.config = StudentConfig(n_components=3, nll_beta=1.0)
    same = x[:1].expand(8, -1)  # one observation → one variance → all weights 1
    with torch.no_grad():
        assert float(m.loss(same, a)) == pytest.approx(float(m.nll(same, a)), rel=1e-6)


# ------------------------------------------------------------------------- bimodal toy
def test_mdn_reaches_the_optimal_nll_on_a_bimodal_toy():
    rng = np.random.default_rng(11)
    x, y = bimodal(rng, 2048)
    # Dropout off: on a constant input it only blurs the mixture; this test is about the head.
    m = MDN(StudentConfig(dropout=0.0), seed=0)
    hist = train_student(m, x, y, epochs=40, seed=0)  # 320 Adam steps
    assert hist[-1] < hist[0]
    xt, yt = bimodal(rng, 4000)
    with torch.no_grad():
        nll = float(m.nll(torch.from_numpy(xt), torch.from_numpy(yt)))
    optimum = true_nll(yt)  # ≈ log 2 + log(2πe SD²) = −2.46 nats
    assert optimum == pytest.approx(math.log(2) + math.log(2 * math.pi * math.e * SD**2), abs=0.05)
    assert optimum - 0.01 < nll < optimum + 0.03
    # The mode picks one of the two manoeuvres; the mixture mean averages them to ≈ 0.
    with torch.no_grad():
        mode = m.deterministic_action(torch.from_numpy(xt[:1]))[0].numpy()
        mean = m.deterministic_action(torch.from_numpy(xt[:1]), mode="mean")[0].numpy()
        ale, epi = m.uncertainty(torch.from_numpy(xt[:1]))
    assert abs(abs(mode[0]) - 1.0) < 0.05 and abs(mode[1]) < 0.05
    assert abs(mean[0]) < 0.15
    # Total variance = 1 (the ±1 split, epistemic) + 2 SD² (the noise, mostly aleatoric: the
    # split inside one mode between several close components is not identifiable).
    assert float(ale[0] + epi[0]) == pytest.approx(1.0 + 2 * SD**2, rel=0.05)
    assert float(epi[0]) == pytest.approx(1.0, abs=0.05)
    assert SD**2 < float(ale[0]) < 4 * SD**2


def test_mlp_averages_the_two_modes():
    rng = np.random.default_rng(12)
    x, y = bimodal(rng, 1024)
    m = MLPStudent(StudentConfig(kind="mlp", dropout=0.0), seed=0)
    hist = train_student(m, x, y, epochs=40, seed=0)
    assert hist[-1] == pytest.approx(1.0, abs=0.05)  # standardised MSE of the best constant
    with torch.no_grad():
        a = m.deterministic_action(torch.from_numpy(x[:1]))[0].numpy()
    assert abs(a[0]) < 0.15 and abs(a[1]) < 0.05


# ------------------------------------------------------------------------- uncertainty
def test_uncertainty_equals_monte_carlo_total_variance(rng):
    m = perturbed_mdn(seed=3)
    x = torch.from_numpy(random_obs(rng, 4))
    with torch.no_grad():
        logits, mu, sigma = m(x)
        ale, epi = uncertainty(logits, mu, sigma)
    pi = torch.softmax(logits.double(), -1).numpy()
    n = 200_000
    for i in range(4):
        k = rng.choice(pi.shape[1], size=n, p=pi[i] / pi[i].sum())
        samples = mu[i].numpy()[k] + sigma[i].numpy()[k] * rng.normal(size=(n, 2))
        total_mc = float(samples.var(axis=0).sum())
        assert float(ale[i] + epi[i]) == pytest.approx(total_mc, rel=0.02)
        assert float(ale[i]) > 0 and float(epi[i]) > 0


def test_single_component_has_zero_epistemic(rng):
    m = perturbed_mdn(k=1)
    with torch.no_grad():
        ale, epi = m.uncertainty(torch.from_numpy(random_obs(rng, 6)))
    assert torch.all(epi == 0.0)
    assert torch.all(ale > 0.0)


def test_numpy_twin_matches_torch(rng):
    m = perturbed_mdn(seed=5)
    x = torch.from_numpy(random_obs(rng, 16))
    with torch.no_grad():
        logits, mu, sigma = m(x)
        ale, epi = uncertainty(logits, mu, sigma)
        mode = m.deterministic_action(x, "mode")
        mean = m.deterministic_action(x, "mean")
    ale_np, epi_np = mixture_uncertainty(logits.numpy(), mu.numpy(), sigma.numpy())
    np.testing.assert_allclose(ale_np, ale.numpy(), rtol=1e-5)
    np.testing.assert_allclose(epi_np, epi.numpy(), rtol=1e-5)
    np.testing.assert_allclose(mixture_action(logits.numpy(), mu.numpy()), mode.numpy())
    np.testing.assert_allclose(
        mixture_action(logits.numpy(), mu.numpy(), "mean"), mean.numpy(), rtol=1e-5, atol=1e-6
    )
    with pytest.raises(ConfigError):
        mixture_action(logits.numpy(), mu.numpy(), "median")


# ------------------------------------------------------------------------- training
def test_training_is_seeded_and_leaves_global_rng_alone(rng):
    x = random_obs(rng, 200)
    y = rng.normal(size=(200, 2)).astype(np.float32)
    state = torch.get_rng_state()
    runs = []
    for _ in range(2):
        m = MDN(seed=0)
        hist = train_student(m, x, y, epochs=2, batch=64, seed=9)
        runs.append((hist, m.state_dict()))
        assert not m.training
    assert torch.equal(torch.get_rng_state(), state)
    assert runs[0][0] == runs[1][0]
    for k, v in runs[0][1].items():
        assert torch.equal(v, runs[1][1][k]), k
    other = MDN(seed=0)
    assert train_student(other, x, y, epochs=2, batch=64, seed=10) != runs[0][0]


def test_training_fits_the_normalizer_and_reports_progress(rng):
    x = random_obs(rng, 100) + 5.0
    y = (rng.normal(size=(100, 2)) * [0.2, 0.1] + [0.4, 0.0]).astype(np.float32)
    seen: list[tuple[int, float]] = []
    m = build_student(StudentConfig(kind="mlp"))
    train_student(m, x, y, epochs=3, progress=lambda e, loss: seen.append((e, loss)))
    assert [e for e, _ in seen] == [0, 1, 2]
    np.testing.assert_allclose(m.obs_mean.numpy(), x.mean(0), rtol=1e-4)
    np.testing.assert_allclose(m.act_std.numpy(), y.std(0), rtol=1e-4)


@pytest.mark.parametrize(
    ("obs", "act", "needle"),
    [
        (np.zeros((5, 28)), np.zeros((5, 2)), "obs"),
        (np.zeros((5, 29)), np.zeros((4, 2)), "rows"),
        (np.zeros((5, 29)), np.full((5, 2), np.nan), "finite"),
    ],
)
def test_training_rejects_bad_data(obs, act, needle):
    with pytest.raises(DataError) as err:
        train_student(MDN(), obs, act, epochs=1)
    assert_house_message(str(err.value), needle)


# ------------------------------------------------------------------------- checkpoints
@pytest.mark.parametrize("which", [0, 1])
def test_checkpoint_round_trip_is_exact(tmp_path, trained_pair, which):
    model, x = trained_pair[which], torch.from_numpy(trained_pair[2])
    path = save_student(model, tmp_path / "s.safetensors", info={"epochs": 3})
    back = load_student(path)
    assert type(back) is type(model) and back.config == model.config and not back.training
    with torch.no_grad():
        a, b = model(x), back(x)
    pairs = zip(a, b, strict=True) if isinstance(a, tuple) else [(a, b)]
    for ta, tb in pairs:
        assert torch.equal(ta, tb)
    meta = read_checkpoint_meta(path)
    assert meta["info"] == {"epochs": 3} and meta["config"]["kind"] == model.kind
    assert b"pickle" not in path.read_bytes()[:16]
    assert not list(tmp_path.glob(".s.safetensors*"))  # no temporary file left behind
    from safetensors import safe_open

    with safe_open(str(path), framework="pt") as fh:  # where the weights were made
        assert fh.metadata()["torch_cpu_capability"] == torch.backends.cpu.get_cpu_capability()


def test_corrupt_or_mismatched_checkpoints_are_refused(tmp_path, trained_pair):
    good = save_student(trained_pair[0], tmp_path / "good.safetensors")
    data = good.read_bytes()
    cases = {
        "missing.safetensors": None,
        "truncated.safetensors": data[: len(data) // 2],
        "garbage.safetensors": b"\x00\x01 not a checkpoint" * 10,
    }
    for name, blob in cases.items():
        if blob is not None:
            (tmp_path / name).write_bytes(blob)
        with pytest.raises(DataError) as err:
            load_student(tmp_path / name)
        assert_house_message(str(err.value), name)

    from safetensors.torch import load_file, save_file

    tensors = load_file(str(good))
    save_file(tensors, str(tmp_path / "nometa.safetensors"))
    with pytest.raises(DataError) as err:
        load_student(tmp_path / "nometa.safetensors")
    assert_house_message(str(err.value), "format", "pioneer.student/1")

    bad_cfg = {"format": "pioneer.student/1", "config": '{"kind": "mdn", "hidden": [64, 64]}'}
    save_file(tensors, str(tmp_path / "mismatch.safetensors"), metadata=bad_cfg)
    with pytest.raises(DataError) as err:
        load_student(tmp_path / "mismatch.safetensors")
    assert_house_message(str(err.value), "tensors", "shape")

    typo = {"format": "pioneer.student/1", "config": '{"kind": "mdn", "n_component": 3}'}
    save_file(tensors, str(tmp_path / "typo.safetensors"), metadata=typo)
    with pytest.raises(DataError) as err:
        load_student(tmp_path / "typo.safetensors")
    assert_house_message(str(err.value), "config", "n_component")

    tensors["mu_head.bias"][0] = float("nan")
    meta = {"format": "pioneer.student/1", "config": '{"kind": "mdn"}'}
    save_file(tensors, str(tmp_path / "nan.safetensors"), metadata=meta)
    with pytest.raises(DataError) as err:
        load_student(tmp_path / "nan.safetensors")
    assert_house_message(str(err.value), "mu_head.bias", "finite")


# ------------------------------------------------------------------------- policy
def test_student_policies_are_registered_and_act(tmp_path, trained_pair):
    from pioneer.envs.env import NavEnv

    assert {"student-mdn", "student-mlp", "student-onnx"} <= set(policy_names())
    save_student(trained_pair[0], tmp_path / "hr-rl.safetensors")
    save_student(trained_pair[1], tmp_path / "mlp.safetensors")
    pattern = str(tmp_path / "{scenario}.safetensors")
    pol = build_policy("student-mdn", "hr-rl", checkpoint=pattern)
    assert isinstance(pol, StudentPolicy) and pol.name == "student-mdn"
    env = NavEnv("hr-rl")
    obs, info = env.reset(seed=3)
    pol.reset(info, np.random.default_rng(0))
    for _ in range(10):
        u = pol.act(obs, info)
        assert u.shape == (2,) and u.dtype == np.float64 and np.all(np.isfinite(u))
        obs, _, term, trunc, info = env.step(u)
        assert not (term or trunc)
    assert len(pol.uncertainty) == 10
    assert all(a > 0 and e >= 0 for a, e in pol.uncertainty)
    with torch.no_grad():
        expected = trained_pair[0].deterministic_action(torch.from_numpy(obs[None]))[0]
    np.testing.assert_allclose(pol.act(obs, info), expected.numpy(), rtol=1e-6)
    pol.reset(info, np.random.default_rng(0))
    assert pol.uncertainty == []

    mlp = build_policy("student-mlp", None, checkpoint=tmp_path / "mlp.safetensors")
    mlp.reset(info, np.random.default_rng(0))
    assert mlp.act(obs, info).shape == (2,)
    assert all(math.isnan(a) and math.isnan(e) for a, e in mlp.uncertainty)

    with pytest.raises(ConfigError) as err:
        build_policy("student-mdn", None, checkpoint=tmp_path / "mlp.safetensors")
    assert_house_message(str(err.value), "student-mlp")
