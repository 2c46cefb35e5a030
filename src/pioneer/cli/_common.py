"""What the command modules share: defaults read where they are declared, choices, option
types, the teacher's ablation flags and ``--policy NAME[:key=value,…]``."""

from __future__ import annotations

import dataclasses
import errno
import math
import os
import sys
import typing
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, Protocol

import tyro
from annotated_types import Ge

from pioneer.cli._parse import config_flags, flag_name
from pioneer.config import default
from pioneer.errors import ConfigError, DataError, expect

if TYPE_CHECKING:
    from pioneer.eval.harness import PolicySpec

__all__ = [
    "Ablation",
    "Ablations",
    "Command",
    "Flag",
    "InFile",
    "InPath",
    "Input",
    "OutDir",
    "OutFile",
    "Output",
    "Seed",
    "Workers",
    "check_outputs",
    "command_line",
    "config_flags",
    "default",
    "flag_name",
    "metavar",
    "number",
    "one_of",
    "optional",
    "policy_spec",
    "require_some",
]


class Command(Protocol):
    """A parsed command: its options, and ``run`` to carry it out (returns the exit code)."""

    def run(self) -> int:
        """Do the work; a :class:`~pioneer.errors.PioneerError` becomes one line, exit 2."""
        ...


def number(value: float | None, spec: str, unit: str = "") -> str:
    """``value`` formatted by ``spec`` (with `` unit`` after it), or "–" where there is none
    (``None``, NaN, ±∞: a mean over no episode), as the tables print it; never ``nan``."""
    if value is None or not math.isfinite(value):
        return "–"
    return f"{value:{spec}}" + (f" {unit}" if unit else "")


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


@dataclasses.dataclass(frozen=True)
class Output:
    """Marks an option as a path the command writes: a ``file`` or a ``folder``. Every such
    path is checked before the command starts (:func:`check_outputs`)."""

    kind: Literal["file", "folder"]


OutFile = Annotated[str, metavar("FILE"), Output("file")]
OutDir = Annotated[str, metavar("DIR"), Output("folder")]


@dataclasses.dataclass(frozen=True)
class Input:
    """Marks an option as a path the command reads: a regular ``file``, or a ``path`` that
    may be a file or a folder (a ROS 2 bag, a distill folder). No output may be one of them
    (:func:`check_outputs`), and a ``file`` must be a regular file before it is read."""

    kind: Literal["file", "path"]


InFile = Annotated[str, metavar("FILE"), Input("file")]
InPath = Annotated[str, metavar("PATH"), Input("path")]


def _marked(command: object, mark: type[Any]) -> list[tuple[str, Any, Any]]:
    """``(field name, value, mark)`` of every field of ``command`` marked with a ``mark``
    instance whose value is set."""
    hints = typing.get_type_hints(type(command), include_extras=True)
    out = []
    for f in dataclasses.fields(command):  # type: ignore[arg-type]
        marks = [m for m in getattr(hints[f.name], "__metadata__", ()) if isinstance(m, mark)]
        value = getattr(command, f.name)
        if marks and value is not None:
            out.append((f.name, value, marks[0]))
    return out


def check_outputs(command: object, inputs: Sequence[str] = ()) -> None:
    """Refuse, before any work, an output path of the wrong kind (a folder, device, FIFO or
    socket where a file goes; anything but a folder where a folder goes) or under a file, an
    output that is one of the command's inputs (its ``Input`` options and ``inputs``, the
    ``--scenarios`` files) or inside an input folder, an input file that is no regular file,
    and — for a command with ``--overwrite`` — an output file that exists already: so an
    hour's run does not end at a path it cannot write, and nothing a user owns is replaced
    unasked."""
    from pioneer.io import (
        check_input_file,
        check_new_output,
        check_not_input,
        check_regular_target,
        output_dir_kind,
    )

    outputs = _marked(command, Output)
    for _, value, mark in outputs:
        path = Path(value)
        _check_ancestor(path)
        if mark.kind == "file":
            check_regular_target(path)
        else:
            output_dir_kind(path)
    read = [*inputs]
    for name, value, mark in _marked(command, Input):
        flag = flag_name(type(command), name)
        if mark.kind == "file":
            check_input_file(value, flag)
        elif not Path(value).exists():
            raise DataError(expect(flag, "an existing file or folder", value, "check the path"))
        read.append(value)
    overwrite = getattr(command, "overwrite", None)
    for _, value, mark in outputs:
        check_not_input(value, read)
        if mark.kind == "file" and isinstance(overwrite, bool):
            check_new_output(value, "--overwrite", overwrite)


def _check_ancestor(path: Path) -> None:
    # The nearest existing ancestor must be a folder (else: "Not a directory", as the writer
    # would find out only at the end).
    for parent in path.absolute().parents:
        if parent.exists():
            if not parent.is_dir():
                raise NotADirectoryError(errno.ENOTDIR, os.strerror(errno.ENOTDIR), str(path))
            return


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


def command_line() -> str:
    """The command as typed, recorded with the outputs (empty when not run as ``pioneer``)."""
    return " ".join(["pioneer", *sys.argv[1:]]) if sys.argv[0].endswith("pioneer") else ""


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
