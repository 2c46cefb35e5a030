"""ROS bag replay and ``pioneer export``: bags written here with rosbags, a tiny exported MDN."""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from pioneer.cli import main
from pioneer.deploy import StudentRuntime, replay_bag
from pioneer.deploy.bag import CSV_COLUMNS, goal_in_robot_frame
from pioneer.errors import ConfigError, DataError
from pioneer.learn import MDN, StudentConfig, export_onnx, save_student
from pioneer.learn.export import MDN_OUTPUTS, PARITY_TOL
from pioneer_testutils import (
    ROBOT_SIDE_PRELUDE,
    assert_house_message,
    one_error_line,
    wrong_width_onnx,
)

pytest.importorskip("rosbags")

from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

torch.set_num_threads(1)

N_SCANS = 20
N_BEAMS = 360
T0 = 1_700_000_000  # [s] first header stamp
GOAL = (2.0, 1.0)  # [m] robot frame
SCAN = "sensor_msgs/msg/LaserScan"
ODOM = "nav_msgs/msg/Odometry"
STRING = "std_msgs/msg/String"


def make_scans(seed: int = 0) -> list[np.ndarray]:
    """``N_SCANS`` ranges of ``N_BEAMS`` beams [m]: returns, inf (no return), beyond range_max."""
    rng = np.random.default_rng(seed)
    scans = []
    for k in range(N_SCANS):
        r = rng.uniform(0.3, 12.0, N_BEAMS).astype(np.float32)
        r[rng.random(N_BEAMS) < 0.2] = np.inf
        r[k : k + 3] = np.nan  # a few invalid beams
        scans.append(r)
    return scans


def stamp(k: int) -> tuple[int, int]:
    """Header stamp of scan k: 10 Hz from T0, plus 7 ns (exact-decimal check)."""
    return T0 + k // 10, (k % 10) * 100_000_000 + 7


RECEIVE_DELAY = 0.02  # [s] bag time − header stamp


def bag_ns(k: int) -> int:
    """Receive (bag) time of scan k: 20 ms after its stamp."""
    sec, nsec = stamp(k)
    return sec * 1_000_000_000 + nsec + 20_000_000


class BagWriter:
    """Writes LaserScan / Odometry / String messages to a ROS 1 or ROS 2 bag."""

    def __init__(self, path: Path, fmt: str) -> None:
        self.ros1 = fmt == "ros1"
        self.ts = get_typestore(Stores.ROS1_NOETIC if self.ros1 else Stores.ROS2_HUMBLE)
        if self.ros1:
            self.w: Writer1 | Writer = Writer1(path)
        else:
            plugin = StoragePlugin.MCAP if fmt == "mcap" else StoragePlugin.SQLITE3
            self.w = Writer(path, version=9, storage_plugin=plugin)
        self.w.open()
        self.conns: dict[str, object] = {}

    def _header(self, k: int, frame: str) -> object:
        t = self.ts.types["builtin_interfaces/msg/Time"](*stamp(k))
        h = self.ts.types["std_msgs/msg/Header"]
        return h(seq=k, stamp=t, frame_id=frame) if self.ros1 else h(stamp=t, frame_id=frame)

    def write(self, topic: str, msgtype: str, t_ns: int, msg: object) -> None:
        if topic not in self.conns:
            self.conns[topic] = self.w.add_connection(topic, msgtype, typestore=self.ts)
        ser = self.ts.serialize_ros1 if self.ros1 else self.ts.serialize_cdr
        data = ser(msg, msgtype)
        self.w.write(self.conns[topic], t_ns, data)

    def scan(self, topic: str, k: int, ranges: np.ndarray) -> None:
        inc = 2 * math.pi / N_BEAMS
        msg = self.ts.types[SCAN](
            header=self._header(k, "base_link"),
            angle_min=-math.pi,
            angle_max=math.pi - inc,
            angle_increment=inc,
            time_increment=0.0,
            scan_time=0.1,
            range_min=0.1,
            range_max=10.0,
            ranges=ranges,
            intensities=np.zeros(0, dtype=np.float32),
        )
        self.write(topic, SCAN, bag_ns(k), msg)

    def odom(self, topic: str, k: int, t_ns: int, x: float, y: float, yaw: float) -> None:
        T = self.ts.types
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
            orientation=T["geometry_msgs/msg/Quaternion"](
                x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
            ),
        )
        zero = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        msg = T[ODOM](
            header=self._header(k, "odom"),
            child_frame_id="base_link",
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=zero, angular=zero),
                covariance=np.zeros(36),
            ),
        )
        self.write(topic, ODOM, t_ns, msg)

    def text(self, topic: str, t_ns: int, data: str) -> None:
        self.write(topic, STRING, t_ns, self.ts.types[STRING](data=data))

    def close(self) -> None:
        self.w.close()


