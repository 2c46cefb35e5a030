"""The lazy policy registry: names resolve without imports; plugins via entry points."""

from __future__ import annotations

import importlib.metadata
import itertools
import subprocess
import sys
from typing import Any

import pytest

from pioneer.baselines.classic import GoalPolicy
from pioneer.control import registry
from pioneer.control.registry import check_policy_kwargs
from pioneer.errors import ConfigError, DataError
from pioneer_testutils import assert_house_message


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
    # an own reward: no shipped demos looked up, but the file itself is loaded and checked
    with pytest.raises(DataError, match="reward model: expected an existing"):
        registry.check_parts("teacher", "no-such-demos", {"reward": "r.npz"})
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


# ----------------------------------------------------------------------- typed policy parameters
@pytest.mark.parametrize(
    ("name", "kwargs", "needle"),
    [
        ("teacher", {"density": "abc"}, "policy teacher.density: expected true or false"),
        ("dwa", {"horizon": "abc"}, "policy dwa.horizon: expected a number"),
        ("dwa", {"n_v": 2.5}, "policy dwa.n_v: expected an integer"),
        ("dwa", {"n_v": True}, "policy dwa.n_v: expected an integer"),
        ("dwa", {"horizon": -1}, "horizon: expected a finite number > 0"),
        ("dwa", {"n_v": 1}, "n_v: expected an integer >= 2"),
        ("dwa", {"horizon": float("nan")}, "policy dwa.horizon: expected a number"),
        ("goal", {"v_max": 0}, "v_max: expected a finite number > 0"),
        ("sfm", {"tau": "x"}, "policy sfm.tau: expected a number"),
        ("teacher", {"bogus": 1}, "expected keys among"),
    ],
)
def test_policy_parameters_are_typed_and_ranged(name, kwargs, needle):
    with pytest.raises(ConfigError) as err:
        check_policy_kwargs(name, kwargs)
    assert_house_message(str(err.value), needle)


def test_policy_parameters_come_back_typed():
    # an integer given for a float parameter becomes a float; None passes where allowed
    assert check_policy_kwargs("dwa", {"horizon": 3, "n_v": 5}) == {"horizon": 3.0, "n_v": 5}
    assert isinstance(check_policy_kwargs("dwa", {"horizon": 3})["horizon"], float)
    assert check_policy_kwargs("sfm", {"tau": None}) == {"tau": None}
    assert check_policy_kwargs("teacher", {"density": False}) == {"density": False}


