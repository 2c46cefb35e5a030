"""The package states ranges, the repository pins: ``pyproject.toml`` (and the light runtime's)
declare every dependency as a range with an upper bound and no exact version, and
``constraints.txt`` (what ``make`` installs) pins each of them to one version inside its range,
torch to its CPU build. The built wheels themselves are checked by ``make smoke``."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[1]
MAIN = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
RUNTIME = tomllib.loads((ROOT / "runtime" / "pyproject.toml").read_text())["project"]


def _requirements(project: dict) -> list[Requirement]:
    listed = [*project["dependencies"]]
    for extra in project.get("optional-dependencies", {}).values():
        listed += extra
    return [Requirement(r) for r in listed]


def _pins() -> dict[str, Version]:
    pins: dict[str, Version] = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            name, _, version = line.partition("==")
            assert version, f"constraints.txt: {line!r} is not an exact pin"
            pins[canonicalize_name(name)] = Version(version)
    return pins


@pytest.mark.parametrize("project", [MAIN, RUNTIME], ids=["pioneer-nav", "pioneer-nav-runtime"])
def test_ranges_with_an_upper_bound_and_no_exact_pin(project):
    assert project["requires-python"] == ">=3.11"
    for req in _requirements(project):
        operators = {s.operator for s in req.specifier}
        assert "==" not in operators and "===" not in operators, str(req)
        assert "<" in operators, f"{req}: no upper bound"
        assert ">=" in operators, f"{req}: no lower bound"


def test_constraints_pin_every_dependency_inside_its_range():
    pins = _pins()
    for req in _requirements(MAIN) + _requirements(RUNTIME):
        pin = pins.get(canonicalize_name(req.name))
        assert pin is not None, f"{req.name} is not pinned in constraints.txt"
        assert req.specifier.contains(pin, prereleases=True), f"{req.name}=={pin} not in {req}"
    assert pins["torch"].local == "cpu"  # the CPU build, not the CUDA one PyPI serves
