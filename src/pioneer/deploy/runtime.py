"""The robot-side student: laser scan → 29-D observation → ONNX Runtime → command (paper §IV-B).

Imports numpy, onnxruntime and :mod:`pioneer.laser` only — never torch, numba or the
simulator — so it runs on a robot computer with the light distribution
``pip install ./runtime`` (numpy and onnxruntime, docs/deployment.md), starts in well under a
second and compiles nothing at its first scan. The ONNX file comes from
:func:`pioneer.learn.export.export_onnx`; its graph already computes the deterministic action
and the aleatoric/epistemic uncertainty, so a decision is one ``session.run`` on a batch of 1.

**Scan health.** Every :meth:`StudentRuntime.step` reports the share of the scan's beams that
are valid (a return in [range_min, range_max], or "no return": ``+inf`` or above
``range_max``), the angle around the robot the scan saw (``coverage_rad``: the simulator's 72
directions with a valid beam within 2.5°, × 5°) and the scan's age. It never drives on a scan
it cannot trust: it returns v = ω = 0 with ``stop_reason`` set to the first of
:data:`STOP_REASONS` that applies —

- ``"invalid"``: no beam returned a range (all NaN, all ``+inf``, all zero or below
  ``range_min``): a dead or blinded sensor, not an empty room;
- ``"sparse"``: fewer than ``min_valid_share`` (default 50 %) of the beams are valid;
- ``"stale"``: the scan's age is NaN, above ``max_age_s`` (default 0.5 s), or below
  −``max_age_s`` (a stamp from the future: the clocks disagree); without ``age_s`` the age
  is not checked;
- ``"action"``: the student's output was not finite.

A direction the scanner does not see (the rear of a 270° scanner, or beams without a valid
range) is filled by the rule ``RuntimeConfig.unseen`` (:data:`pioneer.laser.UNSEEN_RULES`);
the default, ``"obstacle"`` (range 0), never reports free space the sensor did not observe,
and the shipped students keep their success rate under it with a 270° scanner
(docs/student.md). A stop is not a fault: the next good scan drives again.

**Command limits.** Every command leaves clipped to ``v ∈ [v_min, v_max]`` and
``|ω| ≤ omega_max`` (:class:`RuntimeConfig`, defaults those of the simulated robot,
:mod:`pioneer.limits`): the MDN's slightly negative v (down to −0.045 m/s) leaves as 0.

Wiring a ROS 2 ``sensor_msgs/LaserScan`` topic (sketch; rclpy and tf2 are not dependencies)::

    import rclpy
    from geometry_msgs.msg import Twist
    from rclpy.time import Time
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
            age = (self.get_clock().now() - Time.from_msg(msg.header.stamp)).nanoseconds * 1e-9
            d = self.runtime.step(msg.ranges, msg.angle_min, msg.angle_increment,
                                  msg.range_max, (gx, gy), range_min=msg.range_min, age_s=age)
            out = Twist()
            out.linear.x, out.angular.z = d.v, d.omega  # 0, 0 on a stop (log d.stop_reason)
            self.cmd.publish(out)  # log d.aleatoric / d.epistemic, or gate on them (shield)

A student trained to read the previous observation or its previous command
(:class:`StudentInputs`) takes them from the runtime's previous decision: call
``runtime.reset()`` when the robot starts towards a new goal (the node above would do it in
its goal callback), as the simulator's episodes start from o_{t−1} = o_t and u_{t−1} = 0.

The scan must be in a frame whose origin is the robot centre, x forward, counter-clockwise
positive (``base_link``); if the laser is mounted off-centre or upside down, transform or
reverse the ranges first (a negative ``angle_increment`` is handled). A malformed message (no
beams, a zero or non-finite ``angle_increment``, a non-finite header, a non-finite goal) is a
caller's bug, not sensor health: it raises :class:`~pioneer.errors.DataError`.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.deploy.config import RuntimeConfig
from pioneer.deploy.inputs import InputMemory, StudentInputs
from pioneer.errors import DataError, expect
from pioneer.laser import (
    LidarConfig,
    ScanReading,
    observation_from_beams,
    read_scan,
)

__all__ = [
    "ONNX_FORMAT",
    "STOP_REASONS",
    "OnnxStudentPolicy",
    "RuntimeDecision",
    "StudentRuntime",
    "make_onnx_student_policy",
]

ONNX_FORMAT = "pioneer.student-onnx/1"  # written by pioneer.learn.export.export_onnx
STOP_REASONS = ("invalid", "sparse", "stale", "action")  # in the order they are checked


@dataclasses.dataclass(frozen=True)
class RuntimeDecision:
    """One decision: the command (clipped to the robot's limits; 0, 0 on a stop), its
    uncertainty, and the health of the scan it was made on (NaN where there was no scan or
    no age)."""

    v: float  # [m/s]
    omega: float  # [rad/s]
    aleatoric: float  # [(m/s)² + (rad/s)²] Σ_k π_k Σ_d σ_kd²; NaN for an MLP or a stop
    epistemic: float  # [(m/s)² + (rad/s)²] Σ_k π_k ‖μ_k − μ̄‖²; NaN for an MLP or a stop
    stop_reason: str | None = None  # one of STOP_REASONS, None when the student drove
    valid_share: float = math.nan  # share of the scan's beams that were valid
    coverage_rad: float = math.nan  # [rad] angle around the robot the scan saw (≤ 2π)
    age_s: float = math.nan  # [s] the scan's age as given (NaN: not given)

    @property
    def stopped(self) -> bool:
        """Whether this is a stop command (see :data:`STOP_REASONS`)."""
        return self.stop_reason is not None


class StudentRuntime:
    """An exported student running under ONNX Runtime (CPU, ``threads`` intra-op threads).

    ``lidar`` must match the simulator's LiDAR the student was trained with (default
    :class:`LidarConfig`: 72 beams, sectors of 3, 5 m); ``config`` sets the scan health
    limits, the unseen-direction rule and the command limits (:class:`RuntimeConfig`).
    Raises :class:`DataError` when the file is missing, not ONNX, or not a PioneeR student
    graph.
    """

    def __init__(
        self,
        onnx_path: str | Path,
        lidar: LidarConfig | None = None,
        threads: int = 1,
        config: RuntimeConfig | None = None,
    ) -> None:
        import onnxruntime as ort

        p = Path(onnx_path)
        fix = "export the student again: pioneer export --model CHECKPOINT --out FILE.onnx"
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
            reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:160]
            raise DataError(
                expect(f"student ONNX model {p}", "a valid ONNX file", reason, fix)
            ) from exc
        meta: Mapping[str, str] = self.session.get_modelmeta().custom_metadata_map
        if meta.get("format") != ONNX_FORMAT:
            raise DataError(expect(f"{p}: format", ONNX_FORMAT, meta.get("format"), fix))
        self.path = p
        self.kind: str = meta.get("kind", "?")
        self.action_mode: str = meta.get("action_mode", "?")
        self.config: dict[str, Any] = json.loads(meta.get("config", "{}"))
        self.lidar = lidar or LidarConfig()
        self.runtime_config = config or RuntimeConfig()
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
        # a student that also reads o_{t−1} or u_{t−1}: the runtime remembers them
        self.inputs = StudentInputs.of(self.config)
        self.input_dim = self.inputs.width(self.obs_dim)
        self.memory = InputMemory(self.inputs, self.runtime_config)
        self._check_input(p, fix)
        self.outputs = [o.name for o in self.session.get_outputs()]
        self._fetch = [n for n in ("action", "aleatoric", "epistemic") if n in self.outputs]
        if "action" not in self._fetch:
            raise DataError(expect(f"{p}: outputs", "an 'action' output", self.outputs, fix))

    def _check_input(self, p: Path, fix: str) -> None:
        """The graph's input must be ``obs`` of ``(N, input_dim)`` (the observation, and
        o_{t−1} or u_{t−1} for a student that reads them): a graph of another width, whatever
        its metadata says, would fail on its first decision (a named batch size passes; a
        fixed width must be the inputs')."""
        inputs = {i.name: list(i.shape) for i in self.session.get_inputs()}
        shape = inputs.get("obs")
        if shape is None:
            raise DataError(expect(f"{p}: inputs", "one named 'obs'", sorted(inputs), fix))
        width = shape[-1] if len(shape) == 2 else None
        if len(shape) != 2 or (isinstance(width, int) and width != self.input_dim):
            raise DataError(
                expect(
                    f"{p}: input 'obs'",
                    f"shape (N, {self.input_dim}) (the {self.input_dim}-D inputs)",
                    f"shape {tuple(shape)}",
                    "export the student trained on this observation (pioneer export)",
                )
            )

    def reset(self) -> None:
        """Start an episode: forget the previous observation and command."""
        self.memory.reset()

    def raw_outputs(
        self, x: NDArray[np.floating]
    ) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]:
        """``(action (N, 2), aleatoric (N,), epistemic (N,))`` for inputs ``(N, input_dim)``:
        the 29-D observations, followed for a student that reads them by o_{t−1} and u_{t−1}
        (:meth:`StudentInputs.stack`). The graph's raw outputs, for analysis (the action is not
        clipped; :meth:`from_observation` and :meth:`step` clip it); the uncertainties are NaN
        for a regression (MLP) student."""
        x = np.ascontiguousarray(x, dtype=np.float32)
        if x.ndim != 2 or x.shape[1] != self.input_dim:
            what = f"{self.input_dim}-D inputs (StudentInputs.stack)"
            raise DataError(expect("obs", f"shape (N, {self.input_dim})", x.shape, f"pass {what}"))
        if not np.isfinite(x).all():
            raise DataError(expect("obs", "finite values", "NaN or inf", "check the scan"))
        got = self.session.run(self._fetch, {"obs": x})
        action = got[0]
        nan = np.full(x.shape[0], np.nan, dtype=np.float32)
        aleatoric = got[1] if len(got) > 1 else nan
        epistemic = got[2] if len(got) > 2 else nan
        return action, aleatoric, epistemic

    def from_observation(self, obs: NDArray[np.floating]) -> RuntimeDecision:
        """The decision for one observation ``(29,)``, clipped to the command limits (a
        non-finite action is a stop with reason ``"action"``); no scan, so no scan health.
        A student reading o_{t−1} or u_{t−1} takes them from this runtime's previous decision
        (:meth:`reset` at an episode's start)."""
        d = self._decide(obs, math.nan, math.nan, math.nan)
        self.memory.note(None if d.stopped else obs, np.array([d.v, d.omega]))
        return d

    def step(
        self,
        ranges: NDArray[np.floating] | list[float],
        angle_min: float,
        angle_increment: float,
        range_max: float,
        goal_xy_robot: tuple[float, float] | NDArray[np.float64],
        range_min: float = 0.0,
        *,
        age_s: float | None = None,
    ) -> RuntimeDecision:
        """Scan → command: ``ranges`` [m] with ROS ``LaserScan`` conventions (angles [rad]),
        the goal ``(x, y)`` [m] in the robot frame and the scan's age [s] at decision time
        (now − header stamp) → a :class:`RuntimeDecision`, a stop when the scan is unhealthy (module
        docstring). Without ``age_s`` the age is not checked (reported NaN): a robot node
        should always pass it."""
        cfg = self.runtime_config
        reading = read_scan(
            ranges, angle_min, angle_increment, range_max, self.lidar, range_min, cfg.unseen
        )
        obs = observation_from_beams(reading.beams, goal_xy_robot, self.lidar)
        age = math.nan if age_s is None else float(age_s)
        reason = self._scan_fault(reading, age_s)
        if reason is not None:
            d = _stop(reason, reading.valid_share, reading.coverage_rad, age)
        else:
            d = self._decide(obs, reading.valid_share, reading.coverage_rad, age)
        # after a stop the history restarts: the next observation is its own o_{t−1}
        self.memory.note(None if d.stopped else obs, np.array([d.v, d.omega]))
        return d

    def _scan_fault(self, reading: ScanReading, age_s: float | None) -> str | None:
        """The first of STOP_REASONS the scan has, or None."""
        cfg = self.runtime_config
        if reading.returns == 0:
            return "invalid"
        if reading.valid_share < cfg.min_valid_share:
            return "sparse"
        if age_s is not None and not abs(float(age_s)) <= cfg.max_age_s:  # NaN: stale too
            return "stale"
        return None

    def _decide(
        self, obs: NDArray[np.floating], valid_share: float, coverage_rad: float, age_s: float
    ) -> RuntimeDecision:
        a, al, ep = self.raw_outputs(self.memory.inputs(obs))
        v, w = float(a[0, 0]), float(a[0, 1])
        if not (math.isfinite(v) and math.isfinite(w)):
            return _stop("action", valid_share, coverage_rad, age_s)
        cfg = self.runtime_config
        return RuntimeDecision(
            v=min(max(v, cfg.v_min), cfg.v_max),
            omega=min(max(w, -cfg.omega_max), cfg.omega_max),
            aleatoric=float(al[0]),
            epistemic=float(ep[0]),
            valid_share=valid_share,
            coverage_rad=coverage_rad,
            age_s=age_s,
        )


def _stop(reason: str, valid_share: float, coverage_rad: float, age_s: float) -> RuntimeDecision:
    return RuntimeDecision(
        v=0.0,
        omega=0.0,
        aleatoric=math.nan,
        epistemic=math.nan,
        stop_reason=reason,
        valid_share=valid_share,
        coverage_rad=coverage_rad,
        age_s=age_s,
    )


class OnnxStudentPolicy:
    """A :class:`~pioneer.envs.policy.Policy` acting from the 29-D observation through
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
        self.runtime.reset()

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """The command ``(v [m/s], ω [rad/s])``, shape ``(2,)``."""
        d = self.runtime.from_observation(obs)
        self.uncertainty.append((d.aleatoric, d.epistemic))
        return np.array([d.v, d.omega])


def make_onnx_student_policy(
    model: str | Path, scenario: str | None = None, name: str = "student-onnx"
) -> OnnxStudentPolicy:
    """Policy factory: ``model`` is an ONNX file; ``{scenario}`` in it is filled in, so one
    spec serves every scenario (e.g. ``students/{scenario}.onnx``)."""
    path = str(model).format(scenario=scenario) if scenario is not None else str(model)
    return OnnxStudentPolicy(path, name=name)
