"""Typed, frozen configuration base: defaults live in one place, unknown keys are rejected,
and range checks are declared on the fields.

A field may carry `annotated-types <https://github.com/annotated-types/annotated-types>`_
bounds, e.g. ``radius: Annotated[float, Gt(0)] = 0.3`` (or the aliases
:data:`pioneer.bounds.Positive`, :data:`pioneer.bounds.NonNegative`); :class:`Config`
enforces them once, before any ``__post_init__`` of the subclass runs, with the message of
:func:`check_positive` / :func:`check_nonnegative` / :func:`check_within` (the helpers
left for the configs of the light robot install, which declare no bounds). Supported:
``Gt``, ``Ge``, ``Lt``, ``Le`` and ``Interval`` on ``int`` and ``float`` fields, also inside
``| None`` (``None`` then passes). A bounded ``float`` must be finite; a bounded ``int`` must
be an integer (not a bool). A ``Literal[...]`` field (a choice) must hold one of its values;
it needs no annotated-types.

A tuple field is checked item by item against its item types (``tuple[Positive, ...]``: every
item > 0; ``tuple[Annotated[float, Lt(0)], Positive]``: the first < 0, the second > 0;
``tuple[Literal["a", "b"], ...]``: choices), may bound its length (``MinLen``, ``MaxLen``) and
may carry :class:`Ordered`: finite items in non-decreasing order, e.g. a ``(low, high)`` range
(:data:`pioneer.bounds.Span`). Cross-field checks stay code in ``__post_init__``.

annotated-types is imported only when a field carries ``Annotated`` metadata, so a config
without declared bounds (the LiDAR's, the robot runtime's) needs no annotated-types: the
light robot install (``runtime/``) has numpy and onnxruntime only.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import itertools
import math
import types
import typing
import weakref
from collections.abc import Callable, Iterator, Mapping
from typing import Annotated, Any, ClassVar, Self

from pioneer.errors import ConfigError, expect

__all__ = [
    "Config",
    "Ordered",
    "check_nonnegative",
    "check_option_bounds",
    "check_positive",
    "check_range",
    "check_values",
    "check_within",
    "default",
    "field_checks",
    "without_none",
]


@dataclasses.dataclass(frozen=True)
class _Bounds:
    """The bounds declared on one field, checked with the house message."""

    integer: bool = False  # an ``int`` field: the value must be an integer (not a bool)
    lower: float | None = None
    lower_strict: bool = False  # Gt rather than Ge
    upper: float | None = None
    upper_strict: bool = False  # Lt rather than Le
    optional: bool = False  # ``None`` passes

    def describe(self) -> str:
        """``> 0``, ``>= 1``, ``>= 0 and <= 1``: the accepted range (infinite bounds, which
        only ask for a finite number, left out)."""
        parts = []
        if self.lower is not None and math.isfinite(self.lower):
            parts.append(f"{'>' if self.lower_strict else '>='} {self.lower:g}")
        if self.upper is not None and math.isfinite(self.upper):
            parts.append(f"{'<' if self.upper_strict else '<='} {self.upper:g}")
        return " and ".join(parts)

    def check(self, owner: str, name: str, value: object, label: str | None = None) -> None:
        """Raise :class:`ConfigError` unless ``value`` lies within the bounds; the message
        names ``label`` (default ``owner.name``)."""
        if value is None and self.optional:
            return
        if not self._accepts(value):
            kind = "an integer" if self.integer else "a finite number"
            wanted = f"{kind} {self.describe()}".strip()
            fix = f"set {label or name} {self.describe() or 'to ' + kind}"
            raise ConfigError(expect(label or f"{owner}.{name}", wanted, value, fix))

    def _accepts(self, value: object) -> bool:
        if self.integer:
            if not isinstance(value, int) or isinstance(value, bool):
                return False
        elif not (isinstance(value, int | float) and math.isfinite(value)):
            return False
        x = float(value)
        if self.lower is not None and not (
            x > self.lower if self.lower_strict else x >= self.lower
        ):
            return False
        return self.upper is None or (x < self.upper if self.upper_strict else x <= self.upper)


def check_positive(owner: str, name: str, value: float) -> None:
    """Raise :class:`ConfigError` unless ``value`` is a finite number > 0."""
    _Bounds(lower=0, lower_strict=True).check(owner, name, value)


def check_nonnegative(owner: str, name: str, value: float) -> None:
    """Raise :class:`ConfigError` unless ``value`` is a finite number ≥ 0."""
    _Bounds(lower=0).check(owner, name, value)


def check_within(owner: str, name: str, value: float, low: float, high: float) -> None:
    """Raise :class:`ConfigError` unless ``value`` is a finite number in ``[low, high]``."""
    _Bounds(lower=low, upper=high).check(owner, name, value)


def check_count(what: str, n: int, ceiling: int, fix: str) -> None:
    """Raise :class:`ConfigError` if the count ``n`` (episodes, layouts, samples a run would
    hold) exceeds ``ceiling``, before any work; the message states the ceiling."""
    if n > ceiling:
        raise ConfigError(expect(what, f"at most {ceiling:,} (the ceiling of one run)", n, fix))


MAX_EPISODES = 200_000  # episodes one run may ask for (≈ 15 × the paper profile's)


def check_range(owner: str, name: str, lo: float, hi: float) -> None:
    """Raise :class:`ConfigError` unless ``lo <= hi`` and both are finite."""
    _Items(items=(None, None), ordered=True).check(owner, name, (lo, hi))


@dataclasses.dataclass(frozen=True)
class Ordered:
    """``Annotated`` metadata of a tuple of numbers: its items are finite and in non-decreasing
    order (a ``(low, high)`` range: low <= high). Checked by :class:`Config`."""


@dataclasses.dataclass(frozen=True)
class _Items:
    """The checks of a tuple field: its length, each item's bounds or choices, the order."""

    items: tuple[_Check | None, ...] | None = None  # per position; None: ``tuple[X, ...]``
    each: _Check | None = None  # every item of a ``tuple[X, ...]``
    min_len: int = 0
    max_len: int | None = None
    ordered: bool = False  # see Ordered
    optional: bool = False  # ``None`` passes

    def check(self, owner: str, name: str, value: object, label: str | None = None) -> None:
        """Raise :class:`ConfigError` unless ``value`` is a tuple (or list) of the right length
        whose items pass their checks (each named ``name[i]``), in order when ordered."""
        if value is None and self.optional:
            return
        field = label or f"{owner}.{name}"
        n_min, n_max = self.min_len, self.max_len
        if self.items is not None:
            n_min = n_max = len(self.items)
        if not isinstance(value, tuple | list) or not (
            n_min <= len(value) and (n_max is None or len(value) <= n_max)
        ):
            if n_min == 0 and n_max is None:
                raise ConfigError(expect(field, "a list", value, "give a list of values"))
            if n_min == n_max:
                size, count = f"{n_min}", n_min
            elif n_max is None:
                size, count = f"at least {n_min}", n_min
            else:
                size, count = f"{n_min} to {n_max}", n_max
            many = f"{size} value{'' if count == 1 else 's'}"
            raise ConfigError(expect(field, f"a list of {many}", value, f"give {many}"))
        for i, item in enumerate(value):
            check = self.each if self.items is None else self.items[i]
            if check is not None:
                check.check(owner, f"{name}[{i}]", item, None if label is None else f"{label}[{i}]")
        if self.ordered:
            finite = all(
                isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
                for v in value
            )
            if not (finite and all(a <= b for a, b in itertools.pairwise(value))):
                if self.items is not None and len(self.items) == 2:  # a (low, high) range
                    wanted, fix = "finite bounds with low <= high", "swap or fix"
                else:
                    wanted, fix = "finite numbers in non-decreasing order", "sort them"
                raise ConfigError(expect(field, wanted, tuple(value), fix))


