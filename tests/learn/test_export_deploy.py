"""ONNX export and the torch-free runtime: parity with PyTorch, scan round trip, import hygiene."""

from __future__ import annotations

import ast
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from pioneer.control.registry import build_policy
from pioneer.data import shipped_demos
from pioneer.deploy import OnnxStudentPolicy, StudentRuntime, mixture_uncertainty
from pioneer.envs.env import NavEnv
from pioneer.errors import ConfigError, DataError
from pioneer.learn import MDN, MLPStudent, StudentConfig, export_onnx, train_student
from pioneer.learn.export import MDN_OUTPUTS
from pioneer.reward.dataset import Dataset
from pioneer.sim.lidar import observation_from_scan
from pioneer.sim.robot import RobotConfig
from pioneer.sim.world import scan
from pioneer_testutils import ROBOT_SIDE_PRELUDE, assert_house_message

torch.set_num_threads(1)

TOL = {"rtol": 1e-5, "atol": 1e-5}


@pytest.fixture(scope="module")
def demo_obs() -> np.ndarray:
    """Real observations: the teacher's shipped hr-rl demonstrations."""
    return Dataset.load(shipped_demos("hr-rl")).obs


@pytest.fixture(scope="module")
def students(tmp_path_factory) -> dict[str, tuple[MDN | MLPStudent, Path]]:
    """An MDN and an MLP briefly trained on the shipped demos, each exported to ONNX."""
    data = Dataset.load(shipped_demos("hr-rl"))
    out = tmp_path_factory.mktemp("onnx")
    res: dict[str, tuple[MDN | MLPStudent, Path]] = {}
    for name, model in (("mdn", MDN(seed=0)), ("mlp", MLPStudent(seed=0))):
        train_student(model, data.obs, data.action, epochs=3, seed=1)
        res[name] = (model, export_onnx(model, out / f"{name}.onnx"))
    mean = MDN(StudentConfig(action_mode="mean"), seed=0)
    mean.load_state_dict(res["mdn"][0].state_dict())
    res["mdn-mean"] = (mean, export_onnx(mean, out / "mdn-mean.onnx"))
    return res


def torch_outputs(model: MDN | MLPStudent, obs: np.ndarray) -> list[np.ndarray]:
    x = torch.from_numpy(np.ascontiguousarray(obs, dtype=np.float32))
    with torch.no_grad():
        if isinstance(model, MLPStudent):
            return [model(x).numpy()]
        logits, mu, sigma = model(x)
        ale, epi = model.uncertainty(x)
        return [t.numpy() for t in (model.deterministic_action(x), ale, epi, logits, mu, sigma)]


def clip(action: np.ndarray) -> np.ndarray:
    """``(v, ω)`` clipped to the simulated robot's limits, as the runtime clips."""
    rc = RobotConfig()
    return np.clip(action, [rc.v_min, -rc.omega_max], [rc.v_max, rc.omega_max])


def inputs(kind: str, demo_obs: np.ndarray) -> np.ndarray:
    rng = np.random.default_rng(5)
    if kind == "random":
        return (rng.normal(size=(257, 29)) * 3.0).astype(np.float32)
    if kind == "uniform-scan":  # plausible ranges and angles, uniformly spread
        r = rng.uniform(0.2, 5.0, size=(100, 24))
        d = np.sort(rng.uniform(0.2, 2.0, size=(100, 2)), axis=1)
        ang = rng.uniform(-np.pi, np.pi, size=(100, 3))
        return np.concatenate([r, d, ang], axis=1).astype(np.float32)
    return demo_obs


# ------------------------------------------------------------------------------ export
@pytest.mark.parametrize("which", ["mdn", "mdn-mean", "mlp"])
@pytest.mark.parametrize("kind", ["random", "uniform-scan", "demos"])
def test_onnx_runtime_matches_pytorch(students, demo_obs, which, kind):
    import onnxruntime as ort

    model, path = students[which]
    obs = inputs(kind, demo_obs)
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    sess = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
    got = sess.run(None, {"obs": obs})
    want = torch_outputs(model, obs)
    assert len(got) == len(want)
    for g, w in zip(got, want, strict=True):
        assert g.shape == w.shape and g.dtype == np.float32
        np.testing.assert_allclose(g, w, **TOL)


