"""Students that also read the previous observation o_{t−1} or their previous command u_{t−1}:
DAgger's training inputs, the torch student and the ONNX runtime build the same inputs, step by
step, and the runtime remembers what it sent."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from pioneer.data import shipped_demos
from pioneer.deploy import OnnxStudentPolicy
from pioneer.deploy.config import RuntimeConfig
from pioneer.deploy.inputs import InputMemory, StudentInputs
from pioneer.deploy.runtime import StudentRuntime
from pioneer.envs.env import NavEnv
from pioneer.envs.episode import Episode
from pioneer.errors import DataError
from pioneer.learn import MDN, StudentConfig, export_onnx, train_student
from pioneer.learn.dagger import DaggerConfig
from pioneer.learn.dagger import _Students as Students
from pioneer.learn.policy import StudentPolicy
from pioneer.reward.dataset import Dataset

torch.set_num_threads(1)

KINDS = {
    "command": StudentInputs(previous_command=True),
    "observation": StudentInputs(previous_observation=True),
    "both": StudentInputs(previous_observation=True, previous_command=True),
}


def test_an_episodes_inputs_shift_by_one_step_and_clip_the_commands():
    obs = np.arange(4 * 3, dtype=np.float32).reshape(4, 3)
    sent = np.array([[0.5, 0.1], [-0.04, 2.0], [0.9, -2.0], [0.3, 0.0]])
    lim = RuntimeConfig()
    x = KINDS["both"].of_episode(obs, sent)
    assert x.shape == (4, 3 + 3 + 2) and x.dtype == np.float32
    np.testing.assert_array_equal(x[:, :3], obs)
    np.testing.assert_array_equal(x[:, 3:6], obs[[0, 0, 1, 2]])  # o_{t−1}; o_0 at the start
    want = [[0, 0], [0.5, 0.1], [0, lim.omega_max], [lim.v_max, -lim.omega_max]]
    np.testing.assert_allclose(x[:, 6:], want, atol=1e-7)  # u_{t−1} as the robot ran it
    np.testing.assert_array_equal(StudentInputs().of_episode(obs, sent), obs)
    assert [k.width(29) for k in KINDS.values()] == [31, 58, 60]


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_step_by_step_inputs_equal_the_episodes(kind):
    """InputMemory (the torch student and the runtime) against of_episode (DAgger)."""
    rng = np.random.default_rng(0)
    obs = rng.random((6, 29)).astype(np.float32)
    sent = rng.uniform(-1, 1, (6, 2))
    mem = InputMemory(KINDS[kind])
    rows = []
    for o, u in zip(obs, sent, strict=True):
        rows.append(mem.inputs(o)[0])
        mem.note(o, u)
    np.testing.assert_array_equal(np.array(rows), KINDS[kind].of_episode(obs, sent))
    mem.reset()
    first = KINDS[kind].of_episode(obs[3:4], sent[3:4])[0]
    np.testing.assert_array_equal(mem.inputs(obs[3])[0], first)


def test_stack_refuses_missing_or_unread_parts():
    with pytest.raises(DataError, match="previous_command"):
        KINDS["command"].stack(np.zeros((1, 29)))
    with pytest.raises(DataError, match="previous_obs"):
        KINDS["command"].stack(np.zeros((1, 29)), np.zeros((1, 29)), np.zeros((1, 2)))


def test_dagger_aggregates_each_episodes_own_history():
    eps = [
        {
            "obs": np.full((n, 29), float(n), dtype=np.float32),
            "action": np.zeros((n, 2), dtype=np.float32),
            "applied": np.arange(2 * n, dtype=np.float64).reshape(n, 2) / 10,
            "gap": np.linspace(0.05, 1.0, n),
        }
        for n in (3, 2)
    ]
    cfg = DaggerConfig(student=StudentConfig(previous_command=True))
    x, y, repeat, _ = Students(cfg, {}).aggregate(eps)
    np.testing.assert_array_equal(repeat, 1)
    assert x.shape == (5, 31) and y.shape == (5, 2)
    np.testing.assert_allclose(
        x[:, 29:], [[0, 0], [0, 0.1], [0.2, 0.3], [0, 0], [0, 0.1]], atol=1e-7
    )  # each episode starts from zeros
    plain, _, _, _ = Students(DaggerConfig(), {}).aggregate(eps)
    assert plain.shape == (5, 29)
    # near_gap/near_repeat: frames closer than 0.3 m to a person count 4 times
    _, _, repeat, _ = Students(DaggerConfig(near_gap=0.3, near_repeat=4), {}).aggregate(eps)
    np.testing.assert_array_equal(repeat, [4, 1, 1, 4, 1])


@pytest.fixture(scope="module", params=sorted(KINDS))
def student(request, tmp_path_factory) -> tuple[MDN, Path]:
    """An MDN reading o_{t−1} and/or u_{t−1}, briefly trained on the shipped demos (as one long
    episode: enough for a smoke fit), and its ONNX export."""
    inputs = KINDS[request.param]
    data = Dataset.load(shipped_demos("hr-rl"))
    cfg = StudentConfig(
        previous_observation=inputs.previous_observation,
        previous_command=inputs.previous_command,
    )
    model = MDN(cfg, seed=0)
    train_student(model, inputs.of_episode(data.obs, data.action), data.action, epochs=2, seed=1)
    return model, export_onnx(model, tmp_path_factory.mktemp("inputs") / "student.onnx")


def _drive(policy, seed: int = 3, steps: int = 40) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The observations, the commands a policy sends, and the simulator's applied command
    before each step."""
    obs, sent, applied = [], [], []
    ep = Episode(NavEnv("hr-rl"), policy, seed)
    for _ in range(steps):
        if ep.done:
            break
        step = ep.step()
        obs.append(step.obs)
        sent.append(step.command)
        applied.append(step.info["state"].command[0])
    return np.array(obs), np.array(sent), np.array(applied)