def _constraints(metadata: tuple[Any, ...]) -> Iterator[Any]:
    """The annotated-types constraints among ``Annotated`` metadata (``Interval`` unpacked);
    other metadata (e.g. CLI markers) is not ours and is skipped."""
    import annotated_types as at

    for m in metadata:
        if isinstance(m, at.GroupedMetadata):
            yield from _constraints(tuple(m))
        elif isinstance(m, at.BaseMetadata):
            yield m


def without_none(hint: Any) -> tuple[Any, bool]:
    """``X | None`` → ``(X, True)``; anything else → ``(hint, False)``."""
    args = typing.get_args(hint)
    union = typing.get_origin(hint) in (typing.Union, types.UnionType)
    if union and len(args) == 2 and type(None) in args:
        return next(a for a in args if a is not type(None)), True
    return hint, False


@functools.cache
def _bound_kinds() -> dict[type, tuple[str, str, bool]]:
    """constraint type → (which bound, its attribute, strict)."""
    import annotated_types as at

    return {
        at.Gt: ("lower", "gt", True),
        at.Ge: ("lower", "ge", False),
        at.Lt: ("upper", "lt", True),
        at.Le: ("upper", "le", False),
    }


@dataclasses.dataclass(frozen=True)
class _Choices:
    """The values a ``Literal[...]`` field takes (``None`` too when optional)."""

    values: tuple[Any, ...]
    optional: bool = False

    def check(self, owner: str, name: str, value: object, label: str | None = None) -> None:
        if value is None and self.optional:
            return
        if not any(value == v and type(value) is type(v) for v in self.values):
            shown = ", ".join(repr(v) for v in self.values)
            raise ConfigError(
                expect(label or f"{owner}.{name}", f"one of {shown}", value, "pick one of them")
            )


