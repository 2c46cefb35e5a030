"""The exception hierarchy of PioneeR.

Every error a user can cause says what was expected, what was received and how to fix it.
The CLI turns any :class:`PioneerError` into one line on stderr and exit code 2.
"""

from __future__ import annotations

import errno


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


# Optional dependencies: import name -> the pip extra that installs it.
EXTRAS = {
    "torch": "learn",
    "safetensors": "learn",
    "onnx": "learn",
    "onnxruntime": "deploy",
    "rosbags": "ros",
    "pygame": "teleop",
    "ray": "distributed",
    "pysocialforce": "bench",
    "stable_baselines3": "sb3",
}

_OS_FIXES = {
    errno.EACCES: "choose a path you may write to (or read)",
    errno.EPERM: "choose a path you may write to (or read)",
    errno.EROFS: "choose a path on a writable file system",
    errno.ENOSPC: "free disk space and run again",
    errno.EDQUOT: "free disk space (or raise the quota) and run again",
    errno.EFBIG: "raise the file-size limit (ulimit -f) or free space, and run again",
    errno.ENOTDIR: "a part of the path is a file, not a folder: choose another path",
    errno.EISDIR: "the path is a folder: name a file inside it",
    errno.EEXIST: "the path exists as the other kind (file or folder): choose another path",
    errno.ENOENT: "check the path",
    errno.ENAMETOOLONG: "choose a shorter path",
}


def os_error_line(exc: OSError) -> str:
    """One line for an :class:`OSError` met while reading or writing a file: the path, what
    happened and the fix (the CLI prints it and exits 2)."""
    where = exc.filename if exc.filename is not None else "a file"
    what = exc.strerror or type(exc).__name__
    name = errno.errorcode.get(exc.errno or 0, "")
    received = f"{what} ({name})" if name else what
    fix = _OS_FIXES.get(exc.errno or 0, "check the path and the disk")
    return f"{where}: expected a path that can be read or written, received {received}; fix: {fix}"


def missing_dependency_line(exc: ImportError) -> str:
    """One line for a missing optional dependency, naming the extra that installs it."""
    module = (exc.name or str(exc)).split(".")[0]
    extra = EXTRAS.get(module)
    fix = f"pip install 'pioneer-nav[{extra}]'" if extra else f"pip install {module}"
    return expect(f"module {module}", "installed", "not installed", fix)
