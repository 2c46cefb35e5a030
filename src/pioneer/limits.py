"""The robot's command limits, defined once for the simulator and the robot runtime.

:class:`pioneer.sim.robot.RobotConfig` takes its defaults from here, and so does
:class:`pioneer.deploy.runtime.RuntimeConfig`, which clips every command that leaves the
runtime; the runtime cannot import the simulator (it would load numba), so the numbers live in
this dependency-free module rather than in either config.
"""

from __future__ import annotations

import math

__all__ = ["OMEGA_MAX", "V_MAX", "V_MIN"]

V_MIN = 0.0  # [m/s] the robot does not reverse
V_MAX = 0.8  # [m/s]
OMEGA_MAX = 0.4 * math.pi  # [rad/s] |ω| ≤ OMEGA_MAX
