"""File helpers: atomic writes (temp file in the same folder, then rename)."""

from __future__ import annotations

import contextlib
import datetime
import hashlib
import json
import math
import os
import re
import socket
import stat
import tempfile
import time
import zipfile
import zlib
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from pioneer.errors import ConfigError, DataError, expect

__all__ = [
    "LOCK_FILE",
    "atomic_path",
    "check_input_file",
    "check_name",
    "check_new_output",
    "check_not_input",
    "check_regular_target",
    "file_record",
    "file_sha256",
    "inside",
    "load_npz",
    "naming_path",
    "output_dir",
    "output_dir_kind",
    "read_text_bounded",
    "remove_partial_writes",
    "run_lock",
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


def check_input_file(path: str | os.PathLike[str], what: str) -> Path:
    """``path`` as a :class:`Path` if it is an existing regular file (also behind a symlink);
    a missing path, a folder, a device, a FIFO or a socket raises :class:`DataError` naming
    ``what`` — before anything reads it (a FIFO would block, ``/dev/zero`` never end)."""
    p = Path(path)
    try:
        mode = p.stat().st_mode
    except FileNotFoundError:
        raise DataError(expect(what, "an existing file", os.fspath(p), "check the path")) from None
    if not stat.S_ISREG(mode):
        raise DataError(expect(f"{what} {p}", "a regular file", _kind(mode), "name a file"))
    return p


def read_text_bounded(path: str | os.PathLike[str], what: str, limit: int) -> str:
    """The UTF-8 text of the regular file ``path`` (:func:`check_input_file`), refused with
    :class:`DataError` naming ``what`` if it is larger than ``limit`` bytes (the limit in the
    message) or is not UTF-8 (the offset of the first bad byte in the message)."""
    p = check_input_file(path, what)
    with open(p, "rb") as fh:
        data = fh.read(limit + 1)
    if len(data) > limit:
        raise DataError(
            expect(
                f"{what} {p}",
                f"at most {limit:,} bytes",
                f"a larger file ({p.stat().st_size:,} bytes)",
                "split it into smaller files",
            )
        )
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DataError(
            expect(
                f"{what} {p}",
                "UTF-8 text",
                f"byte 0x{data[exc.start]:02x} at offset {exc.start}, not UTF-8",
                "save the file as UTF-8",
            )
        ) from None


def check_not_input(
    output: str | os.PathLike[str], inputs: Iterable[str | os.PathLike[str] | None]
) -> None:
    """Refuse with :class:`DataError` an ``output`` that would write over one of the command's
    ``inputs``: the same file (by name, through a symbolic link or a hard link) or a path
    inside an input folder. Missing inputs are left to their own checks."""
    out = Path(output)
    resolved = out.resolve()
    for item in inputs:
        if item is None:
            continue
        inp = Path(item)
        if not inp.exists():
            continue
        if out.exists() and os.path.samefile(out, inp):
            same_name = out.absolute() == inp.absolute()
            got = f"the input {inp} itself" if same_name else f"a link to the input {inp}"
        elif inp.is_dir() and resolved.is_relative_to(inp.resolve()):
            got = f"a path inside the input folder {inp}"
        else:
            continue
        raise DataError(
            expect(
                f"output {out}",
                "a path that is none of the command's inputs",
                got,
                "write the output to another path",
            )
        )


def check_new_output(path: str | os.PathLike[str], flag: str, overwrite: bool) -> None:
    """Refuse with :class:`DataError` an output file that exists already unless ``overwrite``
    (``flag`` given): a dataset or a model a user made is never replaced unasked."""
    p = Path(path)
    if not overwrite and p.exists():
        raise DataError(
            expect(
                f"output {p}",
                "a new path",
                "an existing file",
                f"choose another path, or pass {flag} to replace it",
            )
        )


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
    raises one :class:`DataError` naming ``what`` and the ``fix``. A file that is no ``.npz``
    archive at all is reported as such (and a safetensors checkpoint by name), never with
    numpy's hint to load it unsafely."""
    p = Path(path)
    if not p.is_file():
        raise DataError(expect(what, "an existing .npz file", str(p), "check the path"))
    if not zipfile.is_zipfile(p):
        raise DataError(expect(f"{what} {p}", "an .npz archive", _file_kind(p), fix))
    try:
        with np.load(p, allow_pickle=False) as f:
            return {k: f[k] for k in f.files}
    except (zipfile.BadZipFile, zlib.error, ValueError, OSError, EOFError) as exc:
        # numpy refuses object arrays with a hint to allow pickles: PioneeR never does.
        why = "object arrays (pickled data, never loaded)" if "pickle" in str(exc) else str(exc)
        raise DataError(
            expect(f"{what} {p}", "a readable .npz archive", f"unreadable: {why}", fix)
        ) from exc


def _file_kind(p: Path) -> str:
    """What a file that is no zip archive looks like: a safetensors file (8 bytes of header
    length, little-endian, then a JSON object), empty, or neither."""
    with open(p, "rb") as fh:
        head = fh.read(9)
    if not head:
        return "an empty file"
    if len(head) == 9 and head[8:9] == b"{" and 2 <= int.from_bytes(head[:8], "little") < 2**27:
        return "a safetensors file (a network checkpoint), not an .npz archive"
    return "not an .npz archive"


def file_sha256(path: str | os.PathLike[str]) -> str:
    """The SHA-256 of a file's bytes, as hex (read in chunks)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def file_record(path: str | os.PathLike[str]) -> dict[str, str]:
    """``{"path", "sha256"}`` of a file a run loaded: what it was, not only where."""
    return {"path": os.fspath(path), "sha256": file_sha256(path)}


# Names that become file names (scenarios, layout prefixes, row labels): no separator, no
# leading dot (so neither "." nor ".."), nothing a shell or a file system treats specially.
_SAFE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")


def check_name(what: str, name: object) -> str:
    """``name`` if it is a safe name — letters, digits, ``-``, ``_`` and ``.``, not starting
    with a dot — else :class:`ConfigError` naming ``what``. Such a name, used as a file name,
    stays in its folder."""
    if not isinstance(name, str) or not _SAFE_NAME.fullmatch(name):
        raise ConfigError(
            expect(
                what,
                "a name of letters, digits, '-', '_' and '.' (not starting with '.')",
                name,
                "rename it (no '/', no spaces, no leading dot)",
            )
        )
    return name


def inside(folder: str | os.PathLike[str], name: str) -> Path:
    """``folder / name``, refused with :class:`DataError` unless it stays inside ``folder``:
    ``name`` is relative and, once ``..`` and ``.`` are resolved, names something below the
    folder. (Resolved by name, not by following symbolic links: a link the user placed in the
    folder leads where they meant it to.)"""
    base = Path(folder)
    rel = os.path.normpath(name) if name else "."
    if os.path.isabs(name) or rel == "." or rel == ".." or rel.startswith(".." + os.sep):
        raise DataError(
            expect(
                f"output {name!r}",
                f"a path inside {base}",
                os.fspath(base / name),
                "use a plain name (no '..', no absolute path)",
            )
        )
    return base / rel


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


LOCK_FILE = ".lock"
_STALE_UNREADABLE_S = 10.0  # a lock file still empty after this long was left by a crash


@contextlib.contextmanager
def run_lock(folder: str | os.PathLike[str], instead: str = "use another --out") -> Iterator[Path]:
    """Hold ``folder``'s lock (creating the folder) for the block: one writer per run folder.

    The lock is the file ``folder/.lock``, created exclusively (``O_CREAT | O_EXCL``) with
    ``{"pid", "host", "started"}``; a second writer is refused with :class:`ConfigError`
    naming the holder (and ``instead``, what to do but wait). A lock left by a process that
    no longer runs on this host (killed with SIGKILL, the machine rebooted) is stale: it is
    replaced. The block's end — also by an exception or a signal's
    :class:`~pioneer.interrupt.Interrupted` — removes the lock.
    """
    out = output_dir(folder)
    lock = out / LOCK_FILE
    mine = {
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "started": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }
    with naming_path(lock):
        _acquire(lock, mine, instead)
    try:
        yield out
    finally:
        with contextlib.suppress(OSError):
            if _read_lock(lock) == mine:  # never remove another writer's lock
                lock.unlink()


def _acquire(lock: Path, mine: dict[str, Any], instead: str) -> None:
    for _ in range(3):
        try:
            fd = os.open(lock, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            holder = _read_lock(lock)
            if _stale(lock, holder):
                with contextlib.suppress(FileNotFoundError):
                    lock.unlink()
                continue
            raise ConfigError(_held_line(lock, holder, instead)) from None
        with os.fdopen(fd, "w") as fh:
            fh.write(json.dumps(mine) + "\n")
            fh.flush()
            os.fsync(fh.fileno())
        return
    raise ConfigError(_held_line(lock, _read_lock(lock), instead))


def _read_lock(lock: Path) -> dict[str, Any] | None:
    """The holder written in a lock file; None if it is unreadable (empty: being written)."""
    try:
        holder = json.loads(lock.read_text())
    except (OSError, ValueError):
        return None
    return holder if isinstance(holder, dict) else None


def _stale(lock: Path, holder: dict[str, Any] | None) -> bool:
    """A lock whose process is gone from this host, or that stayed unreadable too long."""
    if holder is None:
        try:
            return time.time() - lock.stat().st_mtime > _STALE_UNREADABLE_S
        except FileNotFoundError:
            return True
    pid = holder.get("pid")
    if holder.get("host") != socket.gethostname() or not isinstance(pid, int):
        return False  # another machine's process (a shared folder): cannot tell
    return not _alive(pid)


def _alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    with contextlib.suppress(OSError, IndexError):  # a zombie has finished (Linux: /proc)
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    return True


def _held_line(lock: Path, holder: dict[str, Any] | None, instead: str) -> str:
    who = (
        f"pid {holder.get('pid')} on {holder.get('host')} since {holder.get('started')}"
        if holder
        else "a run starting"
    )
    return expect(
        f"run folder {lock.parent}",
        "one writer at a time",
        f"another run writing to it ({who})",
        f"wait for it to end or {instead}; if no run uses the folder, delete {lock}",
    )


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
