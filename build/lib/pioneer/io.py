"""File helpers: atomic writes (temp file in the same folder, then rename)."""

from __future__ import annotations

import contextlib
import os
import tempfile
import zipfile
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from pioneer.errors import DataError, expect

__all__ = ["atomic_path", "load_npz", "write_text_atomic"]

# Read once at import (reading the umask means setting it; not thread-safe later on).
_UMASK = os.umask(0)
os.umask(_UMASK)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it over ``path``.

    If the body raises, the temporary file is removed and ``path`` is left untouched, so a
    crash or bad input never leaves a half-written file behind.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=target.suffix, dir=target.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        # mkstemp creates 0600, and writers that recreate the file (safetensors) do too: give
        # the finished file the usual permissions.
        os.chmod(tmp_path, 0o666 & ~_UMASK)
        os.replace(tmp_path, target)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def load_npz(path: str | os.PathLike[str], what: str, fix: str) -> dict[str, Any]:
    """All arrays of an ``.npz`` (``allow_pickle=False``); a missing, truncated or corrupt file
    raises one :class:`DataError` naming ``what`` and the ``fix``."""
    p = Path(path)
    if not p.is_file():
        raise DataError(expect(what, "an existing .npz file", str(p), "check the path"))
    try:
        with np.load(p, allow_pickle=False) as f:
            return {k: f[k] for k in f.files}
    except (zipfile.BadZipFile, zlib.error, ValueError, OSError, EOFError) as exc:
        raise DataError(
            expect(f"{what} {p}", "a readable .npz", f"unreadable ({exc})", fix)
        ) from exc


def write_text_atomic(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` to ``path`` through :func:`atomic_path`."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)
