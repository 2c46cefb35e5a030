"""File helpers: atomic writes (temp file in the same folder, then rename)."""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import stat
import tempfile
import zipfile
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from pioneer.errors import DataError, expect

__all__ = [
    "atomic_path",
    "check_regular_target",
    "load_npz",
    "naming_path",
    "output_dir",
    "output_dir_kind",
    "remove_partial_writes",
    "to_json",
    "write_text_atomic",
]

# Read once at import (reading the umask means setting it; not thread-safe later on).
_UMASK = os.umask(0)
os.umask(_UMASK)


_KINDS = (
    (stat.S_ISDIR, "a folder"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISSOCK, "a socket"),
)


def check_regular_target(path: str | os.PathLike[str]) -> Path:
    """``path`` as a :class:`Path` if it is a regular file or does not exist yet; anything
    else (folder, device, FIFO, socket — also behind a symlink) raises :class:`DataError`,
    so a writer never replaces or blocks on it."""
    target = Path(path)
    try:
        mode = target.stat().st_mode
    except FileNotFoundError:
        return target
    if stat.S_ISREG(mode):
        return target
    raise DataError(
        expect(f"output {target}", "a regular file or a new path", _kind(mode), "name a file path")
    )


def _kind(mode: int) -> str:
    if stat.S_ISREG(mode):
        return "a regular file"
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def output_dir_kind(path: str | os.PathLike[str]) -> Path:
    """``path`` as a :class:`Path` if it is a folder or does not exist yet; a file, device,
    FIFO or socket there raises :class:`DataError`."""
    out = Path(path)
    with contextlib.suppress(FileNotFoundError):
        mode = out.stat().st_mode
        if not stat.S_ISDIR(mode):
            raise DataError(
                expect(
                    f"output folder {out}", "a folder or a new path", _kind(mode), "name a folder"
                )
            )
    return out


def output_dir(path: str | os.PathLike[str]) -> Path:
    """Create the output folder ``path`` (and its parents) if needed and return it; a file,
    device, FIFO or socket at ``path`` raises :class:`DataError` (:func:`output_dir_kind`), an
    unwritable place the :class:`OSError` that the CLI reports in one line."""
    out = output_dir_kind(path)
    out.mkdir(parents=True, exist_ok=True)
    return out


@contextlib.contextmanager
def naming_path(path: str | os.PathLike[str]) -> Iterator[None]:
    """Re-raise an :class:`OSError` of the body (a full disk, a file-size limit, a temporary
    file that cannot be created) with ``path`` as its file name, so the one error line names
    the file the user asked for, not a temporary one or none."""
    try:
        yield
    except OSError as exc:
        if exc.errno is None:
            raise
        raise OSError(exc.errno, exc.strerror, os.fspath(path)) from exc


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it over ``path``.

    If the body raises, the temporary file is removed and ``path`` is left untouched, so a
    crash or bad input never leaves a half-written file behind. ``path`` must be a regular
    file or new (:func:`check_regular_target`): a device, FIFO, socket or folder there is
    refused before anything is written.
    """
    target = check_regular_target(path)
    with naming_path(target):
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(
            prefix=f".{target.name}.", suffix=target.suffix, dir=target.parent
        )
        os.close(fd)
        tmp_path = Path(tmp)
        try:
            yield tmp_path
            # mkstemp creates 0600, and writers that recreate the file (safetensors) do too:
            # give the finished file the usual permissions.
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


def _finite(obj: Any) -> Any:
    """``obj`` with every non-finite float (NaN, ±inf; numpy scalars too) as ``None``."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _finite(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def to_json(obj: Any, **kwargs: Any) -> str:
    """``json.dumps`` for everything PioneeR writes or prints: strict JSON, so a NaN or an
    infinity (an undefined mean, an AUROC without negatives) is written as ``null``."""
    return json.dumps(_finite(obj), allow_nan=False, **kwargs)


# atomic_path's temporary file: "." + the target's name + "." + mkstemp's 8 characters + suffix
_PARTIAL = re.compile(r"^\.(?P<name>.+)\.[A-Za-z0-9_]{8}(?P<suffix>\.[^.]*)?$")


def remove_partial_writes(folder: str | os.PathLike[str]) -> int:
    """Delete the temporary files that :func:`atomic_path` leaves below ``folder`` when its
    process is killed mid-write (a resumed run never reads them); returns how many. A missing
    folder has none."""
    removed = 0
    for p in Path(folder).rglob(".*"):
        m = _PARTIAL.match(p.name)
        if m and p.is_file() and m["name"].endswith(m["suffix"] or ""):
            p.unlink()
            removed += 1
    return removed
