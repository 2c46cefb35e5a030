"""Bound aliases for config fields: ``radius: Positive = 0.3`` (see :mod:`pioneer.config`).

Apart from :mod:`pioneer.config` because they need annotated-types at import, and the robot
runtime's configs, which declare no bounds, must not.
"""

from __future__ import annotations

from typing import Annotated

import annotated_types as at

__all__ = ["NonNegative", "Positive"]

Positive = Annotated[float, at.Gt(0)]  # a finite number > 0
NonNegative = Annotated[float, at.Ge(0)]  # a finite number >= 0
