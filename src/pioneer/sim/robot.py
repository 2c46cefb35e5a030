"""Unicycle robot: configuration, command clipping and exact integration.

Kinematics (paper §III-A): ṗx = v cos θ, ṗy = v sin θ, θ̇ = ω. With the command held over a
step of length h the solution is an arc (ω ≠ 0) or a straight line (ω = 0); we integrate it
exactly rather than with an Euler step, so a rollout at 0.3 s matches three steps at 0.1 s.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from pioneer.bounds import NonNegative, Positive
from pioneer.config import Config
from pioneer.errors import CommandError, expect
from pioneer.limits import OMEGA_MAX, V_MAX, V_MIN, check_speed_range

__all__ = ["RobotConfig", "clip_command", "integrate_unicycle", "validate_command", "wrap_angle"]


@dataclasses.dataclass(frozen=True)
class RobotConfig(Config):
    """Robot body and command limits."""

    radius: Positive = 0.3  # [m] r_r
    v_min: NonNegative = V_MIN  # [m/s] (defaults: pioneer.limits, shared with the runtime)
    v_max: Positive = V_MAX  # [m/s]
    omega_max: Positive = OMEGA_MAX  # [rad/s] |ω| ≤ omega_max

    def __post_init__(self) -> None:
        check_speed_range("RobotConfig", self.v_min, self.v_max)

    @property
    def command_low(self) -> NDArray[np.float64]:
        """Lower command bound ``[v_min, -omega_max]``."""
        return np.array([self.v_min, -self.omega_max])

    @property
    def command_high(self) -> NDArray[np.float64]:
        """Upper command bound ``[v_max, omega_max]``."""
        return np.array([self.v_max, self.omega_max])


def validate_command(u: NDArray[np.float64] | list[float], batch: int) -> NDArray[np.float64]:
    """Return ``u`` as a float64 array of shape ``(batch, 2)``; refuse NaN/inf or a bad shape.

    A single command of shape ``(2,)`` is accepted when ``batch == 1``.
    """
    arr = np.asarray(u, dtype=np.float64)
    if arr.shape == (2,) and batch == 1:
        arr = arr.reshape(1, 2)
    if arr.shape != (batch, 2):
        raise CommandError(
            expect(
                "command", f"shape ({batch}, 2) of (v, ω)", arr.shape, "pass one (v, ω) per copy"
            )
        )
    if not np.all(np.isfinite(arr)):
        raise CommandError(
            expect("command", "finite (v [m/s], ω [rad/s])", arr.tolist(), "remove NaN/inf values")
        )
    return arr


def clip_command(u: NDArray[np.float64], cfg: RobotConfig) -> NDArray[np.float64]:
    """Clip commands ``(..., 2)`` to ``v ∈ [v_min, v_max]``, ``ω ∈ [-omega_max, omega_max]``."""
    return np.clip(u, cfg.command_low, cfg.command_high)


@njit(cache=True, inline="always")
def wrap_angle(a: float) -> float:
    """Wrap an angle [rad] to (−π, π] (for compiled loops; arrays and the light install:
    :func:`pioneer.laser.wrap_angles`, bit for bit the same)."""
    r = math.pi - ((math.pi - a) % (2.0 * math.pi))
    return r if r > -math.pi else math.pi


@njit(cache=True, inline="always")
def integrate_unicycle(
    x: float, y: float, th: float, v: float, w: float, h: float
) -> tuple[float, float, float]:
    """Exact unicycle motion over ``h`` seconds with ``(v, ω)`` held constant.

    The arc's chord has length v·h·sinc(ωh/2) and points along θ + ωh/2; written this way it
    has no cancellation for small ω (the textbook (v/ω)(sin θ' − sin θ) loses all precision
    near ω → 0) and needs no straight-line special case.
    """
    half = 0.5 * w * h
    # sinc(half); below 1e-4 its Taylor series 1 − half²/6 is exact to < 1e-17.
    f = math.sin(half) / half if abs(half) > 1e-4 else 1.0 - half * half / 6.0
    chord = v * h * f
    mid = th + half
    th1 = th + w * h
    th1 = th1 if -math.pi < th1 <= math.pi else wrap_angle(th1)  # exact when no wrap is needed
    return x + chord * math.cos(mid), y + chord * math.sin(mid), th1