def write_scan_bag(path: Path, fmt: str, scans: list[np.ndarray]) -> Path:
    w = BagWriter(path, fmt)
    for k, r in enumerate(scans):
        w.scan("/scan", k, r)
        w.text("/chatter", bag_ns(k) + 1, f"hello {k}")  # an unrelated topic
    w.close()
    return path


@pytest.fixture(scope="module")
def student(tmp_path_factory) -> tuple[MDN, Path]:
    """A freshly built tiny MDN (untrained; the inputs standardised as the real ones), exported."""
    out = tmp_path_factory.mktemp("student")
    model = MDN(StudentConfig(hidden=(16, 16), n_components=3), seed=0)
    with torch.no_grad():
        model.obs_mean.fill_(1.5)
        model.obs_std.fill_(1.0)
    model.eval()
    return model, export_onnx(model, out / "student.onnx")


@pytest.fixture(scope="module")
def scans() -> list[np.ndarray]:
    return make_scans()


def read_csv(path: Path) -> tuple[list[str], list[list[str]]]:
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def direct(rt: StudentRuntime, scans: list[np.ndarray], goals: list[tuple[float, float]]):
    """``StudentRuntime.step`` on the scans as the messages carry them (float32 header fields:
    the resampling's nearest-beam choice can depend on their rounding)."""
    f32 = np.float32
    amin, inc = f32(-math.pi), f32(2 * math.pi / N_BEAMS)
    rows = []
    for k, (r, g) in enumerate(zip(scans, goals, strict=True)):
        d = rt.step(r, amin, inc, f32(10.0), g, range_min=f32(0.1), age_s=RECEIVE_DELAY)
        assert d.stop_reason is None, k
        rows.append([d.v, d.omega, d.aleatoric, d.epistemic, d.valid_share, d.coverage_rad])
    return np.array(rows)


def numbers(rows: list[list[str]]) -> np.ndarray:
    """The CSV's decision and health columns as numbers (``stop_reason`` and ``age_s`` apart;
    the age is checked exactly where the stamps are known)."""
    at = [CSV_COLUMNS.index(c) for c in (*CSV_COLUMNS[2:6], "valid_share", "coverage_rad")]
    return np.array([[float(r[i]) for i in at] for r in rows])


# ------------------------------------------------------------------------------ replay
@pytest.mark.parametrize("fmt", ["sqlite3", "mcap", "ros1"])
def test_replay_matches_the_runtime_scan_by_scan(student, scans, tmp_path, fmt):
    _, onnx = student
    bag = write_scan_bag(tmp_path / ("in.bag" if fmt == "ros1" else "in"), fmt, scans)
    out = tmp_path / "out" / "commands.csv"
    summary = replay_bag(bag, onnx, out, goal=GOAL, progress=False)
    assert summary["scan_topic"] == "/scan" and summary["rows"] == N_SCANS
    assert summary["scans"] == N_SCANS and summary["skipped"] == 0
    header, rows = read_csv(out)
    assert tuple(header) == CSV_COLUMNS
    assert len(rows) == N_SCANS
    assert [r[0] for r in rows] == [f"{s}.{n:09d}" for s, n in map(stamp, range(N_SCANS))]
    want_bag = [f"{t // 10**9}.{t % 10**9:09d}" for t in map(bag_ns, range(N_SCANS))]
    assert [r[1] for r in rows] == want_bag
    got = numbers(rows)
    assert np.isfinite(got).all() and (got[:, 2:] >= 0).all()
    want = direct(StudentRuntime(onnx), scans, [GOAL] * N_SCANS)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-7)
    assert {r[CSV_COLUMNS.index("stop_reason")] for r in rows} == {""}
    ages = [float(r[CSV_COLUMNS.index("age_s")]) for r in rows]
    np.testing.assert_allclose(ages, RECEIVE_DELAY, rtol=1e-9)
    assert summary["stops"] == {}
    assert sorted(p.name for p in out.parent.iterdir()) == ["commands.csv"]  # no temp file left


