"""Sphinx extension: the CLI reference, written from each command's own ``--help``.

When the site builds, the command tree of ``pioneer`` is walked and ``pioneer PATH --help`` is
run for every command and group (a subprocess each, as a user would type it); the outputs go
into ``reference/cli.md`` (generated, not committed), so the page cannot fall behind the CLI.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

from sphinx.application import Sphinx

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
    env = {**os.environ, "COLUMNS": WIDTH, "NO_COLOR": "1", "TERM": "dumb"}
    done = subprocess.run(
        [sys.executable, "-m", "pioneer.cli", *path, "--help"],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    if done.returncode != 0:
        command = " ".join(("pioneer", *path))
        raise RuntimeError(f"{command} --help exited {done.returncode}: {done.stderr}")
    return done.stdout.rstrip()


def write_page(app: Sphinx) -> None:
    paths = [(), *_paths(_TREE)]
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        helps = list(pool.map(_help, paths))
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
