"""The exception hierarchy of PioneeR.

Every error a user can cause says what was expected, what was received and how to fix it.
The CLI turns any :class:`PioneerError` into one line on stderr and exit code 2.
"""

from __future__ import annotations


class PioneerError(Exception):
    """Base class of all errors a user can cause (bad config, bad data, bad command)."""


class ConfigError(PioneerError, ValueError):
    """A configuration value is invalid: out of range, unknown key, impossible geometry."""


class ScenarioError(ConfigError):
    """A scenario cannot be built or sampled (unknown name, humans placed in walls)."""


class CommandError(PioneerError, ValueError):
    """A control command is malformed (wrong shape, NaN or inf)."""


class DataError(PioneerError, ValueError):
    """A file or array does not hold what it should (shape, finiteness, range, truncation)."""


def expect(field: str, expected: str, received: object, fix: str) -> str:
    """Format the house error message: ``field: expected X, received Y; fix: Z``."""
    return f"{field}: expected {expected}, received {received!r}; fix: {fix}"
