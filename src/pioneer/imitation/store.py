"""A DAgger run on disk: one ``.npz`` per labelled episode, one model per round, the settings.

Layout below the run folder ``DIR`` (every file written atomically)::

    DIR/config.json                   the run's settings (a rerun must have the same ones)
    DIR/rounds/round-RR/ep-EEE.npz    episode EEE of round RR: the arrays of its method
    DIR/rounds/round-RR/MODEL         the model fitted on the aggregate of rounds 0..RR

A rerun resumes: what is on disk is kept, only missing episodes are collected and missing
models fitted (:mod:`pioneer.imitation.rounds`). An episode is written whole or not at all,
so a killed run leaves at most the temporary file of one write, which :meth:`RunFolder.prepare`
removes. The settings are checked before anything is written: a rerun with other settings is
refused in one line naming what differs (:func:`check_settings`).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Collection, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pioneer.errors import ConfigError, DataError, expect
from pioneer.io import atomic_path, load_npz, remove_partial_writes, to_json, write_text_atomic

__all__ = ["SETTINGS_FILE", "RunFolder", "check_settings", "file_version", "save_episode"]

SETTINGS_FILE = "config.json"
SETTINGS_FIX = "use the same options to resume, or a new --out directory"


def check_settings(
    where: str,
    stored: Mapping[str, Any],
    mine: Mapping[str, Any],
    what: str,
    free: Collection[str] = (),
) -> None:
    """Refuse ``mine`` unless every key of it but the ``free`` ones has its value in
    ``stored`` (the settings a run in ``where`` was made with; compared as JSON, so tuples
    equal lists; a nested config key by key, named ``student.kind``). Keys only ``stored``
    has are no settings any more and are ignored."""
    new = _flat(json.loads(to_json(dict(mine))))
    stored = _flat(dict(stored))
    diff = [k for k in new if k.split(".")[0] not in free and stored.get(k) != new[k]]
    if diff:
        raise ConfigError(
            expect(
                f"{where}: {what} settings {', '.join(diff)}",
                f"those of the run already there, { ({k: stored.get(k) for k in diff})!r}",
                {k: new[k] for k in diff},
                SETTINGS_FIX,
            )
        )


def _flat(settings: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``settings`` with nested dicts spread into dotted keys (``student.kind``)."""
    out: dict[str, Any] = {}
    for key, value in settings.items():
        if isinstance(value, dict):
            out |= _flat(value, f"{prefix}{key}.")
        else:
            out[f"{prefix}{key}"] = value
    return out


def save_episode(path: str | os.PathLike[str], arrays: Mapping[str, Any]) -> str:
    """Write one episode's ``arrays`` to ``path`` (``.npz``, uncompressed, atomically: a
    reader sees the whole file or none); returns the path."""
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
    return os.fspath(path)


def file_version(path: str | os.PathLike[str]) -> tuple[str, int, int]:
    """``path`` with its modification time and size: a key that changes when the file is
    rewritten (a worker caching the model it drives with sees a recreated run's new one)."""
    st = os.stat(path)
    return os.fspath(path), st.st_mtime_ns, st.st_size


class RunFolder:
    """The files of one DAgger run in ``root``: episodes, the rounds' models (``model_file``
    in each round's folder) and the settings. ``what`` names the run in messages ("DAgger");
    ``defaults`` fill settings that an older run's file lacks, ``upgrade`` (if given) reads a
    stored file in today's layout instead; ``free`` settings (the number of rounds) may differ
    between runs."""

    def __init__(
        self,
        root: str | os.PathLike[str],
        model_file: str,
        what: str,
        defaults: Mapping[str, Any] | None = None,
        free: Collection[str] = (),
        upgrade: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
    ) -> None:
        self.root = Path(root)
        self.model_file = model_file
        self.what = what
        self.defaults = dict(defaults or {})
        self.free = tuple(free)
        self.upgrade = upgrade

    # ------------------------------------------------------------------ layout
    def round_dir(self, rnd: int) -> Path:
        """``DIR/rounds/round-RR``."""
        return self.root / "rounds" / f"round-{rnd:02d}"

    def episode_path(self, rnd: int, index: int) -> Path:
        """``DIR/rounds/round-RR/ep-EEE.npz``."""
        return self.round_dir(rnd) / f"ep-{index:03d}.npz"

    def model_path(self, rnd: int) -> Path:
        """The model fitted after round ``rnd``."""
        return self.round_dir(rnd) / self.model_file

    @property
    def settings_path(self) -> Path:
        """``DIR/config.json``."""
        return self.root / SETTINGS_FILE

    # ------------------------------------------------------------------ episodes
    def missing(self, rnd: int, n: int) -> list[int]:
        """The indices of round ``rnd``'s ``n`` episodes that are not on disk yet."""
        return [i for i in range(n) if not self.episode_path(rnd, i).exists()]

    def load_round(self, rnd: int, n: int) -> list[dict[str, Any]]:
        """The arrays of round ``rnd``'s ``n`` episodes, in order (all must exist)."""
        return [self._load(self.episode_path(rnd, i)) for i in range(n)]

    def _load(self, path: Path) -> dict[str, Any]:
        fix = "delete that file and rerun the command (it will be collected again)"
        return load_npz(path, f"{self.what} episode", fix)

    def check_episodes(self, sizes: Sequence[int]) -> None:
        """Load every episode on disk of a run of ``sizes[r]`` episodes in round r: a corrupt
        one (truncated, not an archive) raises :class:`DataError` naming it, before a resumed
        run collects anything."""
        for rnd, n in enumerate(sizes):
            for i in range(n):
                path = self.episode_path(rnd, i)
                if path.exists():
                    self._load(path)

    def on_disk(self, sizes: Sequence[int]) -> tuple[int, int]:
        """Episodes and rounds' models on disk, of a run of ``sizes[r]`` episodes in round r."""
        eps = sum(self.episode_path(r, i).exists() for r, n in enumerate(sizes) for i in range(n))
        return eps, sum(self.model_path(r).exists() for r in range(len(sizes)))

    def kept(self, sizes: Sequence[int]) -> str:
        """What an interrupted run keeps (:func:`pioneer.interrupt.kept`)."""
        episodes, models = self.on_disk(sizes)
        return (
            f"{episodes} of {sum(sizes)} episodes and {models} of {len(sizes)} rounds "
            f"kept in {self.root}"
        )

    # ------------------------------------------------------------------ settings
    def check(self, settings: Mapping[str, Any]) -> None:
        """Refuse ``settings`` if the run already in the folder was made with other ones
        (reads only; a folder without a run accepts any)."""
        p = self.settings_path
        if not p.exists():
            return
        fix = f"delete {p} if no run of these settings is in the folder, or use a new --out"
        try:
            stored = json.loads(p.read_text())
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise DataError(
                expect(str(p), "the run's settings as JSON", "unreadable", fix)
            ) from exc
        if not isinstance(stored, dict):
            raise DataError(expect(str(p), "a JSON object", type(stored).__name__, fix))
        if self.upgrade is not None:
            try:
                stored = self.upgrade(stored)
            except ConfigError as exc:
                raise DataError(f"{p}: {exc}") from None
        check_settings(str(p), {**self.defaults, **stored}, settings, self.what, self.free)

    def prepare(self, settings: Mapping[str, Any]) -> None:
        """Check ``settings`` (again: the caller holds the folder's lock now), remove what
        killed writes left and record the settings."""
        self.check(settings)
        remove_partial_writes(self.root / "rounds")
        write_text_atomic(self.settings_path, to_json(dict(settings), indent=2) + "\n")
