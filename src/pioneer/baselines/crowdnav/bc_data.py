"""The imitation data of CrowdNav++'s warm start: teacher-labelled steps as one ``.npz`` with
JSON metadata (no pickle), and its reader (:mod:`pioneer.baselines.crowdnav.imitation`)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.errors import DataError, expect
from pioneer.io import atomic_path, load_npz
from pioneer.sim.events import Event

__all__ = ["DATA_FORMAT", "BCData", "load_bc_data", "save_bc_data"]

DATA_FORMAT = "pioneer.crowdnav-bc/1"


@dataclasses.dataclass
class BCData:
    """Teacher-labelled steps (S of them) of E episodes, in episode order."""

    robot: NDArray[np.float32]  # (S, 8) observation: robot node
    temporal: NDArray[np.float32]  # (S, 2) observation: temporal edge
    spatial: NDArray[np.float32]  # (S, N, 2(K + 1)) observation: spatial edges
    mask: NDArray[np.bool_]  # (S, N)
    action: NDArray[np.float32]  # (S, 2) the teacher's raw action in [−1, 1]² (the label)
    teacher_command: NDArray[np.float64]  # (S, 2) the teacher's unclipped (v, ω)
    command: NDArray[np.float64]  # (S, 2) the (v, ω) applied at this step
    episode: NDArray[np.int64]  # (S,) episode index 0..E−1
    ep_seed: NDArray[np.int64]  # (E,) seed of the episode's initial state
    ep_round: NDArray[np.int64]  # (E,) 0: teacher-driven, r ≥ 1: DAgger round r
    ep_event: NDArray[np.int8]  # (E,) 1 success, 2 collision, 3 timeout

    def fields(self) -> dict[str, NDArray[Any]]:
        """The arrays by name."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    @property
    def n_episodes(self) -> int:
        """E."""
        return int(self.ep_seed.shape[0])

    def rounds(self, below: int) -> BCData:
        """The episodes of rounds < ``below``."""
        keep_ep = np.flatnonzero(self.ep_round < below)
        remap = np.full(self.n_episodes, -1, dtype=np.int64)
        remap[keep_ep] = np.arange(keep_ep.size)
        rows = remap[self.episode] >= 0
        per_step = {k: v[rows] for k, v in self.fields().items() if not k.startswith("ep_")}
        per_step["episode"] = remap[self.episode[rows]]
        per_ep = {k: v[keep_ep] for k, v in self.fields().items() if k.startswith("ep_")}
        return BCData(**per_step, **per_ep)

    @staticmethod
    def concat(parts: list[BCData]) -> BCData:
        """The episodes of ``parts`` one after the other."""
        out: dict[str, NDArray[Any]] = {}
        offset = 0
        eps = []
        for p in parts:
            eps.append(p.episode + offset)
            offset += p.n_episodes
        for k in parts[0].fields():
            out[k] = np.concatenate([getattr(p, k) for p in parts])
        out["episode"] = np.concatenate(eps)
        return BCData(**out)

    def summary(self) -> dict[str, Any]:
        """Episode outcomes per round and how much the clipping changed the teacher."""
        diff = np.abs(self.teacher_command - self.command)
        out: dict[str, Any] = {"episodes": self.n_episodes, "steps": int(self.episode.size)}
        for r in np.unique(self.ep_round):
            ev = self.ep_event[self.ep_round == r]
            out[f"round{int(r)}"] = {
                "episodes": int(ev.size),
                "success_rate": float(np.mean(ev == Event.SUCCESS)),
                "collision_rate": float(np.mean(ev == Event.COLLISION)),
            }
        t = self.ep_round[self.episode] == 0
        if t.any():
            out["teacher_clipped_fraction"] = float(np.mean(np.any(diff[t] > 1e-9, axis=1)))
            out["teacher_clip_mean_abs"] = [float(x) for x in diff[t].mean(axis=0)]
        return out


def save_bc_data(data: BCData, path: str | Path, meta: dict[str, Any]) -> Path:
    """Write ``data`` to ``.npz`` (atomically) with ``meta`` as JSON text (no pickle)."""
    p = Path(path)
    full = {"format": DATA_FORMAT, **meta}
    with atomic_path(p) as tmp, tmp.open("wb") as fh:
        arrays: dict[str, Any] = {
            "meta": np.array(json.dumps(full, sort_keys=True)),
            **data.fields(),
        }
        np.savez(fh, **arrays)
    return p


def load_bc_data(path: str | Path) -> tuple[BCData, dict[str, Any]]:
    """The dataset and meta written by :func:`save_bc_data`; a bad file raises DataError."""
    fix = "delete it or use a new --out (it is not a CrowdNav++ imitation dataset)"
    raw = load_npz(path, "CrowdNav++ imitation data", fix)
    try:
        meta = json.loads(str(raw.pop("meta")))
        data = BCData(**raw)
    except (KeyError, TypeError, json.JSONDecodeError) as exc:
        raise DataError(expect(f"{path}", "the fields of BCData", sorted(raw), fix)) from exc
    if meta.get("format") != DATA_FORMAT:
        raise DataError(expect(f"{path}: format", DATA_FORMAT, meta.get("format"), fix))
    return data, meta
