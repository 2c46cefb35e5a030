"""The robot-side student: laser scan → 29-D observation → ONNX Runtime → command (SPEC 6).

Imports numpy, onnxruntime and :mod:`pioneer.laser` only — never torch, numba or the
simulator — so it runs on a robot computer with ``pip install pioneer-nav[deploy]``, starts in
well under a second and compiles nothing at its first scan. The ONNX file comes from
:func:`pioneer.learn.export.export_onnx`; its graph already computes the deterministic action
and the aleatoric/epistemic uncertainty, so a decision is one ``session.run`` on a batch of 1.

Wiring a ROS 2 ``sensor_msgs/LaserScan`` topic (sketch; rclpy and tf2 are not dependencies)::

    import rclpy
    from geometry_msgs.msg import Twist
    from sensor_msgs.msg import LaserScan
    from pioneer.deploy import StudentRuntime

    class StudentNode(rclpy.node.Node):
        def __init__(self):
            super().__init__("pioneer_student")
            self.runtime = StudentRuntime("student.onnx")
            self.cmd = self.create_publisher(Twist, "cmd_vel", 1)
            self.create_subscription(LaserScan, "scan", self.on_scan, 1)  # ~10 Hz

        def on_scan(self, msg):
            gx, gy = self.goal_in_base_link()  # goal (x, y) [m] in the robot frame, from tf2
            d = self.runtime.step(msg.ranges, msg.angle_min, msg.angle_increment,
                                  msg.range_max, (gx, gy), range_min=msg.range_min)
            out = Twist()
            out.linear.x, out.angular.z = d.v, d.omega
            self.cmd.publish(out)  # log d.aleatoric / d.epistemic, or gate on them (shield)

The scan must be in a frame whose origin is the robot centre, x forward, counter-clockwise
positive (``base_link``); if the laser is mounted off-centre or upside down, transform or
reverse the ranges first (a negative ``angle_increment`` is handled). ``+inf`` ranges mean "no
return" (REP 117) and NaNs are ignored, as in :func:`pioneer.laser.resample_scan`. The
runtime does not clip the command: pass it through the base's velocity limits (in
simulation, :func:`pioneer.sim.robot.clip_command` with the robot's ``RobotConfig`` does this).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from pioneer.errors import DataError, expect
from pioneer.laser import LidarConfig, observation_from_scan

__all__ = [
    "ONNX_FORMAT",
    "Decision",
    "OnnxStudentPolicy",
    "StudentRuntime",
    "make_onnx_student_policy",
]

ONNX_FORMAT = "pioneer.student-onnx/1"  # written by pioneer.learn.export.export_onnx


class Decision(NamedTuple):
    """One decision: the command and its uncertainty (NaN for a regression student)."""

    v: float  # [m/s]
    omega: float  # [rad/s]
    aleatoric: float  # [(m/s)² + (rad/s)²] Σ_k π_k Σ_d σ_kd²
    epistemic: float  # [(m/s)² + (rad/s)²] Σ_k π_k ‖μ_k − μ̄‖²


class StudentRuntime:
    """An exported student running under ONNX Runtime (CPU, ``threads`` intra-op threads).

    ``lidar`` must match the simulator's LiDAR the student was trained with (default
    :class:`LidarConfig`: 72 beams, sectors of 3, 5 m). Raises :class:`DataError` when the
    file is missing, not ONNX, or not a PioneeR student graph.
    """

    def __init__(
        self, onnx_path: str | Path, lidar: LidarConfig | None = None, threads: int = 1
    ) -> None:
        import onnxruntime as ort

        p = Path(onnx_path)
        fix = "re-export it with pioneer.learn.export.export_onnx"
        if not p.is_file():
            raise DataError(expect("student ONNX model", "an existing file", str(p), fix))
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = int(threads)
        opts.inter_op_num_threads = 1
        opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        opts.log_severity_level = 3
        try:
            self.session = ort.InferenceSession(
                str(p), sess_options=opts, providers=["CPUExecutionProvider"]
            )
        except Exception as exc:  # onnxruntime raises its own untyped errors
            raise DataError(
                expect(f"student ONNX model {p}", "a valid ONNX file", "", fix)
            ) from exc
        meta: Mapping[str, str] = self.session.get_modelmeta().custom_metadata_map
        if meta.get("format") != ONNX_FORMAT:
            raise DataError(expect(f"{p}: format", ONNX_FORMAT, meta.get("format"), fix))
        self.path = p
        self.kind: str = meta.get("kind", "?")
        self.action_mode: str = meta.get("action_mode", "?")
        self.config: dict[str, Any] = json.loads(meta.get("config", "{}"))
        self.lidar = lidar or LidarConfig()
        self.obs_dim = int(self.config.get("obs_dim", self.lidar.obs_dim))
        if self.obs_dim != self.lidar.obs_dim:
            raise DataError(
                expect(
                    f"{p}: obs_dim",
                    f"{self.lidar.obs_dim} (the LiDAR config's)",
                    self.obs_dim,
                    "pass the LidarConfig the student was trained with",
                )
            )
        self.outputs = [o.name for o in self.session.get_outputs()]
        self._fetch = [n for n in ("action", "aleatoric", "epistemic") if n in self.outputs]
        if "action" not in self._fetch:
            raise DataError(expect(f"{p}: outputs", "an 'action' output", self.outputs, fix))

    def decide_batch(
        self, obs: NDArray[np.floating]
    ) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]:
        """``(action (N, 2), aleatoric (N,), epistemic (N,))`` for observations ``(N, 29)``;
        the uncertainties are NaN for a regression (MLP) student."""
        x = np.ascontiguousarray(obs, dtype=np.float32)
        if x.ndim != 2 or x.shape[1] != self.obs_dim:
            raise DataError(
                expect("obs", f"shape (N, {self.obs_dim})", x.shape, "pass 29-D observations")
            )
        if not np.isfinite(x).all():
            raise DataError(expect("obs", "finite values", "NaN or inf", "check the scan"))
        got = self.session.run(self._fetch, {"obs": x})
        action = got[0]
        nan = np.full(x.shape[0], np.nan, dtype=np.float32)
        aleatoric = got[1] if len(got) > 1 else nan
        epistemic = got[2] if len(got) > 2 else nan
        return action, aleatoric, epistemic

    def decide(self, obs: NDArray[np.floating]) -> Decision:
        """The decision for one observation ``(29,)`` (see :class:`Decision`)."""
        a, al, ep = self.decide_batch(np.reshape(obs, (1, -1)))
        return Decision(float(a[0, 0]), float(a[0, 1]), float(al[0]), float(ep[0]))

    def step(
        self,
        ranges: NDArray[np.floating] | list[float],
        angle_min: float,
        angle_increment: float,
        range_max: float,
        goal_xy_robot: tuple[float, float] | NDArray[np.float64],
        range_min: float = 0.0,
    ) -> Decision:
        """Scan → command: ``ranges`` [m] with ROS ``LaserScan`` conventions (angles [rad]) and
        the goal ``(x, y)`` [m] in the robot frame → ``Decision(v, omega, aleatoric, epistemic)``
        (unpacks as a 4-tuple)."""
        obs = observation_from_scan(
            ranges, angle_min, angle_increment, range_max, goal_xy_robot, self.lidar, range_min
        )
        return self.decide(obs)


class OnnxStudentPolicy:
    """A :class:`~pioneer.control.policy.Policy` acting from the 29-D observation through
    :class:`StudentRuntime`; ``uncertainty`` holds ``(aleatoric, epistemic)`` per step of the
    current episode (cleared by ``reset``).

    It satisfies the protocol structurally and is registered as ``student-onnx`` by
    :mod:`pioneer.learn.policy`, so this module never imports the controllers."""

    def __init__(self, runtime: StudentRuntime | str | Path, name: str = "student-onnx") -> None:
        self.runtime = runtime if isinstance(runtime, StudentRuntime) else StudentRuntime(runtime)
        self.name = name
        self.uncertainty: list[tuple[float, float]] = []

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Start an episode (the student is deterministic; ``rng`` is unused)."""
        self.uncertainty = []

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """The command ``(v [m/s], ω [rad/s])``, shape ``(2,)``."""
        d = self.runtime.decide(obs)
        self.uncertainty.append((d.aleatoric, d.epistemic))
        return np.array([d.v, d.omega])


def make_onnx_student_policy(
    model: str | Path, scenario: str | None = None, name: str = "student-onnx"
) -> OnnxStudentPolicy:
    """Policy factory: ``model`` is an ONNX file; ``{scenario}`` in it is filled in, so one
    spec serves every scenario (e.g. ``students/{scenario}.onnx``)."""
    path = str(model).format(scenario=scenario) if scenario is not None else str(model)
    return OnnxStudentPolicy(path, name=name)
