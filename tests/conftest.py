"""Shared pytest setup: make the helper module importable and expose common fixtures."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

_HERE = str(Path(__file__).resolve().parent)
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

import pioneer_testutils as tu  # noqa: E402


@pytest.fixture
def rng() -> object:
    """A seeded generator (never the global numpy RNG)."""
    import numpy as np

    return np.random.default_rng(20240611)


@pytest.fixture
def open_world() -> object:
    """A world without walls and with far-away bounds."""
    return tu.open_world()


@pytest.fixture
def scenario_registry(monkeypatch: pytest.MonkeyPatch) -> object:
    """``pioneer.sim.scenarios`` with its registry, bases and ``PIONEER_SCENARIOS`` restored
    after the test (register variants freely; ``main()`` may extend the variable)."""
    from pioneer.sim.scenarios import registry as sc

    monkeypatch.setattr(sc, "_REGISTRY", dict(sc._REGISTRY))
    monkeypatch.setattr(sc, "_BASES", dict(sc._BASES))
    monkeypatch.setattr(sc, "_SOURCES", dict(sc._SOURCES))
    monkeypatch.setattr(sc, "_ENV_LOADED", "")
    monkeypatch.setenv(sc.SCENARIOS_ENV, "")
    return sc
