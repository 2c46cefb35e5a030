"""tyro, with every refusal of a command line as one line on stderr and exit code 2, and
config dataclasses as groups of a command's options.

A command nests a config (``dagger: tyro.conf.OmitArgPrefixes[DaggerConfig] =
DaggerConfig()``) instead of re-declaring its fields: every field becomes a flag with the
field's default, bounds, choices and help (its docstring or comment). :func:`config_flags`
registers how a config's fields appear (a flag renamed, a field left out); a config nested in
a command must be registered, so that its values are checked with the flags named. tyro builds
the config through a struct rule of ours (:data:`REGISTRY`, tyro's public constructor API).

tyro reports a bad command line in a multi-line box. Its parse-error hook (``tyro._errors``,
private and marked unstable in tyro 1.0) hands the refusal over as data: we word it as the
house message (``where: expected …, received …; fix: …``) and exit 2, as argparse did. A
refusal the hook does not describe, or a tyro without the hook, still gives one line: tyro's
box, caught on stderr and flattened.
"""

from __future__ import annotations

import contextlib
import dataclasses
import difflib
import io
import re
import sys
import typing
from collections.abc import Iterator, Sequence
from typing import Annotated, Any, NoReturn, TypeVar

import tyro
from tyro.constructors import ConstructorRegistry, StructConstructorSpec, StructTypeInfo

from pioneer.config import check_values
from pioneer.errors import expect

try:  # where tyro has the hook; elsewhere its box is flattened (see _flatten)
    from tyro import _errors as tyro_errors
except ImportError:  # pragma: no cover - depends on the installed tyro
    tyro_errors = None  # type: ignore[assignment]
if not hasattr(tyro_errors, "on_parse_error"):  # pragma: no cover - as above
    tyro_errors = None  # type: ignore[assignment]

__all__ = ["REGISTRY", "config_flags", "flag_name", "one_line", "parse", "refuse"]

T = TypeVar("T")

REGISTRY = ConstructorRegistry()  # builds the configs registered with config_flags
_FLAGS: dict[type, dict[str, tuple[Any, ...]]] = {}  # config → field → extra tyro settings
_BUILDING: set[type] = set()  # configs whose default spec the rule is asking tyro for


def config_flags(cls: type, **fields: Any) -> None:
    """Register config dataclass ``cls`` for nesting in commands, its fields as flags without
    a prefix (``--rounds``): ``name="flag_name"`` renames a field's flag, ``name=None`` leaves
    the field out (it keeps its default), and a tyro setting (``tyro.conf.arg(…)``, e.g. a
    metavar) is added to the field's. Registering a class again must say the same."""
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(fields) - known)
    if unknown:
        raise TypeError(f"{cls.__name__} has no fields {unknown} (known: {sorted(known)})")
    marks = {
        name: (
            (tyro.conf.Suppress,)
            if how is None
            else (tyro.conf.arg(name=how),)
            if isinstance(how, str)
            else (how,)
        )
        for name, how in fields.items()
    }
    if _FLAGS.setdefault(cls, marks) != marks:
        raise TypeError(f"{cls.__name__} is registered with other flags: {_FLAGS[cls]}")


def flag_name(cls: type, name: str) -> str:
    """The flag of field ``name`` of a registered config (``--name``, or its new name)."""
    for mark in _FLAGS.get(cls, {}).get(name, ()):
        if isinstance(getattr(mark, "name", None), str):
            name = mark.name
    return "--" + name.replace("_", "-")


def _shown(cls: type, name: str) -> bool:
    """Whether field ``name`` of a registered config is a flag (not left out)."""
    return tyro.conf.Suppress not in _FLAGS.get(cls, {}).get(name, ())


