"""The options the commands declare: tyro settings of an option (its choices, its metavar,
what its default ``None`` means), the shared option types (``--workers``, a seed, a flag
without a ``--no-`` pair), the teacher's ablation flags and ``--policy NAME[:key=value,…]``."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import tyro
from annotated_types import Ge

from pioneer.errors import ConfigError, expect

if TYPE_CHECKING:
    from pioneer.eval.harness import PolicySpec

__all__ = [
    "Ablation",
    "Ablations",
    "Flag",
    "Seed",
    "Workers",
    "metavar",
    "one_of",
    "optional",
    "policy_spec",
    "require_some",
]


def one_of(values: Iterable[str]) -> Any:
    """``Literal[*values]``, for choices declared as a tuple elsewhere: tyro lists them in
    ``--help`` and refuses any other value."""
    return Literal[tuple(values)]


def optional(metavar: str, meaning: str) -> Any:
    """tyro settings of an option whose default ``None`` means ``meaning``."""
    return tyro.conf.arg(metavar=metavar, help_behavior_hint=f"(default: {meaning})")


def metavar(name: str) -> Any:
    """tyro settings of an option whose value is shown as ``name`` (``DIR``, ``FILE``…)."""
    return tyro.conf.arg(metavar=name)


Workers = Annotated[int | None, Ge(1), optional("N", "all cores")]
Seed = Annotated[int, Ge(0)]  # an episode or training seed


Flag = tyro.conf.FlagCreatePairsOff[bool]  # ``--lidar`` sets it; there is no ``--no-lidar``


@dataclasses.dataclass(frozen=True)
class Ablation:
    """The teacher without one of its terms (paper Table II); only a teacher takes them."""

    no_density: Flag = False
    """teacher without the learned term"""
    no_goal: Flag = False
    """teacher without the goal term"""
    no_obstacle: Flag = False
    """teacher without the obstacle term"""

    def kwargs(self) -> dict[str, bool]:
        """``{term: False}`` for every term switched off: the teacher's keyword arguments."""
        off = {"density": self.no_density, "goal": self.no_goal, "obstacle": self.no_obstacle}
        return {term: False for term, flag in off.items() if flag}

    def suffix(self) -> str:
        """The row label's suffix, e.g. ``-no-density``."""
        return "".join(f"-no-{term}" for term in self.kwargs())


Ablations = tyro.conf.OmitArgPrefixes[Ablation]  # flags --no-density…, not --ablation.no-density


def require_some(flag: str, values: Sequence[str]) -> None:
    """Refuse an empty list (``--scenario`` given without names)."""
    if not values:
        raise ConfigError(expect(flag, "at least one name", list(values), f"name one after {flag}"))


def policy_spec(text: str) -> PolicySpec:
    """``--policy NAME[:key=value,…]`` → a checked spec (parameters against the factory; a
    ``checkpoint``/``model``/``reward``/``weights`` path made absolute for every worker)."""
    from pioneer.control.registry import check_policy_kwargs, check_policy_name
    from pioneer.eval.harness import PolicySpec

    spec = PolicySpec.parse(text)
    check_policy_name(spec.name)
    kwargs = check_policy_kwargs(spec.name, dict(spec.kwargs))
    if kwargs:
        for key in ("checkpoint", "model", "reward", "weights"):
            if isinstance(kwargs.get(key), str) and "{" not in kwargs[key]:
                kwargs[key] = str(Path(kwargs[key]).resolve())
    return dataclasses.replace(spec, kwargs=tuple(sorted(kwargs.items())))
