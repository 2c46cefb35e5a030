"""Names are names: scenario names, layout prefixes and row labels are letters, digits, ``-``,
``_`` and ``.`` (no leading dot, no separator), checked where they enter; every output path
derived from one stays inside its folder."""

from __future__ import annotations

import json

import pytest

from pioneer.cli import main
from pioneer.errors import ConfigError, DataError, ScenarioError
from pioneer.eval.harness import PolicySpec, evaluate
from pioneer.io import check_name, inside
from pioneer.sim.scenarios.distribution import LayoutDistribution, sample_variants
from pioneer_testutils import assert_house_message, file_tree, one_error_line

GOOD = ["hr-rl", "general-0001", "static-1s", "A.b_c", "_x", "0"]
BAD = ["", ".", "..", ".hidden", "../x", "a/b", "a\\b", "/abs", "a b", "-lead", "x\n", "tab\t"]


@pytest.mark.parametrize("name", GOOD)
def test_safe_names_pass(name):
    assert check_name("name", name) == name


@pytest.mark.parametrize("name", BAD)
def test_unsafe_names_are_refused(name):
    with pytest.raises(ConfigError) as err:
        check_name("scenario name", name)
    assert_house_message(str(err.value), "scenario name", "letters, digits")


@pytest.mark.parametrize("name", ["x.png", "figures/x.png", "a/./b.png", "a/../b.png"])
def test_inside_keeps_a_path_in_its_folder(tmp_path, name):
    p = inside(tmp_path, name)
    assert p.resolve().is_relative_to(tmp_path.resolve()) and p.resolve() != tmp_path.resolve()


@pytest.mark.parametrize("name", ["../x.png", "a/../../x.png", "/etc/x", "", ".", "a/.."])
def test_inside_refuses_a_path_that_leaves_its_folder(tmp_path, name):
    with pytest.raises(DataError) as err:
        inside(tmp_path / "out", name)
    assert_house_message(str(err.value), "inside")


def _file(tmp_path, name: str) -> str:
    path = tmp_path / "variants.json"
    doc = {"format": "pioneer.scenarios/1", "scenarios": {name: {"static": {}}}}
    path.write_text(json.dumps(doc))
    return str(path)


def test_a_scenario_name_that_leaves_its_folder_is_refused_and_draws_nothing(
    tmp_path, capsys, scenario_registry
):
    """``scenarios --png-dir`` wrote ``../../evil.png`` two folders up."""
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    before = file_tree(tmp_path)
    code = main(["--scenarios", _file(work, "../../evil"), "scenarios", "--png-dir", str(work)])
    one_error_line(capsys.readouterr().err, code, "'../../evil'", "letters, digits")
    after = file_tree(tmp_path)
    assert set(after) - set(before) == {"a/b/variants.json"}  # the test's own input only
    with pytest.raises(ScenarioError):
        scenario_registry.load_scenario_file(_file(tmp_path, ".hidden"))
    with pytest.raises(ScenarioError):
        scenario_registry.register_scenario(
            "x/y", lambda: scenario_registry.static_study_scenario().replace(name="x/y")
        )


def test_a_layout_prefix_that_leaves_its_folder_is_refused(tmp_path, capsys):
    with pytest.raises(ScenarioError, match="prefix"):
        sample_variants(LayoutDistribution(), 1, 0, "../../x")
    out = tmp_path / "layouts.json"
    code = main(["sample-layouts", "--prefix", "../../x", "--n", "1", "--out", str(out)])
    one_error_line(capsys.readouterr().err, code, "--prefix", "../../x")
    assert list(tmp_path.iterdir()) == []


def test_a_row_label_is_a_name(tmp_path, capsys):
    with pytest.raises(ConfigError, match="label"):
        PolicySpec.parse("goal:label=../up")
    with pytest.raises(ConfigError, match="label"):  # through the API as well
        evaluate(["static"], [PolicySpec("goal", (), "a/b")], 1, 1, tmp_path / "ev")
    code = main(["eval", "--scenario", "static", "--policy", "goal:label=.hidden", "--out",
                 str(tmp_path / "ev")])  # fmt: skip
    one_error_line(capsys.readouterr().err, code, "label", ".hidden")
    assert list(tmp_path.iterdir()) == []