def test_the_torch_student_acts_on_its_episodes_training_inputs(student):
    """The inputs the student acted on, rebuilt from the episode as DAgger does, give the same
    commands; and u_{t−1} is what the simulator applied."""
    model, _ = student
    obs, sent, applied = _drive(StudentPolicy(model))
    x = model.config.inputs.of_episode(obs, sent)
    with torch.no_grad():
        again = model.deterministic_action(torch.from_numpy(x)).numpy()
    np.testing.assert_allclose(again, sent, atol=1e-6)
    if model.config.previous_command:
        np.testing.assert_allclose(x[:, -2:], applied, atol=1e-6)


def test_the_onnx_runtime_drives_like_the_torch_student(student):
    model, onnx = student
    _, torch_sent, _ = _drive(StudentPolicy(model))
    _, onnx_sent, _ = _drive(OnnxStudentPolicy(onnx))
    n = min(len(torch_sent), len(onnx_sent))
    assert n >= 20
    lim = RuntimeConfig()
    clipped = np.clip(torch_sent[:n], [lim.v_min, -lim.omega_max], [lim.v_max, lim.omega_max])
    np.testing.assert_allclose(onnx_sent[:n], clipped, atol=1e-5)


def test_the_runtime_remembers_what_it_sent_and_forgets_it_on_reset(student):
    model, onnx = student
    rt = StudentRuntime(onnx)
    assert rt.input_dim == model.config.input_dim
    obs = Dataset.load(shipped_demos("hr-rl")).obs[:2]
    first = rt.from_observation(obs[0])
    second = rt.from_observation(obs[1])
    sent = np.array([[first.v, first.omega], [second.v, second.omega]])
    x = rt.inputs.of_episode(obs, sent)
    a, _, _ = rt.raw_outputs(x[1:2])
    assert second.v == pytest.approx(float(np.clip(a[0, 0], 0, None)), abs=1e-7)
    rt.reset()
    again = rt.from_observation(obs[0])
    assert (again.v, again.omega) == (first.v, first.omega)
    with pytest.raises(DataError, match="obs"):
        rt.raw_outputs(obs[:1])  # the 29-D observation alone is not this student's input
