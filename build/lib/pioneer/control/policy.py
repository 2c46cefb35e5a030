"""The one interface every controller implements: teacher, baselines and students.

A policy sees the observation (29-D, SPEC 1.4) and the environment's ``info`` dict, whose
``state`` and ``world`` entries give privileged controllers the full simulator state. Policies
hold their own RNG, seeded by ``reset``, and never touch the global numpy RNG.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from pioneer.errors import ConfigError, expect

__all__ = [
    "LAZY_POLICIES",
    "Policy",
    "build_policy",
    "check_policy_kwargs",
    "check_policy_name",
    "make_policy",
    "policy_factory",
    "policy_names",
    "register_policy",
]


@runtime_checkable
class Policy(Protocol):
    """A controller: ``reset`` at the start of an episode, then one ``act`` per 0.1 s step."""

    name: str

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Start an episode; ``info`` is what ``env.reset`` returned."""
        ...

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """The command ``(v [m/s], ω [rad/s])`` for this step, shape ``(2,)``."""
        ...


_FACTORIES: dict[str, Callable[..., Policy]] = {}


def register_policy(name: str, factory: Callable[..., Policy]) -> None:
    """Make a policy constructible by name (CLI, evaluation harness)."""
    _FACTORIES[name] = factory


def policy_names() -> list[str]:
    """Registered policy names."""
    return sorted(_FACTORIES)


# Registered by pioneer.learn on first use (it imports torch, which costs ≈ 250 MB).
LAZY_POLICIES = ("crowdnav++", "student-mdn", "student-mlp", "student-onnx", "student-shield")


def check_policy_name(name: str) -> None:
    """Raise :class:`ConfigError` unless ``name`` is registered or registered on first use —
    without importing torch (the evaluation parent only checks names; workers build)."""
    if name not in _FACTORIES and name not in LAZY_POLICIES:
        known = sorted({*_FACTORIES, *LAZY_POLICIES})
        raise ConfigError(expect("policy", f"one of {known}", name, "pick a listed policy"))


def policy_factory(name: str) -> Callable[..., Policy]:
    """The factory registered under ``name``."""
    if (name.startswith("student") or name == "crowdnav++") and name not in _FACTORIES:
        # The students and CrowdNav++ live in pioneer.learn (torch); register them on first use.
        try:
            import pioneer.learn  # noqa: F401
        except ImportError as exc:
            raise ConfigError(
                expect(
                    "policy", f"{name} (needs torch)", str(exc), "pip install 'pioneer-nav[learn]'"
                )
            ) from exc
    if name not in _FACTORIES:
        raise ConfigError(
            expect("policy", f"one of {policy_names()}", name, "pick a listed policy")
        )
    return _FACTORIES[name]


def check_policy_kwargs(name: str, kwargs: Mapping[str, Any]) -> None:
    """Raise :class:`ConfigError` unless the factory of ``name`` takes every key of ``kwargs``
    (imports the factory: torch for the students)."""
    import inspect

    params = inspect.signature(policy_factory(name)).parameters
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return
    allowed = sorted(k for k in params if k != "scenario")
    unknown = sorted(set(kwargs) - set(allowed))
    if unknown:
        raise ConfigError(
            expect(
                f"policy {name!r} parameters",
                f"keys among {allowed}",
                unknown,
                "correct the key (see the policy's factory)",
            )
        )


def build_policy(name: str, scenario: str | None = None, **kwargs: Any) -> Policy:
    """Construct ``name``, passing ``scenario`` only to factories that take it (the teacher
    needs the scenario to pick its reward; the go-to-goal controller does not)."""
    import inspect

    factory = policy_factory(name)
    if scenario is not None and "scenario" in inspect.signature(factory).parameters:
        kwargs["scenario"] = scenario
    return factory(**kwargs)


def make_policy(name: str, **kwargs: Any) -> Policy:
    """Construct a registered policy by name."""
    if name not in _FACTORIES:
        raise ConfigError(
            expect("policy", f"one of {policy_names()}", name, "pick a listed policy")
        )
    return _FACTORIES[name](**kwargs)
