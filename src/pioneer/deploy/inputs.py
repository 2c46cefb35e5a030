"""What a student reads besides the observation, built one way for training, the torch student
and the robot runtime (:class:`StudentInputs`), and step by step on the robot
(:class:`InputMemory`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.deploy.config import RuntimeConfig
from pioneer.errors import ConfigError, DataError, expect
from pioneer.laser import LidarConfig, mirror_map

__all__ = ["InputMemory", "StudentInputs"]


@dataclasses.dataclass(frozen=True)
class StudentInputs:
    """What a student reads besides the observation o_t (beyond the paper; both off by
    default): the previous step's observation o_{t−1} (its motion: where people go, not only
    where they are) and u_{t−1}, the command the robot sent at the previous step. Its inputs
    are ``[o_t, o_{t−1}?, u_{t−1}?]``; at an episode's start o_{t−1} = o_t and u_{t−1} = 0.

    One definition for training (:meth:`of_episode`, DAgger's aggregate), the torch student and
    this runtime (:class:`InputMemory`, step by step), so all three build the same inputs.
    """

    previous_observation: bool = False
    previous_command: bool = False

    @classmethod
    def of(cls, config: Mapping[str, Any]) -> StudentInputs:
        """The inputs of a student from its config (a ``StudentConfig`` as a dict)."""
        return cls(
            bool(config.get("previous_observation", False)),
            bool(config.get("previous_command", False)),
        )

    def width(self, obs_dim: int) -> int:
        """The network's input width for an ``obs_dim``-D observation."""
        return obs_dim * (2 if self.previous_observation else 1) + (
            2 if self.previous_command else 0
        )

    def mirror_map(self, obs_dim: int) -> tuple[NDArray[np.intp], NDArray[np.float32]]:
        """The mirror image (world mirrored x → −x) of this student's inputs as a gather and a
        sign, ``index (width,)`` and ``sign (width,)``: o_t and o_{t−1} as
        :func:`pioneer.laser.mirror_map`, u_{t−1} = (v, ω) → (v, −ω). An ``obs_dim`` other than
        the LiDAR's observation width has no mirror (refused)."""
        lidar = LidarConfig()
        if obs_dim != lidar.obs_dim:
            raise ConfigError(
                expect(
                    "a mirror-true observation",
                    f"the LiDAR's {lidar.obs_dim}-D observation",
                    obs_dim,
                    "mirror only students of the default observation",
                )
            )
        one, one_sign = mirror_map(lidar)
        index, sign = [one], [one_sign]
        if self.previous_observation:
            index.append(one + obs_dim)
            sign.append(one_sign)
        if self.previous_command:
            start = obs_dim * (2 if self.previous_observation else 1)
            index.append(np.array([start, start + 1], dtype=np.intp))
            sign.append(np.array([1.0, -1.0], dtype=np.float32))
        return np.concatenate(index), np.concatenate(sign)

    def stack(
        self,
        obs: NDArray[np.floating],
        previous_obs: NDArray[np.floating] | None = None,
        previous_command: NDArray[np.floating] | None = None,
    ) -> NDArray[np.float32]:
        """``[o_t, o_{t−1}?, u_{t−1}?]`` as ``(N, width)`` float32 from ``(N, obs_dim)``
        observations and the parts this student reads (and no others)."""
        parts = [np.asarray(obs, dtype=np.float32)]
        for name, used, part, cols in (
            ("previous_obs", self.previous_observation, previous_obs, parts[0].shape[-1]),
            ("previous_command", self.previous_command, previous_command, 2),
        ):
            if used != (part is not None):
                wanted = f"an array (N, {cols})" if used else "None (this student does not read it)"
                raise DataError(expect(name, wanted, type(part).__name__, f"pass {wanted}"))
            if part is not None:
                x = np.asarray(part, dtype=np.float32)
                if x.shape != (parts[0].shape[0], cols):
                    want = f"shape ({parts[0].shape[0]}, {cols})"
                    raise DataError(expect(name, want, x.shape, "align it with obs"))
                parts.append(x)
        return np.ascontiguousarray(np.concatenate(parts, axis=1))

    def of_episode(
        self,
        obs: NDArray[np.floating],
        sent: NDArray[np.floating],
        limits: RuntimeConfig | None = None,
    ) -> NDArray[np.float32]:
        """The inputs of every step of one episode ``(T, width)`` from its observations
        ``(T, obs_dim)`` and the commands chosen at each step ``sent (T, 2)``, each u_{t−1}
        clipped to the command limits (``limits``, default :class:`RuntimeConfig`'s) as the
        robot ran it."""
        o = np.asarray(obs, dtype=np.float32)
        before = np.concatenate([o[:1], o[:-1]]) if self.previous_observation else None
        command = None
        if self.previous_command:
            lo, hi = _limits(limits)
            u = np.asarray(sent, dtype=np.float64).reshape(-1, 2)
            command = np.zeros_like(u)
            command[1:] = np.clip(u[:-1], lo, hi)
        return self.stack(o, before, command)


class InputMemory:
    """A student's inputs step by step: remembers the previous observation and the command
    sent (:class:`StudentInputs`); ``reset`` at an episode's start."""

    def __init__(self, inputs: StudentInputs, limits: RuntimeConfig | None = None) -> None:
        self.kind = inputs
        self._low, self._high = _limits(limits)
        self.reset()

    def reset(self) -> None:
        """Forget the previous observation and command (o_{t−1} = o_t, u_{t−1} = 0 next)."""
        self._obs: NDArray[np.float32] | None = None
        self._command = np.zeros(2)

    def inputs(self, obs: NDArray[np.floating]) -> NDArray[np.float32]:
        """The inputs ``(1, width)`` for observation ``obs (obs_dim,)`` at this step."""
        o = np.asarray(obs, dtype=np.float32).reshape(1, -1)
        before = (o if self._obs is None else self._obs) if self.kind.previous_observation else None
        command = self._command.reshape(1, 2) if self.kind.previous_command else None
        return self.kind.stack(o, before, command)

    def note(self, obs: NDArray[np.floating] | None, command: NDArray[np.floating]) -> None:
        """After a step: the observation decided on (None: the history restarts, as after a
        scan the runtime did not trust) and the command sent (clipped to the limits)."""
        self._obs = None if obs is None else np.asarray(obs, dtype=np.float32).reshape(1, -1)
        self._command = np.clip(np.asarray(command, dtype=np.float64), self._low, self._high)


def _limits(limits: RuntimeConfig | None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    cfg = limits or RuntimeConfig()
    return np.array([cfg.v_min, -cfg.omega_max]), np.array([cfg.v_max, cfg.omega_max])
