"""The robot runtime's settings (:class:`RuntimeConfig`): scan health limits, the fill rule of
unseen directions and the command limits, bounds checked by hand (the light robot install has
no annotated-types)."""

from __future__ import annotations

import dataclasses

from pioneer.config import Config, check_nonnegative, check_positive, check_within
from pioneer.laser import DEFAULT_UNSEEN, UnseenRule
from pioneer.limits import OMEGA_MAX, V_MAX, V_MIN, check_speed_range

__all__ = ["RuntimeConfig"]


@dataclasses.dataclass(frozen=True)
class RuntimeConfig(Config):
    """Scan health limits, the fill rule of unseen directions and the robot's command limits.

    ``max_age_s``: the student decides every 0.1 s on a scan whose stamp is the start of its
    0.1 s sweep, and drivers add 10–50 ms of transport, so a fresh scan is 0.1–0.2 s old;
    0.5 s tolerates two or three lost scans of a 10 Hz scanner, while the robot at v_max and a
    human walking at 0.6 m/s close at most 0.7 m unseen — beyond that, stop.
    ``min_valid_share``: below half the beams valid, the scan more likely comes from a dirty
    window, a blocked sensor or a driver fault than from the room.
    """

    max_age_s: float = 0.5  # [s]
    min_valid_share: float = 0.5  # share of the scan's beams in [0, 1]
    unseen: UnseenRule = DEFAULT_UNSEEN  # fill of unseen directions (pioneer.laser)
    v_min: float = V_MIN  # [m/s]
    v_max: float = V_MAX  # [m/s]
    omega_max: float = OMEGA_MAX  # [rad/s] |ω| ≤ omega_max

    def __post_init__(self) -> None:
        # Bounds by hand, not declared: the light install has no annotated-types.
        check_positive("RuntimeConfig", "max_age_s", self.max_age_s)
        check_within("RuntimeConfig", "min_valid_share", self.min_valid_share, 0.0, 1.0)
        check_nonnegative("RuntimeConfig", "v_min", self.v_min)
        check_positive("RuntimeConfig", "v_max", self.v_max)
        check_positive("RuntimeConfig", "omega_max", self.omega_max)
        check_speed_range("RuntimeConfig", self.v_min, self.v_max)