@REGISTRY.struct_rule
def _config_rule(info: StructTypeInfo) -> Any:
    """A registered config as tyro's default spec, each field with its registered settings,
    built after its values pass the config's declared checks named by their flags."""
    cls = info.type
    if cls not in _FLAGS or cls in _BUILDING:
        return None
    _BUILDING.add(cls)
    try:
        spec = ConstructorRegistry.get_struct_spec(info)
    finally:
        _BUILDING.discard(cls)
    if not isinstance(spec, StructConstructorSpec):
        return spec
    marks = _FLAGS[cls]

    def marked(f: Any) -> Any:
        return dataclasses.replace(f, type=Annotated[(f.type, *marks[f.name])])

    fields = tuple(marked(f) if f.name in marks else f for f in spec.fields)

    def instantiate(**values: Any) -> Any:
        check_values(cls, values, lambda name: flag_name(cls, name))
        return spec.instantiate(**values)

    return StructConstructorSpec(instantiate=instantiate, fields=fields)


class _Refused(Exception):
    """Raised from tyro's parse-error hook: the refusal, worded as one line."""


def refuse(message: str) -> NoReturn:
    """Print ``pioneer: error: message`` (one line: any line breaks in it are folded) and exit
    2, as for any bad command line."""
    print(f"pioneer: error: {one_line(message)}", file=sys.stderr)
    raise SystemExit(2)


def one_line(message: str) -> str:
    """``message`` with its line breaks and runs of blanks folded into single spaces."""
    return " ".join(message.split())


def parse(
    cls: type[T],
    args: Sequence[str],
    prog: str,
    description: str | None = None,
    label: str | None = None,
) -> T:
    """``tyro.cli(cls)`` over ``args``; ``--help`` prints and exits 0, a bad command line exits 2
    with one line on stderr (see the module docstring) that names ``label`` (default: prog)."""
    repeated = _repeated_option(args)
    if repeated is not None:
        # argparse (under tyro) keeps the last of a repeated option and drops the others
        # silently: `--scenario hr-rl --scenario hl-rr` would evaluate hl-rr alone.
        refuse(
            expect(
                f"{label or prog} {repeated}",
                "each option once (several values follow one flag)",
                f"{repeated} given more than once",
                f"write {repeated} A B",
            )
        )
    box = io.StringIO()
    try:
        with _hook(cls, args, label or prog), contextlib.redirect_stderr(box):
            return tyro.cli(
                cls, args=list(args), prog=prog, description=description, registry=REGISTRY
            )
    except _Refused as refusal:
        refuse(str(refusal))
    except SystemExit as exc:
        if exc.code in (0, None):
            raise
        refuse(_flatten(box.getvalue()) or f"{prog}: the command line was refused; fix: see --help")


def _repeated_option(args: Sequence[str]) -> str | None:
    """The first long option given twice in ``args`` (before a ``--``), or None."""
    seen: set[str] = set()
    for arg in args:
        if arg == "--":
            break
        if arg.startswith("--"):
            name = arg.split("=", 1)[0]
            if name in seen:
                return name
            seen.add(name)
    return None


@contextlib.contextmanager
def _hook(cls: type, args: Sequence[str], prog: str) -> Iterator[None]:
    if tyro_errors is None:  # pragma: no cover - depends on the installed tyro
        yield
        return

    def hook(event: Any) -> None:
        try:
            message = _describe(event, cls, args, prog)
        except AttributeError:  # another tyro's events: fall back to its box
            return
        if message is not None:
            raise _Refused(message)

    with tyro_errors.on_parse_error(hook):
        yield