@dataclasses.dataclass(frozen=True)
class _Nested:
    """A field holding a config: an instance of its class (``None`` too when optional)."""

    cls: type
    optional: bool = False

    def check(self, owner: str, name: str, value: object, label: str | None = None) -> None:
        if value is None and self.optional:
            return
        if not isinstance(value, self.cls):
            kind = self.cls.__name__
            raise ConfigError(
                expect(label or f"{owner}.{name}", f"a {kind}", value, f"pass a {kind}")
            )


_Check = _Bounds | _Choices | _Items | _Nested  # the checks of one field


def field_checks(owner: str, name: str, hint: Any) -> _Check | None:
    """The bounds (for a ``Literal``, the choices; for a tuple, its items' checks; for a
    config, its class) of one field from its resolved type hint, or ``None`` if it declares
    none."""
    hint, optional = without_none(hint)
    metadata: tuple[Any, ...] = ()
    if typing.get_origin(hint) is Annotated:
        hint, *extra = typing.get_args(hint)
        metadata = tuple(extra)
        hint, none_inside = without_none(hint)
        optional = optional or none_inside
    if typing.get_origin(hint) is typing.Literal:
        return _Choices(typing.get_args(hint), optional)
    if typing.get_origin(hint) is tuple:
        return _tuple_checks(owner, name, hint, metadata, optional)
    if isinstance(hint, type) and issubclass(hint, Config):
        return _Nested(hint, optional)
    found = list(_constraints(metadata)) if metadata else []
    if not found:
        return None
    base = hint
    if base not in (int, float):
        raise TypeError(f"{owner}.{name}: bounds need an int or float field, not {base!r}")
    kw: dict[str, Any] = {}
    for c in found:
        if type(c) not in _bound_kinds():
            raise TypeError(
                f"{owner}.{name}: unsupported constraint {c!r} (use Gt, Ge, Lt, Le, Interval)"
            )
        key, attr, strict = _bound_kinds()[type(c)]
        if key in kw:
            raise TypeError(f"{owner}.{name}: more than one {key} bound")
        kw[key], kw[f"{key}_strict"] = float(getattr(c, attr)), strict
    return _Bounds(integer=base is int, optional=optional, **kw)


def _tuple_checks(
    owner: str, name: str, hint: Any, metadata: tuple[Any, ...], optional: bool
) -> _Items | None:
    """The checks of a tuple field (see :class:`_Items`), or ``None`` if it declares none."""
    args = typing.get_args(hint)
    variadic = len(args) == 2 and args[1] is Ellipsis
    checks = tuple(field_checks(owner, name, a) for a in (args[:1] if variadic else args))
    kw: dict[str, Any] = {}
    if metadata:
        import annotated_types as at

        for c in _constraints(metadata):
            if isinstance(c, at.MinLen) and variadic:
                kw["min_len"] = int(c.min_length)
            elif isinstance(c, at.MaxLen) and variadic:
                kw["max_len"] = int(c.max_length)
            else:
                raise TypeError(
                    f"{owner}.{name}: unsupported constraint {c!r} on a tuple (bound its items"
                    " through their type; MinLen, MaxLen on a tuple[X, ...])"
                )
    ordered = any(isinstance(m, Ordered) for m in metadata)
    if not (ordered or kw or any(c is not None for c in checks)):
        return None
    items = None if variadic else checks
    each = checks[0] if variadic else None
    return _Items(items=items, each=each, ordered=ordered, optional=optional, **kw)


