"""A function's keyword arguments checked against its signature: the parameters of a policy
factory (``--policy NAME:key=value``), typed and ranged once on the factory
(``Annotated[int, Ge(2)]``) with the bounds and messages of :mod:`pioneer.config`'s fields."""

from __future__ import annotations

import inspect
import math
import types
import typing
from collections.abc import Callable, Collection
from pathlib import Path
from typing import Annotated, Any

from pioneer.config import field_checks, without_none
from pioneer.errors import ConfigError, expect

__all__ = ["check_parameters"]


def _type_name(hint: Any) -> str:
    hint, _ = without_none(hint)
    if typing.get_origin(hint) is Annotated:
        hint = typing.get_args(hint)[0]
    if typing.get_origin(hint) is typing.Literal:
        return f"one of {list(typing.get_args(hint))}"
    names = {bool: "true or false", int: "an integer", float: "a number", str: "a text"}
    return names.get(hint, getattr(hint, "__name__", str(hint)))


def _check_type(owner: str, name: str, hint: Any, value: Any) -> Any:
    """``value`` checked against ``hint`` (bool, int, float, str, Path, Literal, ``| None``,
    ``Annotated`` bounds); an int given for a float becomes a float. Other hints pass."""
    bounds = field_checks(owner, name, hint)
    base, optional = without_none(hint)
    if typing.get_origin(base) is Annotated:
        base, none_inside = without_none(typing.get_args(base)[0])
        optional = optional or none_inside
    if value is None:
        if optional or type(None) in typing.get_args(base):
            return None
        raise ConfigError(expect(f"{owner}.{name}", _type_name(hint), None, f"give {name} a value"))
    if typing.get_origin(base) in (typing.Union, types.UnionType):
        options = typing.get_args(base)
        if str in options or Path in options:
            base = str
        elif float in options:
            base = float
    ok = True
    if typing.get_origin(base) is typing.Literal:
        ok = value in typing.get_args(base)
    elif base is bool:
        ok = isinstance(value, bool)
    elif base is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif base is float:
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        value = float(value) if ok else value
        ok = ok and math.isfinite(value)
    elif base in (str, Path):
        ok = isinstance(value, str)
    if not ok:
        raise ConfigError(
            expect(f"{owner}.{name}", _type_name(hint), value, f"give {name} {_type_name(hint)}")
        )
    if bounds is not None:
        bounds.check(owner, name, value)
    return value


def check_parameters(
    owner: str, fn: Callable[..., Any], kwargs: dict[str, Any], fixed: Collection[str] = ()
) -> dict[str, Any]:
    """``kwargs`` checked against the parameters of ``fn`` (a function or a class): every key
    must be a parameter, every value of its annotated type and within its ``Annotated``
    bounds, and every parameter without a default given — by ``kwargs``, by the caller's
    ``fixed`` names, or ``scenario`` (always passed by the caller). Returns the checked values
    (ints given for floats as floats). A function taking ``**kwargs`` accepts any key (its
    config checks them)."""
    target = fn.__init__ if isinstance(fn, type) else fn  # type: ignore[misc]
    params = inspect.signature(fn).parameters
    given = {*kwargs, *fixed, "scenario"}
    missing = [
        p.name
        for p in params.values()
        if p.default is inspect.Parameter.empty
        and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
        and p.name not in given
    ]
    if missing:
        example = ",".join(f"{k}=…" for k in missing)
        raise ConfigError(expect(owner, f"a value for {missing}", "none", f"give {example}"))
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return dict(kwargs)
    allowed = sorted(k for k in params if k != "scenario")
    unknown = sorted(set(kwargs) - set(allowed))
    if unknown:
        raise ConfigError(
            expect(f"{owner} parameters", f"keys among {allowed}", unknown, "correct the key")
        )
    hints = typing.get_type_hints(target, include_extras=True)
    return {k: _check_type(owner, k, hints[k], v) if k in hints else v for k, v in kwargs.items()}
