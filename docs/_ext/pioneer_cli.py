"""Sphinx extension: the CLI reference, written from each command's own ``--help``.

When the site builds, the command tree of ``pioneer`` is walked and ``pioneer PATH --help`` is
run for every command and group (through the console script's own entry point,
:func:`pioneer.cli.main`, in this process: a subprocess each would import torch again for
every command); the outputs go into ``reference/cli.md`` (generated, not committed), so the
page cannot fall behind the CLI.
"""

from __future__ import annotations

import contextlib
import io
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from sphinx.application import Sphinx

from pioneer.cli import main
from pioneer.cli._app import _TREE, _Group

PAGE = Path("reference") / "cli.md"
WIDTH = "100"

INTRO = """\
# CLI reference

Generated from the commands' own `--help` each time the site is built. Every command takes
the global `--scenarios FILE` before its name (`pioneer --scenarios FILE COMMAND …`). Bad
input is refused in one line with exit code 2; Ctrl-C or SIGTERM stops a long run within 2 s
with exit code 130 or 143 and prints the command that resumes it
([architecture](../architecture.md)). `pioneer --version` prints the version.
"""


def _paths(group: _Group, prefix: tuple[str, ...] = ()) -> Iterator[tuple[str, ...]]:
    for name, child in group.children.items():
        yield (*prefix, name)
        if isinstance(child, _Group):
            yield from _paths(child, (*prefix, name))


def _help(path: tuple[str, ...]) -> str:
    out = io.StringIO()
    code: int | str | None
    with contextlib.redirect_stdout(out), _environment(COLUMNS=WIDTH):
        try:
            code = main([*path, "--help"])
        except SystemExit as exc:  # argparse's --help exits 0
            code = exc.code
    if code not in (0, None):
        command = " ".join(("pioneer", *path))
        raise RuntimeError(f"{command} --help exited {code}")
    return out.getvalue().rstrip()


@contextlib.contextmanager
def _environment(**values: str) -> Iterator[None]:
    """Set environment variables for the duration of the block (the help's width)."""
    saved = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def write_page(app: Sphinx) -> None:
    paths = [(), *_paths(_TREE)]
    helps = [_help(path) for path in paths]
    parts = [INTRO]
    for path, text in zip(paths, helps, strict=True):
        title = " ".join(("pioneer", *path))
        parts.append(f"## `{title}`\n\n```text\n{text}\n```\n")
    page = Path(app.srcdir) / PAGE
    new = "\n".join(parts)
    if not page.exists() or page.read_text(encoding="utf-8") != new:
        page.write_text(new, encoding="utf-8")


def setup(app: Sphinx) -> dict[str, Any]:
    app.connect("builder-inited", write_page)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
