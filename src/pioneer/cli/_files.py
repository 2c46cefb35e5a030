"""The files a command reads and writes, declared on its options (``InFile``, ``InPath``,
``OutFile``, ``OutDir``) and checked before any work by :func:`check_outputs`."""

from __future__ import annotations

import dataclasses
import errno
import os
import typing
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Any, Literal

from pioneer.cli._options import metavar
from pioneer.cli._parse import flag_name
from pioneer.errors import DataError, expect

__all__ = [
    "InFile",
    "InPath",
    "Input",
    "OutDir",
    "OutFile",
    "Output",
    "check_outputs",
]


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
    for name, values, mark in _marked(command, Input):
        flag = flag_name(type(command), name)
        for value in values if isinstance(values, tuple) else (values,):  # one path or several
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
