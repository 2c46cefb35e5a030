"""Typed, frozen configuration base: defaults live in one place, unknown keys are rejected."""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from typing import Any, Self

from pioneer.errors import ConfigError, expect

__all__ = ["Config", "check_nonnegative", "check_positive", "check_range"]


def check_positive(owner: str, name: str, value: float) -> None:
    """Raise :class:`ConfigError` unless ``value`` is a finite number > 0."""
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise ConfigError(
            expect(f"{owner}.{name}", "a finite number > 0", value, f"set {name} > 0")
        )


def check_nonnegative(owner: str, name: str, value: float) -> None:
    """Raise :class:`ConfigError` unless ``value`` is a finite number ≥ 0."""
    if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
        raise ConfigError(
            expect(f"{owner}.{name}", "a finite number >= 0", value, f"set {name} >= 0")
        )


def check_range(owner: str, name: str, lo: float, hi: float) -> None:
    """Raise :class:`ConfigError` unless ``lo <= hi`` and both are finite."""
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise ConfigError(
            expect(f"{owner}.{name}", "finite bounds with low <= high", (lo, hi), "swap or fix")
        )


@dataclasses.dataclass(frozen=True)
class Config:
    """Base of every config dataclass: ``from_dict`` rejects unknown keys, ``to_dict`` nests."""

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Self:
        """Build from a plain dict (e.g. parsed JSON); nested configs are built recursively."""
        if not isinstance(data, dict):
            raise ConfigError(expect(cls.__name__, "a mapping", type(data).__name__, "pass a dict"))
        fields = {f.name: f for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - set(fields))
        if unknown:
            raise ConfigError(
                expect(
                    cls.__name__,
                    f"keys among {sorted(fields)}",
                    unknown,
                    "remove or correct the misspelled keys",
                )
            )
        hints = typing.get_type_hints(cls)
        kwargs: dict[str, Any] = {}
        for name, value in data.items():
            kwargs[name] = _coerce(hints[name], value)
        return cls(**kwargs)

    def to_dict(self) -> dict[str, Any]:
        """Plain, JSON-serialisable dict (tuples become lists)."""
        return _plain(dataclasses.asdict(self))

    def replace(self, **changes: Any) -> Self:
        """A copy with some fields changed (validated again)."""
        fields = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(changes) - fields)
        if unknown:
            raise ConfigError(
                expect(type(self).__name__, f"keys among {sorted(fields)}", unknown, "fix the key")
            )
        return dataclasses.replace(self, **changes)


def _coerce(hint: Any, value: Any) -> Any:
    if isinstance(hint, type) and issubclass(hint, Config) and isinstance(value, dict):
        return hint.from_dict(value)
    origin = typing.get_origin(hint)
    if origin is tuple and isinstance(value, list | tuple):
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(args[0], v) for v in value)
        return tuple(_coerce(a, v) for a, v in zip(args, value, strict=False))
    if origin in (typing.Union, types.UnionType):
        for arg in typing.get_args(hint):
            if isinstance(arg, type) and issubclass(arg, Config) and isinstance(value, dict):
                return arg.from_dict(value)
            if typing.get_origin(arg) is tuple and isinstance(value, list | tuple):
                return _coerce(arg, value)
    return value


def _plain(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    return obj
