"""The robot's command limits, defined once for the simulator and the robot runtime.

:class:`pioneer.sim.robot.RobotConfig` takes its defaults from here, and so does
:class:`pioneer.deploy.config.RuntimeConfig`, which clips every command that leaves the
runtime; the runtime cannot import the simulator (it would load numba), so the numbers live in
this dependency-free module rather than in either config, beside the one rule both configs
check (:func:`check_speed_range`).
"""

from __future__ import annotations

import math

from pioneer.errors import ConfigError, expect

__all__ = ["OMEGA_MAX", "V_MAX", "V_MIN", "check_speed_range"]

V_MIN = 0.0  # [m/s] the robot does not reverse
V_MAX = 0.8  # [m/s]
OMEGA_MAX = 0.4 * math.pi  # [rad/s] |ω| ≤ OMEGA_MAX


def check_speed_range(owner: str, v_min: float, v_max: float) -> None:
    """Raise :class:`~pioneer.errors.ConfigError` unless ``v_min ≤ v_max`` (``owner``: the
    config class, named in the message)."""
    if v_min > v_max:
        raise ConfigError(expect(f"{owner}.v_min", f"<= v_max={v_max}", v_min, "lower v_min"))
