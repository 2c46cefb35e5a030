"""Data shipped with the package: default demonstration datasets."""

from __future__ import annotations

from pathlib import Path

from pioneer.errors import DataError, expect

__all__ = ["base_scenario", "shipped_demos"]

DEMOS_DIR = Path(__file__).parent / "demos"


def base_scenario(scenario: str) -> str:
    """The scenario whose shipped demos serve ``scenario`` (``hr-rl-r03`` → ``hr-rl``)."""
    return scenario.removesuffix("-r03")


def shipped_demos(scenario: str) -> Path:
    """Path of the shipped demonstration file for ``scenario``."""
    p = DEMOS_DIR / f"{base_scenario(scenario)}.npz"
    if not p.is_file():
        names = sorted(q.stem for q in DEMOS_DIR.glob("*.npz"))
        raise DataError(expect("shipped demos", f"one of {names}", scenario, "pass --demos FILE"))
    return p