def _describe(event: Any, cls: type, args: Sequence[str], prog: str) -> str | None:
    """The house message for a refusal tyro describes as ``event``; ``None``: use tyro's."""
    te = tyro_errors
    if isinstance(event, te.MissingSubcommand):
        names = ", ".join(event.subcommand_spec.parser_from_name)
        usage = f"usage: {prog} COMMAND [OPTIONS]; see {prog} --help"
        return expect(prog, f"a command, one of {names}", None, f"add one ({usage})")
    if isinstance(event, te.UnrecognizedArgs):
        return _unrecognized(event.tokens, cls, args, prog)
    if isinstance(event, te.MissingArgs):
        name, usage = _usage(event.missing_arguments[0].arg)
        return expect(f"{prog} {name}", "a value (it is required)", None, f"add {usage}")
    if isinstance(event, te.InvalidChoice):
        name, choices = _usage(event.argument)[0], ", ".join(event.choices)
        return expect(f"{prog} {name}", f"one of {choices}", event.value, f"pick one of {choices}")
    if isinstance(event, te.BadValue) and event.reason == "too_few_values":
        name, usage = _usage(event.argument)
        nargs = event.argument.lowered.nargs
        wanted = f"{nargs} values" if isinstance(nargs, int) and nargs > 1 else "a value"
        return expect(f"{prog} {name}", wanted, _given(args, name), f"give {usage}")
    if isinstance(event, te.InstantiationFailure):
        if event.argument is None:  # the options refused themselves: the message is ours
            return str(event.message)
        name, usage = _usage(event.argument)
        reason = _reason(str(event.message))
        wanted = f"{event.argument.lowered.metavar or 'a valid value'} ({reason})"
        return expect(f"{prog} {name}", wanted, _given(args, name), f"give {usage}")
    return None


def _reason(message: str) -> str:
    """tyro's reason a value could not be made, as one line: for an optional option (``int |
    None``) it lists every type's error — keep the real type's, not ``None``'s."""
    lines = [line.strip() for line in message.splitlines() if line.strip()]
    errors = [line[2:] for line in lines if line.startswith("- ")]
    typed = [e for e in errors if not e.startswith("<class 'NoneType'>")]
    if typed:
        return one_line(typed[-1].split(">: ", 1)[-1])
    return one_line(message)


def _usage(arg: Any) -> tuple[str, str]:
    """An argument's name (``--out``, or a positional's) and how to give it (``--out DIR``)."""
    name, metavar = str(arg.display_name()), str(arg.lowered.metavar or "")
    if arg.is_positional():
        return metavar or name.upper(), metavar or name.upper()
    return name, f"{name} {metavar}".strip()


def _unrecognized(tokens: Sequence[str], cls: type, args: Sequence[str], prog: str) -> str:
    """Unknown options (with the nearest known one as the fix), a value given to a switch
    (``--lidar=yes``) or values nobody takes."""
    options = [t.split("=", 1)[0] for t in tokens if t.startswith("-") and not _is_number(t)]
    if options:
        known = ["--help", *_flags(cls)]
        near = difflib.get_close_matches(options[0], known, n=1)
        fix = f"did you mean {near[0]}? (see {prog} --help)" if near else f"see {prog} --help"
        received = options[0] if len(options) == 1 else options
        return expect(prog, "a known option", received, fix)
    for a in args:
        switch, _, value = a.partition("=")
        if a.startswith("--") and value == tokens[0]:
            return expect(f"{prog} {switch}", "no value (a switch)", value, f"write {switch} alone")
    if len(tokens) == 1:
        return expect(prog, "no further values", tokens[0], f"remove it (see {prog} --help)")
    return expect(prog, "no further values", list(tokens), f"remove them (see {prog} --help)")


def _flags(cls: type) -> list[str]:
    """The ``--flags`` of an options dataclass (those of nested option groups unprefixed, a
    registered config's as registered)."""
    if not dataclasses.is_dataclass(cls):
        return []
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        nested = hints[f.name]
        if isinstance(nested, type) and dataclasses.is_dataclass(nested):
            out += _flags(nested)
        elif _shown(cls, f.name):
            out.append(flag_name(cls, f.name))
    return out


def _given(args: Sequence[str], name: str) -> str | list[str] | None:
    """The value(s) that follow option ``name`` on the command line (up to the next option)."""
    for i, a in enumerate(args):
        if a.startswith(name + "="):
            return a.split("=", 1)[1]
        if a == name:
            values = []
            for v in args[i + 1 :]:
                if v.startswith("-") and not _is_number(v):
                    break
                values.append(v)
            return values[0] if len(values) == 1 else values or None
    return None


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


_BOX = re.compile(r"[╭╮╰╯│─━┃┏┓┗┛]+")


def _flatten(text: str) -> str:
    """tyro's error box as one line: frame characters dropped, whitespace collapsed."""
    return " ".join(_BOX.sub(" ", text).split())
