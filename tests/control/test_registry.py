"""The lazy policy registry: names resolve without imports; plugins via entry points."""

from __future__ import annotations

import importlib.metadata
import subprocess
import sys
from typing import Any

import pytest

from pioneer.baselines.classic import GoalPolicy
from pioneer.control import registry
from pioneer.errors import ConfigError, DataError


def test_every_name_builds_in_a_fresh_interpreter_without_prior_imports() -> None:
    code = (
        "import sys\n"
        "from pioneer.control.registry import policy_names, build_policy\n"
        "assert 'torch' not in sys.modules\n"
        "assert 'student-mdn' in policy_names() and 'crowdnav++' in policy_names()\n"
        "assert 'torch' not in sys.modules\n"
        "print(type(build_policy('student-mdn', 'hr-rl')).__name__)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "StudentPolicy"


def test_part_checks_refuse_a_missing_shipped_part_without_building() -> None:
    registry.check_parts("teacher", "hr-rl", {})
    registry.check_parts("teacher", "no-such-demos", {"reward": "r.npz"})  # own reward: no demos
    with pytest.raises(DataError, match="shipped student"):
        registry.check_parts("student-mlp", "static", {})


class _EP:
    def __init__(self, name: str, value: str) -> None:
        self.name, self.value = name, value


def _plugins(monkeypatch: pytest.MonkeyPatch, eps: list[_EP]) -> None:
    monkeypatch.setattr(registry, "_ENTRIES", dict(registry._ENTRIES))
    monkeypatch.setattr(registry, "_PLUGINS_LOADED", False)
    monkeypatch.setattr(registry, "_UNRESOLVED_PLUGINS", set())

    def entry_points(group: str) -> list[Any]:
        assert group == registry.ENTRY_POINT_GROUP
        return list(eps)

    monkeypatch.setattr(importlib.metadata, "entry_points", entry_points)


PLUGIN_ENTRY = registry.PolicyEntry(
    "ignored", "pioneer.baselines.classic:GoalPolicy", summary="a goal-seeker via PolicyEntry"
)


def test_plugins_add_policies_by_entry_point(monkeypatch: pytest.MonkeyPatch) -> None:
    _plugins(
        monkeypatch,
        [
            _EP("my-goal", "pioneer.baselines.classic:GoalPolicy"),
            _EP("my-entry", f"{__name__}:PLUGIN_ENTRY"),
            _EP("goal", "no.such.module:nothing"),  # never shadows a registered name
        ],
    )
    names = registry.policy_names()
    assert {"my-goal", "my-entry"} <= set(names)
    assert isinstance(registry.build_policy("my-goal"), GoalPolicy)
    assert registry.policy_entry("my-entry").summary == "a goal-seeker via PolicyEntry"
    assert isinstance(registry.build_policy("goal"), GoalPolicy)


def test_a_plugin_that_cannot_import_is_one_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    _plugins(monkeypatch, [_EP("broken", "no.such.module:make")])
    with pytest.raises(ConfigError, match="broken"):
        registry.build_policy("broken")
    with pytest.raises(ConfigError, match="one of"):
        registry.build_policy("nope")
