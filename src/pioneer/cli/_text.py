"""What a command prints and records beside its results: a number as the tables print it,
and the command line as typed."""

from __future__ import annotations

import math
import sys

__all__ = ["command_line", "number"]


def number(value: float | None, spec: str, unit: str = "") -> str:
    """``value`` formatted by ``spec`` (with `` unit`` after it), or "–" where there is none
    (``None``, NaN, ±∞: a mean over no episode), as the tables print it; never ``nan``."""
    if value is None or not math.isfinite(value):
        return "–"
    return f"{value:{spec}}" + (f" {unit}" if unit else "")


def command_line() -> str:
    """The command as typed, recorded with the outputs (empty when not run as ``pioneer``)."""
    return " ".join(["pioneer", *sys.argv[1:]]) if sys.argv[0].endswith("pioneer") else ""
