"""Light checks of the shipped parts a policy would load, run before an evaluation starts.

The policy registry (:mod:`pioneer.control.registry`) names these by string; each takes the
scenario and the policy's keyword arguments and raises :class:`~pioneer.errors.DataError`
(from the locators in :mod:`pioneer.data`) when the part is missing. None imports torch.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from pioneer.data import (
    shipped_crowdnav_weights,
    shipped_demos,
    shipped_sb3_weights,
    shipped_student_for,
)

__all__ = ["crowdnav", "sb3", "shield", "student", "teacher"]


def teacher(scenario: str, kwargs: Mapping[str, Any]) -> None:
    """The teacher's default reward is fitted on the scenario's shipped demos."""
    if kwargs.get("density", True) and not kwargs.get("reward"):
        shipped_demos(scenario)


def student(scenario: str, kwargs: Mapping[str, Any]) -> None:
    """Without ``checkpoint`` a student is the scenario's shipped one of its kind."""
    if not kwargs.get("checkpoint"):
        shipped_student_for(scenario, kwargs)


def shield(scenario: str, kwargs: Mapping[str, Any]) -> None:
    """The shielded MDN student, and the teacher it hands over to."""
    student(scenario, {**kwargs, "kind": "mdn"})
    handover = kwargs.get("mode", "handover") == "handover"
    if handover and kwargs.get("fallback", "teacher") == "teacher":
        teacher(scenario, {"reward": kwargs.get("reward")})


def crowdnav(scenario: str, kwargs: Mapping[str, Any]) -> None:
    """Without ``weights`` CrowdNav++ loads the scenario's shipped weights."""
    if not kwargs.get("weights"):
        shipped_crowdnav_weights(scenario, str(kwargs.get("variant", "ppo")))


def sb3(scenario: str, kwargs: Mapping[str, Any]) -> None:
    """Without ``weights`` the SB3 policy is the scenario's shipped one."""
    if not kwargs.get("weights"):
        shipped_sb3_weights(scenario)