def test_onnx_graph_has_dynamic_batch_and_metadata(students, demo_obs):
    import onnx

    model, path = students["mdn"]
    proto = onnx.load(str(path))
    onnx.checker.check_model(proto)
    assert proto.opset_import[0].version == 17
    meta = {p.key: p.value for p in proto.metadata_props}
    assert meta["format"] == "pioneer.student-onnx/1" and meta["kind"] == "mdn"
    assert meta["action_mode"] == "mode"
    assert StudentConfig.from_dict(json.loads(meta["config"])) == model.config
    assert [o.name for o in proto.graph.output] == list(MDN_OUTPUTS)
    rt = StudentRuntime(path)
    for n in (1, 7, 300):
        a, ale, epi = rt.raw_outputs(demo_obs[:n])
        assert a.shape == (n, 2) and ale.shape == (n,) and epi.shape == (n,)
    assert model.training is False
    with pytest.raises(ConfigError):
        export_onnx(model, path.parent / "x.onnx", action_mode="median")


def test_export_keeps_training_mode_and_writes_atomically(tmp_path):
    m = MDN(seed=3)
    m.train()
    export_onnx(m, tmp_path / "m.onnx")
    assert m.training
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.onnx"]


# ------------------------------------------------------------------------------ runtime
def test_runtime_outputs_agree_with_the_numpy_twin(students, demo_obs):
    _, path = students["mdn"]
    rt = StudentRuntime(path)
    logits, mu, sigma, ale, epi = rt.session.run(
        ["logits", "mu", "sigma", "aleatoric", "epistemic"], {"obs": demo_obs[:50]}
    )
    ale_np, epi_np = mixture_uncertainty(logits, mu, sigma)
    np.testing.assert_allclose(ale, ale_np, rtol=1e-5)
    np.testing.assert_allclose(epi, epi_np, rtol=1e-5, atol=1e-7)


def test_runtime_mlp_has_no_uncertainty(students, demo_obs):
    model, path = students["mlp"]
    rt = StudentRuntime(path)
    d = rt.from_observation(demo_obs[0])
    np.testing.assert_allclose([d.v, d.omega], torch_outputs(model, demo_obs[:1])[0][0], **TOL)
    assert math.isnan(d.aleatoric) and math.isnan(d.epistemic)


def test_scan_to_command_round_trip(students):
    """Simulated LiDAR → a LaserScan-style message → runtime == the policy on the env's obs."""
    model, path = students["mdn"]
    rt = StudentRuntime(path)
    pol = OnnxStudentPolicy(rt)
    env = NavEnv("hr-rl")
    obs, info = env.reset(seed=4)
    pol.reset(info, np.random.default_rng(0))
    for _ in range(15):
        s = env.state
        ranges = scan(env.world, s)[0]  # 72 beams, beam 0 along the heading
        x, y, th = s.robot[0]
        dx, dy = s.goal[0] - (x, y)
        goal = (math.cos(th) * dx + math.sin(th) * dy, -math.sin(th) * dx + math.cos(th) * dy)
        # As a typical driver publishes it: from −π, counter-clockwise, inf for no return.
        msg = np.roll(ranges, 36)
        msg[msg >= 5.0] = np.inf
        inc = 2 * math.pi / 72
        np.testing.assert_allclose(observation_from_scan(msg, -math.pi, inc, 5.0, goal), obs)
        d = rt.step(msg, -math.pi, inc, 5.0, goal, age_s=0.0)
        assert d.stop_reason is None and d.valid_share == 1.0
        u = pol.act(obs, info)
        np.testing.assert_allclose([d.v, d.omega], u, **TOL)
        want = torch_outputs(model, obs[None])
        np.testing.assert_allclose([d.v, d.omega], clip(want[0][0]), **TOL)
        np.testing.assert_allclose([d.aleatoric, d.epistemic], [want[1][0], want[2][0]], **TOL)
        # The same scan, clockwise (negative increment), gives the same decision.
        d2 = rt.step(msg[::-1], math.pi - inc, -inc, 5.0, goal, age_s=0.0)
        np.testing.assert_allclose([d2.v, d2.omega], [d.v, d.omega], **TOL)
        obs, _, term, trunc, info = env.step(u)
        if term or trunc:
            break
    assert len(pol.uncertainty) >= 1 and all(a > 0 for a, _ in pol.uncertainty)