def test_goal_in_the_odometry_frame(student, scans, tmp_path):
    _, onnx = student
    w = BagWriter(tmp_path / "odom", "sqlite3")
    poses = []
    for k, r in enumerate(scans):
        if k >= 3:  # odometry starts after the third scan: those are skipped
            pose = (0.1 * k, -0.05 * k, 0.2 * k - 1.0)
            w.odom("/odom", k, bag_ns(k) - 1_000_000, *pose)
            poses.append(pose)
        w.scan("/scan", k, r)
    w.close()
    goal_odom = (3.0, -1.0)
    out = tmp_path / "c.csv"
    summary = replay_bag(tmp_path / "odom", onnx, out, goal=goal_odom, goal_frame="odom")
    assert summary["odom_topic"] == "/odom"
    assert (summary["scans"], summary["rows"], summary["skipped"]) == (N_SCANS, N_SCANS - 3, 3)
    _, rows = read_csv(out)
    got = numbers(rows)
    goals = [goal_in_robot_frame(goal_odom, *p) for p in poses]
    np.testing.assert_allclose(got, direct(StudentRuntime(onnx), scans[3:], goals), rtol=1e-6)
    # The fixed robot-frame goal would have decided differently.
    assert not np.allclose(got, direct(StudentRuntime(onnx), scans[3:], [goal_odom] * 17))


def test_goal_in_robot_frame_geometry():
    gx, gy = goal_in_robot_frame((1.0, 3.0), 1.0, 1.0, math.pi / 2)  # goal 2 m to the north
    assert gx == pytest.approx(2.0) and gy == pytest.approx(0.0, abs=1e-12)  # → straight ahead
    gx, gy = goal_in_robot_frame((0.0, 0.0), 1.0, 0.0, 0.0)  # behind the robot
    assert (gx, gy) == pytest.approx((-1.0, 0.0))


def test_replay_topic_selection_and_errors(student, scans, tmp_path):
    _, onnx = student
    two = tmp_path / "two"
    w = BagWriter(two, "sqlite3")
    for k, r in enumerate(scans[:4]):
        w.scan("/front/scan", k, r)
        w.scan("/rear/scan", k, r[::-1].copy())
    w.close()
    with pytest.raises(DataError) as err:
        replay_bag(two, onnx, tmp_path / "x.csv", goal=GOAL)
    assert_house_message(str(err.value), "--scan-topic", "/front/scan", "/rear/scan")
    s = replay_bag(two, onnx, tmp_path / "x.csv", goal=GOAL, scan_topic="/rear/scan")
    assert s["rows"] == 4
    with pytest.raises(DataError) as err:
        replay_bag(two, onnx, tmp_path / "y.csv", goal=GOAL, scan_topic="/scan")
    assert_house_message(str(err.value), "/scan", "absent")
    with pytest.raises(DataError) as err:  # odom frame but no odometry in the bag
        replay_bag(
            two, onnx, tmp_path / "y.csv", goal=GOAL, goal_frame="odom", scan_topic="/rear/scan"
        )
    assert_house_message(str(err.value), "nav_msgs/msg/Odometry")

    w = BagWriter(tmp_path / "chat", "sqlite3")
    w.text("/chatter", 1, "no scans here")
    w.close()
    with pytest.raises(DataError) as err:
        replay_bag(tmp_path / "chat", onnx, tmp_path / "y.csv", goal=GOAL)
    assert_house_message(str(err.value), "sensor_msgs/msg/LaserScan", "/chatter")

    (tmp_path / "junk.bag").write_bytes(b"not a bag" * 10)
    with pytest.raises(DataError) as err:
        replay_bag(tmp_path / "junk.bag", onnx, tmp_path / "y.csv", goal=GOAL)
    assert_house_message(str(err.value), "junk.bag")
    with pytest.raises(DataError) as err:
        replay_bag(tmp_path / "missing", onnx, tmp_path / "y.csv", goal=GOAL)
    assert_house_message(str(err.value), "missing")
    with pytest.raises(ConfigError):
        replay_bag(two, onnx, tmp_path / "y.csv", goal=(math.nan, 0.0))
    with pytest.raises(ConfigError):
        replay_bag(two, onnx, tmp_path / "y.csv", goal=GOAL, goal_frame="map")
    assert not (tmp_path / "y.csv").exists()


def test_a_malformed_scan_names_the_message(student, scans, tmp_path):
    _, onnx = student
    w = BagWriter(tmp_path / "bad", "sqlite3")
    w.scan("/scan", 0, scans[0])
    w.scan("/scan", 1, np.zeros(0, dtype=np.float32))  # no beams
    w.close()
    with pytest.raises(DataError) as err:
        replay_bag(tmp_path / "bad", onnx, tmp_path / "c.csv", goal=GOAL)
    assert_house_message(str(err.value), "/scan message 2", "scan.ranges")
    assert not (tmp_path / "c.csv").exists()


