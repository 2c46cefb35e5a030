"""A student's forward pass in NumPy against the module's own (the reference): the mixture and
the regressed command to float32 rounding for fresh networks of every input kind and for the
shipped students along episodes; the policy with either forward drives alike (same outcomes,
paths within micrometres, uncertainty within a relative 1e-4); bad settings refused."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pioneer.control.registry import build_policy
from pioneer.errors import ConfigError
from pioneer.eval.episode import run_episode
from pioneer.learn.inference import StudentInference
from pioneer.learn.models import StudentConfig, build_student
from pioneer.learn.policy import StudentPolicy
from pioneer_testutils import assert_house_message

# float32 products and e^x from other libraries: a few units in the last place of values of
# order 1 (measured: ≤ 1e-6 on the shipped students' episodes)
ATOL = 1e-5


def _fitted(kind: str, **inputs: bool):
    """A fresh student with fitted (non-trivial) normalisation buffers."""
    model = build_student(StudentConfig(kind=kind, hidden=(32, 16), **inputs), seed=3)
    rng = np.random.default_rng(0)
    x = rng.normal(2.0, 1.5, size=(200, model.config.input_dim)).astype(np.float32)
    u = rng.normal([0.4, 0.0], [0.2, 0.5], size=(200, 2)).astype(np.float32)
    model.set_normalizer(torch.from_numpy(x), torch.from_numpy(u))
    return model, rng.normal(2.0, 1.5, size=(64, model.config.input_dim)).astype(np.float32)


@pytest.mark.parametrize("inputs", [{}, {"previous_observation": True, "previous_command": True}])
def test_the_mixture_equals_the_module(inputs):
    model, x = _fitted("mdn", **inputs)
    x[0] = 80.0  # far outside the data: softplus above its threshold
    got = StudentInference(model).mixture(x)
    with torch.inference_mode():
        want = [t.numpy() for t in model(torch.from_numpy(x))]
    for g, w in zip(got, want, strict=True):
        assert g.dtype == np.float32 and g.shape == w.shape
        np.testing.assert_allclose(g, w, rtol=1e-5, atol=ATOL)


def test_the_regression_equals_the_module():
    model, x = _fitted("mlp")
    got = StudentInference(model).regress(x)
    with torch.inference_mode():
        want = model(torch.from_numpy(x)).numpy()
    assert got.dtype == np.float32
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=ATOL)


@pytest.mark.parametrize("name", ["student-mdn", "student-mlp"])
@pytest.mark.parametrize("scenario", ["hr-rl", "hl-rr"])
def test_the_shipped_students_drive_alike_with_either_forward(name, scenario):
    fast = build_policy(name, scenario)
    ref = build_policy(name, scenario, forward="torch")
    assert isinstance(fast, StudentPolicy) and fast.forward == "numpy" and ref.forward == "torch"
    for seed in (4, 5):
        a, _ = run_episode(scenario, fast, seed)
        ua = np.array(fast.uncertainty)
        b, _ = run_episode(scenario, ref, seed)
        ub = np.array(ref.uncertainty)
        assert a.event == b.event and a.steps == b.steps
        assert abs(a.path_length_m - b.path_length_m) < 1e-5
        if name == "student-mdn":
            np.testing.assert_allclose(ua, ub, rtol=1e-4, atol=1e-9)
        else:
            assert np.isnan(ua).all() and np.isnan(ub).all()
        assert run_episode(scenario, fast, seed)[0] == a  # each repeats itself


def test_an_unknown_forward_is_refused():
    model = build_student(StudentConfig(kind="mlp", hidden=(8,)))
    with pytest.raises(ConfigError) as e:
        StudentPolicy(model, forward="onnx")  # type: ignore[arg-type]
    assert_house_message(str(e.value), "forward", "onnx")
