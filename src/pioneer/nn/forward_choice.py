"""Who computes a trained network's acting step: NumPy or the PyTorch module.

A policy asks its network for one action per 0.1 s step of one world — a batch of one —
where PyTorch spends its time dispatching dozens of small operators rather than computing.
The acting policies of CrowdNav++ (:mod:`pioneer.baselines.crowdnav.inference`) and of the
students (:mod:`pioneer.learn.inference`) therefore compute that step with the same float32
formulas in NumPy by default; ``"torch"`` keeps the module's own forward as the reference.
The two agree to float32 rounding, not bit for bit (other libraries' products and e^x):
the tests compare them step by step, and docs/student.md and docs/baselines.md compare them
on validation episodes. Training always uses the module.
"""

from __future__ import annotations

import typing
from typing import Literal

from pioneer.errors import ConfigError, expect

__all__ = ["FORWARD", "FORWARDS", "Forward", "check_forward"]

Forward = Literal["numpy", "torch"]
FORWARDS: tuple[str, ...] = typing.get_args(Forward)
FORWARD: Forward = "numpy"  # the acting default; "torch" is the reference


def check_forward(owner: str, forward: str) -> None:
    """Raise :class:`ConfigError` unless ``forward`` is one of :data:`FORWARDS`."""
    if forward not in FORWARDS:
        raise ConfigError(
            expect(f"{owner} forward", f"one of {list(FORWARDS)}", forward, "pick one")
        )
