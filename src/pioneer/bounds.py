"""Bound aliases for config fields: ``radius: Positive = 0.3`` (see :mod:`pioneer.config`).

Apart from :mod:`pioneer.config` because they need annotated-types at import, and the robot
runtime's configs, which declare no bounds, must not.
"""

from __future__ import annotations

import math
from typing import Annotated

import annotated_types as at

from pioneer.config import Ordered

__all__ = [
    "Count",
    "Finite",
    "NonNegative",
    "NonNegativeInt",
    "Positive",
    "Span",
    "UnitInterval",
]

Positive = Annotated[float, at.Gt(0)]  # a finite number > 0
NonNegative = Annotated[float, at.Ge(0)]  # a finite number >= 0
Finite = Annotated[float, at.Interval(gt=-math.inf, lt=math.inf)]  # any finite number
UnitInterval = Annotated[float, at.Interval(ge=0, le=1)]  # a finite number in [0, 1]
Count = Annotated[int, at.Ge(1)]  # an integer >= 1
NonNegativeInt = Annotated[int, at.Ge(0)]  # an integer >= 0
Span = Annotated[tuple[float, float], Ordered()]  # (low, high): finite, low <= high