def test_onnx_policy_is_registered(students, demo_obs, tmp_path):

    _, path = students["mdn"]
    (tmp_path / "hr-rl.onnx").write_bytes(path.read_bytes())
    pol = build_policy("student-onnx", "hr-rl", model=tmp_path / "{scenario}.onnx")
    assert isinstance(pol, OnnxStudentPolicy) and pol.name == "student-onnx"
    pol.reset({}, np.random.default_rng(0))
    assert pol.act(demo_obs[0], {}).shape == (2,)


def test_runtime_refuses_bad_files_and_inputs(students, tmp_path):
    import onnx

    with pytest.raises(DataError) as err:
        StudentRuntime(tmp_path / "missing.onnx")
    assert_house_message(str(err.value), "missing.onnx")
    (tmp_path / "junk.onnx").write_bytes(b"not a graph" * 20)
    with pytest.raises(DataError) as err:
        StudentRuntime(tmp_path / "junk.onnx")
    assert_house_message(str(err.value), "junk.onnx")
    proto = onnx.load(str(students["mdn"][1]))
    del proto.metadata_props[:]
    onnx.save(proto, str(tmp_path / "foreign.onnx"))
    with pytest.raises(DataError) as err:
        StudentRuntime(tmp_path / "foreign.onnx")
    assert_house_message(str(err.value), "format", "pioneer.student-onnx/1")

    rt = StudentRuntime(students["mdn"][1])
    with pytest.raises(DataError) as err:
        rt.from_observation(np.zeros(28))
    assert_house_message(str(err.value), "obs")
    with pytest.raises(DataError) as err:
        rt.from_observation(np.full(29, np.nan))
    assert_house_message(str(err.value), "finite")
    with pytest.raises(DataError):
        rt.step([1.0] * 10, 0.0, 0.1, 5.0, (math.nan, 0.0))


# ------------------------------------------------------------------------------ hygiene
BLOCKED = (
    ROBOT_SIDE_PRELUDE
    + """
import math
import numpy as np
from pioneer.deploy import StudentRuntime

rt = StudentRuntime(sys.argv[1])
ranges = [1.0 + 0.5 * math.cos(3 * i * 2 * math.pi / 360) for i in range(360)]
d = rt.step(ranges, -math.pi, 2 * math.pi / 360, 5.0, (2.0, 1.0), age_s=0.01)
print(json.dumps({"decision": [d.v, d.omega, d.aleatoric, d.epistemic], "heavy": heavy()}))
"""
)


def test_deploy_runs_with_torch_numba_and_simulator_blocked(students):
    model, path = students["mdn"]
    proc = subprocess.run(
        [sys.executable, "-c", BLOCKED, str(path)],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["heavy"] == []
    ranges = [1.0 + 0.5 * math.cos(3 * i * 2 * math.pi / 360) for i in range(360)]
    obs = observation_from_scan(ranges, -math.pi, 2 * math.pi / 360, 5.0, (2.0, 1.0))
    want = torch_outputs(model, obs[None])
    np.testing.assert_allclose(
        out["decision"], [*clip(want[0][0]), want[1][0], want[2][0]], rtol=1e-5, atol=1e-5
    )


def test_deploy_sources_never_import_torch():
    import pioneer.deploy

    root = Path(pioneer.deploy.__file__).parent
    for src in root.glob("*.py"):
        for node in ast.walk(ast.parse(src.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module or ""]
            for n in names:
                assert not n.startswith(("torch", "numba", "pioneer.learn", "pioneer.sim")), (
                    f"{src.name} imports {n}"
                )
