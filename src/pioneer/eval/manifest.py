"""What made a run folder's records: ``manifest.json``, and the refusal to resume on a change.

Every evaluation record carries ``made_by`` — its policy's registered name, every parameter
with the value it got (:func:`pioneer.control.registry.resolve_policy`) and the path and
SHA-256 of every file it loaded (checkpoint, reward model, weights, the shipped demos a
default reward is fitted on, the scenario file of a variant). The run folder's
``manifest.json`` maps each row label and scenario to the same, for a reader and for the
next run into the folder::

    {"format": "pioneer.run-manifest/1",
     "rows": {"dwa": {"static": {"policy": "dwa", "params": {"n_v": 5, …}, "files": {}}}}}

A run into a folder that already holds a row of the same label in the same scenario resumes
only if what makes the row is the same; otherwise it is refused, naming the first difference
(``params.n_v``, ``files.checkpoint.sha256``…), before anything is written: one label never
stands for two settings, and old records are never reported as new ones.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from pioneer.errors import ConfigError, DataError, expect
from pioneer.io import to_json, write_text_atomic

__all__ = [
    "MANIFEST_FILE",
    "MANIFEST_FORMAT",
    "PARAMETERS_ADDED",
    "check_made_by",
    "read_manifest",
    "write_manifest",
]

MANIFEST_FILE = "manifest.json"
MANIFEST_FORMAT = "pioneer.run-manifest/1"

MadeBy = dict[tuple[str, str], dict[str, Any]]  # (scenario, row) → {"policy", "params", "files"}

_FIX = "evaluate into a new --out, or pass --overwrite to start over (deletes its records)"

# Parameters a policy factory gained after run folders held records made without them, with
# the value every such record was made with: a recorded ``made_by`` that lacks one reads as
# having it, so an old folder resumes with the same setting and is refused with another.
PARAMETERS_ADDED: dict[str, Any] = {
    "precision": "float64",  # the teacher's ray precision (make_teacher, 2026-11-26)
    "hold": 0,  # the shield's fallback steps after an unsure one (make_shield_policy, 2026-11-27)
    "assume_radius": 0.0,  # what the teacher's predictions assume of people (make_teacher,
    "assume_a_robot": None,  # 2026-11-27): nothing
    "assume_start_now": False,  # people predicted to start walking now (make_teacher, 2026-11-28)
    "patience": 0.0,  # the teacher's patience (make_teacher, 2026-11-28): none, as before
}


def read_manifest(out: Path) -> dict[str, Any]:
    """The manifest of run folder ``out`` (an empty one when there is none); a file that is
    not one raises :class:`DataError`."""
    p = out / MANIFEST_FILE
    if not p.exists():
        return {"format": MANIFEST_FORMAT, "rows": {}}
    try:
        doc = json.loads(p.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise DataError(expect(str(p), "a run manifest (JSON)", "invalid JSON", _FIX)) from exc
    if not isinstance(doc, dict) or doc.get("format") != MANIFEST_FORMAT:
        got = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise DataError(expect(f"{p}: format", MANIFEST_FORMAT, got, _FIX))
    if not isinstance(doc.get("rows"), dict):
        raise DataError(expect(f"{p}: rows", "an object", type(doc.get("rows")).__name__, _FIX))
    return doc


def _leaves(d: Mapping[str, Any], prefix: str = "") -> Iterator[tuple[str, Any]]:
    for k, v in d.items():
        if isinstance(v, Mapping) and v:
            yield from _leaves(v, f"{prefix}{k}.")
        else:
            yield f"{prefix}{k}", v


def first_difference(old: Mapping[str, Any], new: Mapping[str, Any]) -> tuple[str, Any, Any]:
    """The first dotted key (``policy``, then ``params.*``, then ``files.*``, in the order of
    ``new``) whose value differs, with the two values (``None`` for a missing one); raises
    :class:`ValueError` when there is none."""
    a, b = dict(_leaves(old)), dict(_leaves(new))
    for key in [*b, *(k for k in a if k not in b)]:
        if a.get(key) != b.get(key) or (key in a) != (key in b):
            return key, a.get(key), b.get(key)
    raise ValueError("no difference")


def check_made_by(
    out: Path,
    made_by: MadeBy,
    manifest: Mapping[str, Any],
    records: Sequence[Mapping[str, Any]],
) -> None:
    """Refuse (:class:`ConfigError`, one line naming the first difference and the fix) a run
    whose rows are made otherwise than the rows of the same label and scenario that the
    folder's manifest or records hold; records without ``made_by`` (written before manifests)
    cannot be vouched for and are refused as well."""
    by_pair: dict[tuple[str, str], list[Mapping[str, Any]]] = {}
    for r in records:
        by_pair.setdefault((str(r["scenario"]), str(r["policy"])), []).append(r)
    rows = manifest.get("rows", {})
    for (scenario, row), mine in made_by.items():
        recorded = _upgraded(rows.get(row, {}).get(scenario), mine)
        where = f"{out / MANIFEST_FILE}: row {row!r} on {scenario}"
        if recorded is not None and recorded != mine:
            _refuse(where, recorded, mine)
        for rec in by_pair.get((scenario, row), []):
            theirs = _upgraded(rec.get("made_by"), mine)
            if theirs is None:
                raise ConfigError(
                    expect(
                        f"{out}: records of row {row!r} on {scenario}",
                        "records that name what made them (made_by)",
                        "records written before run manifests",
                        _FIX,
                    )
                )
            if theirs != mine:
                _refuse(f"{out}: a record of row {row!r} on {scenario}", theirs, mine)


def _upgraded(recorded: Any, mine: Mapping[str, Any]) -> Any:
    """``recorded`` (a stored ``made_by``, or ``None``) with every parameter of
    :data:`PARAMETERS_ADDED` that ``mine`` has and it lacks, at the value it was made with."""
    if not isinstance(recorded, Mapping) or not isinstance(recorded.get("params"), Mapping):
        return recorded
    params, now = dict(recorded["params"]), mine.get("params", {})
    missing = {k: v for k, v in PARAMETERS_ADDED.items() if k in now and k not in params}
    return {**recorded, "params": {**params, **missing}} if missing else recorded


def _refuse(where: str, recorded: Mapping[str, Any], mine: Mapping[str, Any]) -> None:
    key, old, new = first_difference(recorded, mine)
    raise ConfigError(
        expect(f"{where}: {key}", f"{old!r} (what its records were made with)", new, _FIX)
    )


def write_manifest(out: Path, manifest: Mapping[str, Any], made_by: MadeBy) -> None:
    """Add this run's rows to the folder's manifest (written atomically, only if it grows)."""
    rows: dict[str, dict[str, Any]] = {
        row: dict(scenarios) for row, scenarios in manifest.get("rows", {}).items()
    }
    changed = not (out / MANIFEST_FILE).exists()
    for (scenario, row), mine in made_by.items():
        if rows.get(row, {}).get(scenario) != mine:
            rows.setdefault(row, {})[scenario] = mine
            changed = True
    if changed:
        doc = {"format": MANIFEST_FORMAT, "rows": rows}
        write_text_atomic(out / MANIFEST_FILE, to_json(doc, indent=1) + "\n")
