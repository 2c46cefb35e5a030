"""The files a registered policy loads: checked before a run starts, recorded with its results.

Two kinds of function, named by the policy registry (:mod:`pioneer.control.registry`):

- a *check* ``(scenario, kwargs) -> None`` raises before any output is written when a part the
  policy would load is missing or does not fit the scenario — the shipped parts (a
  :class:`~pioneer.errors.DataError` from the locators in :mod:`pioneer.data`) and, for the
  teacher, a given reward model: its features must be the scenario's (a static-study (x, y)
  reward cannot score an elevator rollout);
- a *files* function ``(scenario, params) -> {name: path}`` names the shipped files a policy
  falls back on when a path parameter is left unset (the teacher's default reward is fitted on
  the shipped demonstrations; a student without ``checkpoint`` is the shipped one), so that a
  run records what it loaded, not only what it was told.

Neither imports torch.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pioneer.data import (
    shipped_crowdnav_weights,
    shipped_demos,
    shipped_sb3_weights,
    shipped_student_for,
)

__all__ = [
    "check_crowdnav",
    "check_sb3",
    "check_shield",
    "check_student",
    "check_teacher",
    "crowdnav_files",
    "sb3_files",
    "shield_files",
    "student_files",
    "teacher_files",
]


def _path(value: object, scenario: str) -> str:
    return str(value).replace("{scenario}", scenario)


def check_teacher(scenario: str, kwargs: Mapping[str, Any]) -> None:
    """The shipped demos behind the default reward, or the given reward model, which must
    load and fit ``scenario`` (:func:`pioneer.reward.recipe.check_reward_fits`)."""
    reward = kwargs.get("reward")
    if kwargs.get("density", True) and not reward:
        shipped_demos(scenario)
    if kwargs.get("density", True) and reward:
        from pioneer.reward.density import DensityReward
        from pioneer.reward.recipe import check_reward_fits

        path = _path(reward, scenario)
        check_reward_fits(DensityReward.load(path), scenario, path)


def check_student(scenario: str, kwargs: Mapping[str, Any]) -> None:
    """Without ``checkpoint`` a student is the scenario's shipped one of its kind."""
    if not kwargs.get("checkpoint"):
        shipped_student_for(scenario, kwargs)


def check_shield(scenario: str, kwargs: Mapping[str, Any]) -> None:
    """The shielded MDN student, and the teacher it hands over to (with its reward)."""
    check_student(scenario, {**kwargs, "kind": "mdn"})
    if _hands_over_to_teacher(kwargs):
        check_teacher(scenario, {"reward": kwargs.get("reward")})


def check_crowdnav(scenario: str, kwargs: Mapping[str, Any]) -> None:
    """Without ``weights`` CrowdNav++ loads the scenario's shipped weights of its variant."""
    crowdnav_files(scenario, kwargs)


def check_sb3(scenario: str, kwargs: Mapping[str, Any]) -> None:
    """Without ``weights`` the SB3 policy is the scenario's shipped one."""
    sb3_files(scenario, kwargs)


def _hands_over_to_teacher(kwargs: Mapping[str, Any]) -> bool:
    return bool(
        kwargs.get("mode", "handover") == "handover"
        and kwargs.get("fallback", "teacher") == "teacher"
    )


def teacher_files(scenario: str, params: Mapping[str, Any]) -> dict[str, Path]:
    """Without ``reward``, the shipped demonstrations the default reward is fitted on."""
    if not params.get("density", True) or params.get("reward"):
        return {}
    from pioneer.reward.recipe import default_reward_demos

    return default_reward_demos(scenario)


def student_files(scenario: str, params: Mapping[str, Any]) -> dict[str, Path]:
    """Without ``checkpoint``, the shipped student of its kind."""
    if params.get("checkpoint"):
        return {}
    return {"checkpoint": shipped_student_for(scenario, params)}


def shield_files(scenario: str, params: Mapping[str, Any]) -> dict[str, Path]:
    """The student's files, and the handover teacher's."""
    files = student_files(scenario, {**params, "kind": "mdn", "general": False})
    if _hands_over_to_teacher(params):
        files.update(teacher_files(scenario, {"reward": params.get("reward")}))
    return files


def crowdnav_files(scenario: str, params: Mapping[str, Any]) -> dict[str, Path]:
    """Without ``weights``, the shipped weights of its variant."""
    if params.get("weights"):
        return {}
    return {"weights": shipped_crowdnav_weights(scenario, str(params.get("variant", "ppo")))}


def sb3_files(scenario: str, params: Mapping[str, Any]) -> dict[str, Path]:
    """Without ``weights``, the scenario's shipped SB3 policy."""
    if params.get("weights"):
        return {}
    return {"weights": shipped_sb3_weights(scenario)}
