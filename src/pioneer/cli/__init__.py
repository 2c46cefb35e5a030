"""The ``pioneer`` command. Thin: parse (tyro, one frozen dataclass of options per command),
call, print. A bad command line or any :class:`~pioneer.errors.PioneerError` is one line on
stderr and exit code 2."""

from __future__ import annotations

from pioneer.cli._app import main

__all__ = ["main"]