# ------------------------------------------------------------------------------ CLI
def test_cli_replay(student, scans, tmp_path, capsys):
    _, onnx = student
    bag = write_scan_bag(tmp_path / "in.bag", "ros1", scans[:5])
    out = tmp_path / "c.csv"
    argv = ["replay", "--bag", str(bag), "--model", str(onnx), "--out", str(out)]
    assert main([*argv, "--goal", "2", "1"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["rows"] == 5 and len(read_csv(out)[1]) == 5
    argv[2] = str(tmp_path / "nope.bag")
    assert main([*argv, "--goal", "2", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "nope.bag" in err and err.startswith("pioneer: error:")


def test_cli_export_end_to_end(student, scans, tmp_path, capsys):
    model, _ = student
    run = tmp_path / "distill"
    save_student(model, run / "student.safetensors", info={"test": True})
    onnx = tmp_path / "exported" / "student.onnx"
    assert main(["export", "--model", str(run), "--out", str(onnx)]) == 0
    res = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert res["out"] == str(onnx) and res["kind"] == "mdn" and res["action_mode"] == "mode"
    assert res["parity"]["ok"] and 0 <= res["parity"]["max_abs_diff"] <= PARITY_TOL
    assert tuple(res["parity"]["outputs"]) == MDN_OUTPUTS
    assert sorted(p.name for p in onnx.parent.iterdir()) == ["student.onnx"]
    # The exported graph decides as the PyTorch model on a real scan.
    rt = StudentRuntime(onnx)
    inc = 2 * math.pi / N_BEAMS
    d = rt.step(scans[0], -math.pi, inc, 10.0, GOAL, range_min=0.1)
    from pioneer.sim.lidar import observation_from_scan

    x = torch.from_numpy(observation_from_scan(scans[0], -math.pi, inc, 10.0, GOAL, None, 0.1))
    with torch.no_grad():
        want = model.deterministic_action(x[None])[0].numpy()
    np.testing.assert_allclose([d.v, d.omega], want, rtol=1e-5, atol=1e-5)

    mean = tmp_path / "mean.onnx"
    ckpt = run / "student.safetensors"
    assert main(["export", "--model", str(ckpt), "--out", str(mean), "--action-mode", "mean"]) == 0
    assert json.loads(capsys.readouterr().out)["action_mode"] == "mean"
    assert StudentRuntime(mean).action_mode == "mean"


@pytest.mark.parametrize("bad", ["missing.safetensors", "empty-dir", "junk.safetensors"])
def test_cli_export_refuses_bad_paths(tmp_path, capsys, bad):
    (tmp_path / "empty-dir").mkdir()
    (tmp_path / "junk.safetensors").write_bytes(b"\x00" * 64)
    out = tmp_path / "s.onnx"
    assert main(["export", "--model", str(tmp_path / bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("pioneer: error:") and bad in err
    assert not out.exists()


# ------------------------------------------------------------------------------ hygiene
BLOCKED = (
    ROBOT_SIDE_PRELUDE
    + """
from pioneer.cli import main

argv = ["replay", "--bag", sys.argv[1], "--model", sys.argv[2], "--out", sys.argv[3]]
rc = main([*argv, "--goal", "2", "1"])
print(json.dumps({"rc": rc, "heavy": heavy()}))
"""
)


def test_cli_replay_runs_with_torch_numba_and_simulator_blocked(student, scans, tmp_path):
    _, onnx = student
    bag = write_scan_bag(tmp_path / "in", "sqlite3", scans[:3])
    out = tmp_path / "c.csv"
    proc = subprocess.run(
        [sys.executable, "-c", BLOCKED, str(bag), str(onnx), str(out)],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.strip().splitlines()
    assert json.loads(lines[-2])["rows"] == 3  # the CLI's summary
    assert json.loads(lines[-1]) == {"rc": 0, "heavy": []}
    assert len(read_csv(out)[1]) == 3


def test_cli_replay_refuses_a_model_of_another_width_before_reading(scans, tmp_path, capsys):
    """An ONNX graph 28 wide that claims the 29-D observation in its metadata: one line at load,
    not onnxruntime's traceback at the first scan, and no CSV."""
    bag = write_scan_bag(tmp_path / "run.bag", "ros1", scans)
    model = wrong_width_onnx(tmp_path / "w28.onnx")
    out = tmp_path / "cmds.csv"
    code = main(["replay", "--bag", str(bag), "--model", str(model), "--out", str(out),
                 "--goal", "2", "1"])  # fmt: skip
    one_error_line(capsys.readouterr().err, code, "input 'obs'", "28")
    assert not out.exists()
