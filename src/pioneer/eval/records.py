"""The records file of a run folder, ``episodes.jsonl``: one JSON record per episode.

Records are appended whole by one writer (:func:`append_record`: line, flush, fsync; a torn
line is cut off again on a full disk). Reading (:func:`read_records`) refuses a malformed line
with its line number, drops an unfinished last line (a crash mid-write) with a warning, and
counts each episode (scenario, policy, seed, trial) once, saying how many repeats it ignored,
and upgrades records of an older layout (:func:`upgrade_record`).
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import sys
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from pioneer.errors import ConfigError, DataError, expect
from pioneer.eval.episode import RECORD_FORMAT
from pioneer.io import check_input_file, naming_path, to_json

__all__ = [
    "append_record",
    "check_seed_set",
    "key_of",
    "parse_records",
    "read_records",
    "seed_sets",
    "upgrade_record",
    "warn_duplicates",
]

# Layout 1 (records without ``format``) named the surface-to-surface gap "clearance" and the
# centre-to-surface distance "surface"; layout 2 calls them ``gap`` and ``clearance``; layout 3
# adds ``measures`` and ``series``, which an older record cannot be given (its episode would
# have to be run again): it is read without them, and the summaries leave it out of the
# social-navigation measures (pioneer.eval.metrics).
_V1_FIELDS = {"min_clearance_m": "min_gap_m", "min_wall_clearance_m": "min_wall_gap_m"}
_V1_FRAMES = {"clearance": "gap", "surface": "clearance"}


def upgrade_record(rec: dict[str, Any]) -> dict[str, Any]:
    """``rec`` with the current layout's names (:data:`pioneer.eval.episode.RECORD_FORMAT`):
    a record of layout 1 (no ``format``) has its fields renamed, values untouched, and reads
    as layout 2 (``format: 2``); a record of layout 2 is returned as it is. Neither has
    ``measures`` or ``series`` (they need the episode's states), and ``format`` keeps saying
    so. A newer layout is refused."""
    version = rec.get("format", 1)
    if version == RECORD_FORMAT:
        return rec
    if not isinstance(version, int) or version > RECORD_FORMAT:
        raise DataError(
            expect(
                "record format",
                f"{RECORD_FORMAT} or older",
                version,
                "read it with the PioneeR version that wrote it (a newer one)",
            )
        )
    if version >= 2:
        return rec
    out = {_V1_FIELDS.get(k, k): v for k, v in rec.items()}
    if isinstance(out.get("frames"), dict):
        out["frames"] = {_V1_FRAMES.get(k, k): v for k, v in out["frames"].items()}
    out["format"] = 2
    return out


def key_of(rec: Mapping[str, Any]) -> tuple[str, str, int, int]:
    """The identity of a record's episode: (scenario, policy row, seed, trial)."""
    return (str(rec["scenario"]), str(rec["policy"]), int(rec["seed"]), int(rec["trial"]))


MAX_RECORD_BYTES = 8 * 2**20  # one record line's size limit (a record is ≈ 2–50 kB)
_FIELDS = ("scenario", "policy", "seed", "trial", "event")  # every record has them
_EVENTS = ("success", "collision", "timeout")
_NUMBERS = ("time_s", "path_length_m", "min_gap_m", "time_close_s")  # numbers or null


def _lines(p: Path) -> Iterator[tuple[int, str | None]]:
    """``(line number, text)`` of every line of ``p`` that ends in a newline (text without it)
    and, last, ``(number, None)`` for a last line without one; a line longer than
    :data:`MAX_RECORD_BYTES` or not UTF-8 raises :class:`DataError` naming it."""
    with open(check_input_file(p, "records file"), "rb") as fh:
        for i in itertools.count(1):
            raw = fh.readline(MAX_RECORD_BYTES + 1)
            if not raw:
                return
            if not raw.endswith(b"\n"):
                if len(raw) > MAX_RECORD_BYTES:
                    raise DataError(
                        expect(
                            f"{p}: line {i}",
                            f"a record of at most {MAX_RECORD_BYTES:,} bytes",
                            "a longer line",
                            "delete that line (its episode is run again on resume)",
                        )
                    )
                yield i, None
                return
            try:
                yield i, raw[:-1].decode("utf-8")
            except UnicodeDecodeError as exc:
                raise DataError(
                    expect(
                        f"{p}: line {i}",
                        "UTF-8 text",
                        f"byte 0x{raw[exc.start]:02x} at column {exc.start + 1}",
                        "delete or repair that line",
                    )
                ) from None


def _strict(token: str) -> Any:
    raise ValueError(f"{token} (strict JSON has no NaN or Infinity)")


def _check_record(p: Path, i: int, rec: Any, line: str, first: bool) -> None:
    """A record as :func:`pioneer.eval.harness.run_task` writes it: a JSON object with the
    identifying fields, a known ``event`` and numbers (or null) where numbers go."""
    where = f"{p}: line {i}"
    if not isinstance(rec, dict):
        raise DataError(expect(where, "a JSON object", line[:60], "delete or repair that line"))
    missing = [k for k in _FIELDS if k not in rec]
    if missing:
        fix = (
            "name a folder written by pioneer eval (this file holds another command's records)"
            if first
            else "delete that line"
        )
        got = f"a record without {', '.join(missing)} (it has {', '.join(sorted(rec)[:8])})"
        raise DataError(expect(where, f"a record with the fields {', '.join(_FIELDS)}", got, fix))
    if rec["event"] not in _EVENTS:
        raise DataError(
            expect(f"{where}: event", f"one of {_EVENTS}", rec["event"], "delete that line")
        )
    for key in _NUMBERS:
        value = rec.get(key)
        if value is not None and (isinstance(value, bool) or not isinstance(value, int | float)):
            raise DataError(
                expect(f"{where}: {key}", "a number or null", value, "delete that line")
            )


def parse_records(p: Path) -> tuple[list[dict[str, Any]], list[str], int]:
    """``(records, the file's complete lines, duplicates dropped)`` of ``p`` (none if it does
    not exist), reading only; a last line without a newline is left out of both. Records are
    strict: JSON without NaN or Infinity, each an object with the identifying fields, a known
    event and numbers where numbers go; a line that is not (or is not UTF-8, or is longer than
    :data:`MAX_RECORD_BYTES`) raises :class:`DataError` naming it."""
    out: list[dict[str, Any]] = []
    whole: list[str] = []
    seen: set[tuple[str, str, int, int]] = set()
    duplicates = 0
    for i, line in _lines(p) if p.exists() else ():
        if line is None:
            break
        whole.append(line)
        if not line.strip():
            continue
        try:
            rec = json.loads(line, parse_constant=_strict)
        except ValueError as exc:
            why = exc.msg if isinstance(exc, json.JSONDecodeError) else str(exc)
            raise DataError(
                expect(
                    f"{p}: line {i}",
                    "one JSON record (strict: no NaN or Infinity)",
                    f"{line[:60]} ({why})",
                    "delete or repair that line, then resume",
                )
            ) from exc
        _check_record(p, i, rec, line, first=not out and not duplicates)
        try:
            key = key_of(rec)
        except (TypeError, ValueError) as exc:
            raise DataError(
                expect(f"{p}: line {i}", "integer seed and trial", line[:60], "delete that line")
            ) from exc
        if key in seen:
            duplicates += 1
            continue
        seen.add(key)
        out.append(upgrade_record(rec))
    return out, whole, duplicates


def warn_duplicates(path: Path, duplicates: int) -> None:
    """Say on stderr how many repeated records :func:`parse_records` ignored (none: nothing)."""
    if duplicates:
        print(
            f"pioneer: warning: {path}: {duplicates} repeated episode record(s) ignored (each "
            "scenario, policy, seed and trial counts once: the first)",
            file=sys.stderr,
        )


def read_records(path: str | Path) -> list[dict[str, Any]]:
    """All records of an ``episodes.jsonl``, each episode (scenario, policy, seed, trial) once;
    a malformed line raises :class:`DataError`.

    A repeated episode (a line duplicated by hand, or by two runs that once wrote to one
    folder) counts once — the first record — with one warning on stderr saying how many were
    ignored. A last line without a newline (a write cut by a crash) is dropped with a warning
    on stderr, since its episode will simply be run again.
    """
    p = Path(path)
    records, _, duplicates = parse_records(p)
    warn_duplicates(p, duplicates)
    keep, size = _line_aligned_size(p)
    if keep < size:
        print(
            f"pioneer: warning: {p}: ignoring an unfinished last line (re-running it)",
            file=sys.stderr,
        )
        # drop the partial tail so appends stay line-aligned: one truncation at the last
        # newline, so no whole line is ever rewritten (or lost if this process is killed)
        os.truncate(p, keep)
    return records


def _line_aligned_size(p: Path) -> tuple[int, int]:
    """``(bytes up to and including the last newline, all bytes)`` of ``p`` (0, 0 if it does
    not exist); the two differ when the last line is unfinished."""
    if not p.exists():
        return 0, 0
    with open(p, "rb") as fh:
        size = end = fh.seek(0, os.SEEK_END)
        while end > 0:
            start = max(0, end - 65536)
            fh.seek(start)
            at = fh.read(end - start).rfind(b"\n")
            if at >= 0:
                return start + at + 1, size
            end = start
    return 0, size


def append_record(fh: Any, rec: dict[str, Any]) -> None:
    """Append one whole record line; if the disk is full, cut the torn line off again so the
    file resumes cleanly, and name the file in the error."""
    line = to_json(rec) + "\n"
    with naming_path(fh.name):
        pos = fh.tell()
        try:
            fh.write(line)
            fh.flush()
            os.fsync(fh.fileno())
        except OSError:
            with contextlib.suppress(OSError):
                fh.truncate(pos)
            raise


def seed_sets(records: Sequence[Mapping[str, Any]]) -> list[str]:
    """The seed sets of ``records``, sorted (records before seed sets: evaluation)."""
    return sorted({str(r.get("seed_set", "evaluation")) for r in records})


def check_seed_set(path: Path, records: Sequence[Mapping[str, Any]], seed_set: str) -> None:
    """A folder holds episodes of one seed set (records before seed sets: evaluation); records
    of another are refused."""
    found = seed_sets(records)
    if found and found != [seed_set]:
        raise ConfigError(
            expect(
                f"{path}: records of the {seed_set} seed set",
                f"only {seed_set} episodes in one folder",
                f"{'/'.join(found)} episodes",
                "evaluate into another --out",
            )
        )