_BOUNDS: dict[type, tuple[tuple[str, _Check], ...]] = {}


def _bounds_of(cls: type) -> tuple[tuple[str, _Check], ...]:
    """``(field name, bounds or choices)`` of every bounded or ``Literal`` field of a config
    class (resolved once)."""
    if cls in _BOUNDS:
        return _BOUNDS[cls]
    hints = typing.get_type_hints(cls, include_extras=True)
    found = (
        (f.name, field_checks(cls.__name__, f.name, hints[f.name])) for f in dataclasses.fields(cls)
    )
    _BOUNDS[cls] = tuple((name, b) for name, b in found if b is not None)
    return _BOUNDS[cls]


def check_option_bounds(options: object) -> None:
    """The ``Annotated`` bounds of the fields of any dataclass instance (a command's options),
    each error naming the option as ``--name``."""
    fields = dataclasses.fields(options)  # type: ignore[arg-type]
    values = {f.name: getattr(options, f.name) for f in fields}
    check_values(type(options), values, lambda name: "--" + name.replace("_", "-"))


def check_values(cls: type, values: Mapping[str, Any], label: Callable[[str], str]) -> None:
    """The declared checks of the fields of dataclass ``cls`` (bounds, choices, items) on
    ``values`` (field name → value, e.g. parsed options before ``cls`` is built from them),
    each error naming the field as ``label(name)`` (e.g. its command-line flag)."""
    for name, bounds in _bounds_of(cls):
        if name in values:
            bounds.check(cls.__name__, name, values[name], label=label(name))


def _check_bounds(cfg: Config) -> None:
    owner = type(cfg).__name__
    try:
        for name, bounds in _bounds_of(type(cfg)):
            bounds.check(owner, name, getattr(cfg, name))
    except ConfigError as exc:
        if type(exc) is cfg.error_type:
            raise
        raise cfg.error_type(str(exc)) from None


_BOUNDS_FIRST: weakref.WeakSet[Callable[[Any], None]] = weakref.WeakSet()


def _bounds_first(post_init: Callable[[Any], None]) -> Callable[[Any], None]:
    """``post_init`` preceded by the field bounds (its cross-field checks may rely on them)."""

    @functools.wraps(post_init)
    def checked(self: Config) -> None:
        _check_bounds(self)
        post_init(self)

    _BOUNDS_FIRST.add(checked)
    return checked


@dataclasses.dataclass(frozen=True)
class Config:
    """Base of every config dataclass: ``from_dict`` rejects unknown keys, ``to_dict`` nests,
    and the bounds declared on the fields (``Annotated[float, Gt(0)]``, see the module) are
    checked on every construction, ``replace`` and ``from_dict`` included, before the
    subclass's own ``__post_init__`` (which need not call ``super().__post_init__()``)."""

    # What a declared check raises: ConfigError, or a subclass (a scenario's: ScenarioError).
    error_type: ClassVar[type[ConfigError]] = ConfigError

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        own = cls.__dict__.get("__post_init__")
        if own is not None and own not in _BOUNDS_FIRST:
            cls.__post_init__ = _bounds_first(own)  # type: ignore[method-assign,assignment]

    def __post_init__(self) -> None:
        _check_bounds(self)

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


# ------------------------------------------------------------------ defaults
def default(owner: Callable[..., object], name: str) -> Any:
    """The default of field or parameter ``name`` of ``owner`` (a config dataclass, a class or
    a function): a default is declared once, where the value is used, and read from there by a
    command-line flag or an error's hint."""
    if dataclasses.is_dataclass(owner):
        for f in dataclasses.fields(owner):
            if f.name == name and f.default is not dataclasses.MISSING:
                return f.default
            if f.name == name and f.default_factory is not dataclasses.MISSING:
                return f.default_factory()
    else:
        param = inspect.signature(owner).parameters.get(name)
        if param is not None and param.default is not inspect.Parameter.empty:
            return param.default
    raise TypeError(f"{getattr(owner, '__qualname__', owner)} declares no default for {name!r}")