@pytest.mark.parametrize("spec", ["teacher:density=abc", "dwa:horizon=abc", "dwa:n_v=2.5"])
def test_bad_policy_parameter_is_one_cli_line(spec, tmp_path, capsys):
    from pioneer.cli import main

    code = main(["eval", "--policy", spec, "--scenario", "static", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("pioneer: error: policy ")
    assert not (tmp_path / "o").exists()


def test_the_general_student_serves_every_scenario():
    from pioneer.data import shipped_student
    from pioneer.learn import read_checkpoint_meta

    path = shipped_student("anything", "mdn", general=True)
    assert path.name == "general-mdn.safetensors"
    info = read_checkpoint_meta(path)["info"]
    assert info["scenario"] == "general-*" and info["dagger"]["student"]["kind"] == "mdn"
    for scenario in ("hr-rl", "hl-rr", "hr-rl-compact"):
        pol = registry.build_policy("student-general", scenario)
        assert pol.name == "student-general"
    registry.check_parts("student-general", "not-a-built-in", {})  # no per-scenario file


def test_every_shipped_student_seed_and_the_paper_recipe_load():
    """Table III's students: each kind at every DAgger seed, and the paper's recipe."""
    from pioneer.data import STUDENT_SEEDS, shipped_student

    for scenario in ("hr-rl", "hl-rr"):
        for seed in STUDENT_SEEDS:
            for name, kind, recipe in (
                ("student-mdn", "mdn", ""),
                ("student-mlp", "mlp", ""),
                ("student-mdn-paper", "mdn", "paper"),
            ):
                path = shipped_student(scenario, kind, seed=seed, recipe=recipe)
                suffix = (f"-{recipe}" if recipe else "") + (f"-s{seed}" if seed else "")
                assert path.name == f"{scenario}-{kind}{suffix}.safetensors"
                registry.check_parts(name, scenario, {"seed": seed})
                pol = registry.build_policy(name, scenario, seed=seed)
                assert pol.checkpoint == path
                assert pol.model.config.kind == kind
    # the paper's recipe reads the 29-D observation alone
    paper = registry.build_policy("student-mdn-paper", "hr-rl")
    assert paper.model.config.input_dim == 29


def test_every_shipped_student_records_the_recipe_its_readme_names():
    """The DAgger settings in each shipped file's metadata are the shipped recipe of
    ``pioneer.data`` (data/students/README.md): a file copied from the wrong run fails here."""
    from pioneer.data import (
        STUDENT_LABEL_PREV,
        STUDENT_PREVIOUS_COMMAND,
        STUDENT_SEEDS,
        STUDENT_SELECT_EPISODES,
        shipped_student,
    )
    from pioneer.learn import read_checkpoint_meta
    from pioneer.learn.dagger import DaggerConfig

    margins = DaggerConfig().margins  # the teacher's default soft margins
    for scenario, kind in itertools.product(("hr-rl", "hl-rr"), STUDENT_PREVIOUS_COMMAND):
        for seed in STUDENT_SEEDS:
            dagger = read_checkpoint_meta(shipped_student(scenario, kind, seed=seed))["info"]
            dagger = dagger["dagger"]
            assert (dagger["scenario"], dagger["student"]["kind"]) == (scenario, kind)
            assert dagger["seed"] == seed
            assert dagger["label_prev"] == STUDENT_LABEL_PREV
            # files chosen by rerunning a finished run with the selection were trained
            # before the setting existed and do not record it (data/students/README.md)
            assert dagger.get("select_episodes", STUDENT_SELECT_EPISODES) == STUDENT_SELECT_EPISODES
            assert dagger["student"]["previous_observation"] is True
            assert dagger["student"]["previous_command"] is STUDENT_PREVIOUS_COMMAND[kind]
            assert dagger["margins"] == {
                "human": margins.human,
                "wall": margins.wall,
                "tiers": margins.tiers,
            }


def test_the_teacher_keeps_its_soft_margins_and_teacher_paper_none():
    from pioneer.control.teacher import SoftMargins

    assert registry.build_policy("teacher", "hr-rl").config.margins == SoftMargins()
    assert SoftMargins() != SoftMargins(human=0.0, wall=0.0)
    bare = registry.build_policy("teacher-paper", "hr-rl")
    assert bare.config.margins == SoftMargins(human=0.0, wall=0.0)
    assert bare.config.fallback == "stop"  # the paper's teacher: no evade fallback
    assert registry.build_policy("teacher", "hr-rl").config.fallback == "evade"
    evade = registry.build_policy("teacher-paper-evade", "hr-rl").config
    assert (evade.margins, evade.fallback) == (SoftMargins(human=0.0, wall=0.0), "evade")


@pytest.mark.parametrize("term", ["density", "goal", "obstacle"])
def test_the_papers_ablations_are_the_papers_teacher_less_one_term(term):
    from pioneer.control.teacher import SoftMargins

    cfg = registry.build_policy(f"teacher-paper-no-{term}", "hr-rl").config
    assert (cfg.margins, cfg.fallback) == (SoftMargins(human=0.0, wall=0.0), "stop")
    ours = registry.build_policy(f"teacher-no-{term}", "hr-rl").config
    assert (ours.margins, ours.fallback) == (SoftMargins(), "evade")
    used = {t: getattr(cfg.weights, f"use_{t}") for t in ("density", "goal", "obstacle")}
    assert used == {t: t != term for t in used}
