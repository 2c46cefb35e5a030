"""The records file of a run folder, ``episodes.jsonl``: one JSON record per episode.

Records are appended whole by one writer (:func:`append_record`: line, flush, fsync; a torn
line is cut off again on a full disk). Reading (:func:`read_records`) refuses a malformed line
with its line number, drops an unfinished last line (a crash mid-write) with a warning, and
counts each episode (scenario, policy, seed, trial) once, saying how many repeats it ignored,
and upgrades records of an older layout (:func:`upgrade_record`).
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from pioneer.errors import ConfigError, DataError, expect
from pioneer.eval.episode import RECORD_FORMAT
from pioneer.io import naming_path, to_json

__all__ = [
    "append_record",
    "check_seed_set",
    "key_of",
    "parse_records",
    "read_records",
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


def parse_records(p: Path) -> tuple[list[dict[str, Any]], list[str], int]:
    """``(records, the file's complete lines, duplicates dropped)`` of ``p`` (none if it does
    not exist), reading only; a last line without a newline is left out of both."""
    text = p.read_text() if p.exists() else ""
    lines = text.split("\n")
    whole = lines[:-1]
    out: list[dict[str, Any]] = []
    seen: set[tuple[str, str, int, int]] = set()
    duplicates = 0
    for i, line in enumerate(whole, start=1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except json.JSONDecodeError as exc:
            raise DataError(
                expect(
                    f"{p}: line {i}",
                    "one JSON record",
                    line[:60],
                    "delete or repair that line, then resume",
                )
            ) from exc
        if not isinstance(rec, dict):
            raise DataError(
                expect(f"{p}: line {i}", "a JSON object", line[:60], "delete or repair that line")
            )
        missing = {"scenario", "policy", "seed", "trial", "event"} - set(rec)
        if missing:
            raise DataError(
                expect(
                    f"{p}: line {i}",
                    "fields scenario/policy/seed/trial/event",
                    sorted(missing),
                    "delete that line",
                )
            )
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
    records, whole, duplicates = parse_records(p)
    warn_duplicates(p, duplicates)
    if _torn(p):
        print(
            f"pioneer: warning: {p}: ignoring an unfinished last line (re-running it)",
            file=sys.stderr,
        )
        with open(p, "w") as fh:  # drop the partial tail so appends stay line-aligned
            fh.write("".join(line + "\n" for line in whole))
    return records


def _torn(p: Path) -> bool:
    """Whether the file ends in a line without its newline."""
    if not p.exists():
        return False
    with open(p, "rb") as fh:
        fh.seek(0, os.SEEK_END)
        if fh.tell() == 0:
            return False
        fh.seek(-1, os.SEEK_END)
        return fh.read(1) != b"\n"


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


def check_seed_set(path: Path, records: Sequence[Mapping[str, Any]], seed_set: str) -> None:
    """A folder holds episodes of one seed set (records before seed sets: evaluation); records
    of another are refused."""
    found = sorted({str(r.get("seed_set", "evaluation")) for r in records})
    if found and found != [seed_set]:
        raise ConfigError(
            expect(
                f"{path}: records of the {seed_set} seed set",
                f"only {seed_set} episodes in one folder",
                f"{'/'.join(found)} episodes",
                "evaluate into another --out",
            )
        )
