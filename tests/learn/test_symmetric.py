"""Mirror-equivariant students (``StudentConfig.symmetric``): the command of a mirrored input is
the mirrored command — in the torch module, the NumPy forward and the exported ONNX graph —
the uncertainty is the same, and a saved student rebuilds its symmetry from its config."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnxruntime as ort
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pioneer.data import shipped_demos
from pioneer.deploy.inputs import StudentInputs
from pioneer.deploy.mixture import mixture_action, mixture_uncertainty, symmetric_mixture
from pioneer.errors import ConfigError
from pioneer.laser import LidarConfig, apply_mirror, mirror_map, mirror_observation
from pioneer.learn import StudentConfig, export_onnx, load_student, save_student, train_student
from pioneer.learn.inference import StudentInference
from pioneer.learn.models import build_student, symmetrise_mixture
from pioneer.reward.dataset import Dataset

torch.set_num_threads(1)

OBS = LidarConfig().obs_dim
K_SECTORS = LidarConfig().n_sectors
FLIP = np.array([1.0, -1.0])
INPUTS = {
    "o_t": StudentInputs(),
    "o_t, u_t-1": StudentInputs(previous_command=True),
    "o_t, o_t-1, u_t-1": StudentInputs(previous_observation=True, previous_command=True),
}
# The mirror is exact in float32 (a gather and a sign), so the two passes differ only by
# where the rows sit in a product: equal to float32 rounding of the outputs.
TOL = 1e-5


def observations(rng: np.random.Generator, n: int) -> np.ndarray:
    """Random observations in their ranges: distances in [0, 5] m, angles in (−π, π]."""
    o = rng.uniform(0.0, 5.0, (n, OBS)).astype(np.float32)
    o[:, K_SECTORS + 2 :] = rng.uniform(-np.pi, np.pi, (n, OBS - K_SECTORS - 2))
    o[: n // 4, -1] = np.float32(np.pi)  # the goal straight behind: π mirrors onto π
    return o


def student_inputs(inputs: StudentInputs, rng: np.random.Generator, n: int) -> np.ndarray:
    before = observations(rng, n) if inputs.previous_observation else None
    command = None
    if inputs.previous_command:
        command = np.stack([rng.uniform(0, 0.8, n), rng.uniform(-1.25, 1.25, n)], axis=1)
    return inputs.stack(observations(rng, n), before, command)


def symmetric_student(kind: str, inputs: StudentInputs, seed: int = 0):
    cfg = StudentConfig(
        kind=kind,  # type: ignore[arg-type]
        symmetric=True,
        previous_observation=inputs.previous_observation,
        previous_command=inputs.previous_command,
    )
    return build_student(cfg, seed=seed)


def test_the_mirror_map_is_the_mirrored_observation():
    rng = np.random.default_rng(0)
    o = observations(rng, 200)
    index, sign = mirror_map()
    np.testing.assert_array_equal(apply_mirror(o, index, sign), mirror_observation(o))
    np.testing.assert_array_equal(mirror_observation(mirror_observation(o)), o)


def test_the_inputs_mirror_keeps_their_layout():
    rng = np.random.default_rng(1)
    inputs = INPUTS["o_t, o_t-1, u_t-1"]
    x = student_inputs(inputs, rng, 50)
    m = apply_mirror(x, *inputs.mirror_map(OBS))
    np.testing.assert_array_equal(m[:, :OBS], mirror_observation(x[:, :OBS]))
    np.testing.assert_array_equal(m[:, OBS : 2 * OBS], mirror_observation(x[:, OBS : 2 * OBS]))
    np.testing.assert_array_equal(m[:, -2:], x[:, -2:] * FLIP.astype(np.float32))


def test_an_observation_without_a_mirror_is_refused():
    with pytest.raises(ConfigError, match="mirror"):
        StudentInputs().mirror_map(OBS + 1)
    with pytest.raises(ConfigError, match=r"symmetric|mirror"):
        build_student(StudentConfig(symmetric=True, obs_dim=OBS + 1))


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    kind=st.sampled_from(["mdn", "mlp"]),
    inputs=st.sampled_from(sorted(INPUTS)),
    mode=st.sampled_from(["mode", "mean"]),
)
def test_the_command_of_a_mirrored_input_is_the_mirrored_command(seed, kind, inputs, mode):
    """The property, against the brute-force statement: run the student on x and on M x."""
    rng = np.random.default_rng(seed)
    model = symmetric_student(kind, INPUTS[inputs], seed=seed % 1000)
    x = torch.from_numpy(student_inputs(INPUTS[inputs], rng, 16))
    with torch.no_grad():
        a = model.deterministic_action(x, mode).numpy()
        a_m = model.deterministic_action(model.mirror(x), mode).numpy()
        np.testing.assert_allclose(a_m, a * FLIP, atol=TOL)
        if kind == "mdn":
            u = [t.numpy() for t in model.uncertainty(x)]
            u_m = [t.numpy() for t in model.uncertainty(model.mirror(x))]
            np.testing.assert_allclose(u_m, u, rtol=TOL, atol=1e-7)


def test_the_mixture_is_half_own_half_mirrored():
    """p_sym(u | x) = ½ p(u | x) + ½ p(m(u) | M x), by the log-likelihood of both networks."""
    rng = np.random.default_rng(3)
    sym = symmetric_student("mdn", StudentInputs(), seed=4)
    assert sym.config.symmetric_loss == "each_half"  # the default; the forward is the same
    plain = build_student(StudentConfig(), seed=4)
    plain.load_state_dict(sym.state_dict())
    x = torch.from_numpy(observations(rng, 64))
    u = torch.from_numpy(np.stack([rng.uniform(0, 0.8, 64), rng.uniform(-1, 1, 64)], 1)).float()
    with torch.no_grad():
        want = torch.logaddexp(
            plain.log_prob(x, u), plain.log_prob(sym.mirror(x), u * torch.tensor([1.0, -1.0]))
        ) - np.log(2.0)
        np.testing.assert_allclose(sym.log_prob(x, u).numpy(), want.numpy(), atol=1e-5)


def test_numpy_and_torch_symmetrise_alike():
    rng = np.random.default_rng(5)
    parts = [
        (
            rng.normal(size=(8, 10)).astype(np.float32),
            rng.normal(size=(8, 10, 2)).astype(np.float32),
            rng.uniform(0.1, 1, (8, 10, 2)).astype(np.float32),
        )
        for _ in range(2)
    ]
    np_out = symmetric_mixture(parts[0], parts[1])
    with torch.no_grad():
        pt = [tuple(torch.from_numpy(a) for a in p) for p in parts]
        torch_out = symmetrise_mixture(pt[0], pt[1])  # type: ignore[arg-type]
    for a, b in zip(np_out, torch_out, strict=True):
        np.testing.assert_allclose(a, b.numpy(), rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("kind", ["mdn", "mlp"])
def test_a_symmetric_student_trains_saves_and_exports(kind, tmp_path: Path):
    """Trained on the shipped demonstrations, saved and loaded, run by NumPy and by ONNX
    Runtime: the same commands, and each of them mirror-equivariant."""
    data = Dataset.load(shipped_demos("hr-rl"))
    model = symmetric_student(kind, StudentInputs(), seed=0)
    n = len(data.obs) - 200
    train_student(model, data.obs[:n], data.action[:n], epochs=2, seed=0)
    loaded = load_student(save_student(model, tmp_path / "s.safetensors"))
    assert loaded.config.symmetric
    x = data.obs[n:]
    x_m = mirror_observation(x)
    with torch.no_grad():
        a = loaded.deterministic_action(torch.from_numpy(x)).numpy()
        np.testing.assert_array_equal(a, model.deterministic_action(torch.from_numpy(x)).numpy())
    inference = StudentInference(loaded)
    if kind == "mdn":
        logits, mu, sigma = inference.mixture(x)
        assert logits.shape == (200, 2 * loaded.config.n_components)
        np.testing.assert_allclose(mixture_action(logits, mu), a, atol=TOL)
        lm, mm, sm = inference.mixture(x_m)
        np.testing.assert_allclose(mixture_action(lm, mm), a * FLIP, atol=TOL)
        np.testing.assert_allclose(
            mixture_uncertainty(lm, mm, sm), mixture_uncertainty(logits, mu, sigma), rtol=1e-4
        )
    else:
        np.testing.assert_allclose(inference.regress(x), a, atol=TOL)
        np.testing.assert_allclose(inference.regress(x_m), a * FLIP, atol=TOL)
    session = ort.InferenceSession(str(export_onnx(loaded, tmp_path / "s.onnx")))
    (onnx_a,) = session.run(["action"], {"obs": x})
    (onnx_am,) = session.run(["action"], {"obs": x_m})
    np.testing.assert_allclose(onnx_a, a, atol=1e-4)
    np.testing.assert_allclose(onnx_am, a * FLIP, atol=1e-4)


def test_each_half_trains_on_the_frame_and_its_mirror_image():
    """``symmetric_loss="each_half"``: −½ (log p(u | x) + log p(m(u) | M x)) of the network's
    own (unsymmetrised) mixture, so both halves fit both sides; the forward stays symmetric."""
    rng = np.random.default_rng(7)
    sym = build_student(StudentConfig(symmetric=True, symmetric_loss="each_half"), seed=2)
    plain = build_student(StudentConfig(), seed=2)
    plain.load_state_dict(sym.state_dict())
    x = torch.from_numpy(observations(rng, 32))
    u = torch.from_numpy(np.stack([rng.uniform(0, 0.8, 32), rng.uniform(-1, 1, 32)], 1)).float()
    with torch.no_grad():
        flip = torch.tensor([1.0, -1.0])
        want = -0.5 * (plain.log_prob(x, u) + plain.log_prob(sym.mirror(x), u * flip)).mean()
        assert float(sym.loss(x, u)) == pytest.approx(float(want), rel=1e-6)
        a = sym.deterministic_action(x).numpy()
        np.testing.assert_allclose(
            sym.deterministic_action(sym.mirror(x)).numpy(), a * FLIP, atol=TOL
        )
