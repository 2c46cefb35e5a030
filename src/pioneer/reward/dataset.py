"""Demonstration datasets: one self-describing ``.npz`` per dataset, no pickle.

Per sample (row): episode id, step, time [s], observation o ∈ R^29 (paper §III-A), action
(v [m/s], ω [rad/s]), fidelity γ ∈ [−1, 1] (+1 desirable, −1 undesirable), robot pose
(x, y, θ), scenario (index into the metadata's scenario list) and the episode seed. The
metadata (a JSON string inside the npz) holds the format tag, feature names, units, the source,
the command that made the file and free-form notes. Loading validates every field and names the
offending field and row.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.errors import DataError, expect
from pioneer.io import atomic_path, load_npz
from pioneer.laser import OBS_DIM, mirror_observation, wrap_angles
from pioneer.sim.lidar import observation_names

__all__ = ["FORMAT", "OBS_DIM", "UNITS", "Dataset"]

FORMAT = "pioneer.demos/1"
UNITS = {
    "time": "s",
    "obs": "m (ranges r_k, d_i) and rad (angles phi_i, phi_goal)",
    "action": "v [m/s], omega [rad/s]",
    "pose": "x [m], y [m], theta [rad]",
    "gamma": "fidelity in [-1, 1]",
}
_FIELDS: dict[str, tuple[str, tuple[int, ...]]] = {
    # name: (dtype kind, trailing shape)
    "episode": ("i", ()),
    "step": ("i", ()),
    "time": ("f", ()),
    "obs": ("f", (OBS_DIM,)),
    "action": ("f", (2,)),
    "gamma": ("f", ()),
    "pose": ("f", (3,)),
    "scenario": ("i", ()),
    "seed": ("i", ()),
}


def _dtype(field: str) -> type[np.generic]:
    if field == "obs":
        return np.float32
    return np.int64 if _FIELDS[field][0] == "i" else np.float64


@dataclasses.dataclass(frozen=True, eq=False)
class Dataset:
    """A set of demonstration samples (all arrays have N rows)."""

    episode: NDArray[np.int64]
    step: NDArray[np.int64]
    time: NDArray[np.float64]
    obs: NDArray[np.float32]
    action: NDArray[np.float64]
    gamma: NDArray[np.float64]
    pose: NDArray[np.float64]
    scenario: NDArray[np.int64]
    seed: NDArray[np.int64]
    scenarios: tuple[str, ...]
    meta: dict[str, Any] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        _validate(self._arrays(), self.scenarios, "dataset")

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_rows(
        cls, rows: dict[str, Any], scenarios: Sequence[str], meta: dict[str, Any] | None = None
    ) -> Dataset:
        """Build from column arrays (converted to the canonical dtypes, then validated)."""
        missing = sorted(set(_FIELDS) - set(rows))
        if missing:
            raise DataError(
                expect("dataset", f"columns {sorted(_FIELDS)}", f"missing {missing}", "add them")
            )
        cast: dict[str, Any] = {k: np.asarray(rows[k], dtype=_dtype(k)) for k in _FIELDS}
        return cls(**cast, scenarios=tuple(scenarios), meta=dict(meta or {}))

    @staticmethod
    def columns() -> dict[str, list[Any]]:
        """Empty column lists to append rows to, then pass to :meth:`from_rows`."""
        return {k: [] for k in _FIELDS}

    @staticmethod
    def add_frames(
        cols: dict[str, list[Any]],
        frames: Sequence[Mapping[str, Any]],
        gamma: float | Sequence[float],
        episode: int,
        seed: int,
        scenario: int = 0,
    ) -> None:
        """Append recorded frames (dicts with step, time, obs, action, pose) to ``cols``."""
        gammas = [gamma] * len(frames) if isinstance(gamma, int | float) else list(gamma)
        for f, g in zip(frames, gammas, strict=True):
            cols["episode"].append(episode)
            cols["step"].append(f["step"])
            cols["time"].append(f["time"])
            cols["obs"].append(f["obs"])
            cols["action"].append(f["action"])
            cols["gamma"].append(g)
            cols["pose"].append(f["pose"])
            cols["scenario"].append(scenario)
            cols["seed"].append(seed)

    def _arrays(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in _FIELDS}

    def __len__(self) -> int:
        return int(self.gamma.shape[0])

    # ------------------------------------------------------------------ queries
    @property
    def n_positive(self) -> int:
        """Samples with γ > 0."""
        return int(np.sum(self.gamma > 0))

    @property
    def n_negative(self) -> int:
        """Samples with γ < 0."""
        return int(np.sum(self.gamma < 0))

    def one_sided(self) -> str | None:
        """``"no positives"`` or ``"no negatives"`` (or ``"no samples"``) when the dataset
        lacks one side of the density reward's contrast (Eq. 1), else ``None``."""
        if len(self) == 0:
            return "no samples"
        if self.n_positive == 0:
            return "no positives"
        if self.n_negative == 0:
            return "no negatives"
        return None

    def select(self, mask: NDArray[np.bool_]) -> Dataset:
        """The rows where ``mask`` is True (metadata kept)."""
        m = np.asarray(mask, dtype=bool)
        return Dataset(
            **{k: v[m] for k, v in self._arrays().items()},
            scenarios=self.scenarios,
            meta=dict(self.meta),
        )

    def filter(self, min_gamma: float = -1.0, max_gamma: float = 1.0) -> Dataset:
        """Rows with ``min_gamma <= γ <= max_gamma``."""
        return self.select((self.gamma >= min_gamma) & (self.gamma <= max_gamma))

    def with_gamma(self, gamma: NDArray[np.float64]) -> Dataset:
        """The same rows with other fidelities ``γ`` (e.g. graded by quality)."""
        g = np.asarray(gamma, dtype=np.float64)
        if g.shape != self.gamma.shape or not np.all(np.abs(g) <= 1.0):
            raise DataError(
                expect("gamma", f"shape {self.gamma.shape} in [-1, 1]", g.shape, "fix it")
            )
        return dataclasses.replace(self, gamma=g, meta=dict(self.meta))

    def mirrored(self) -> Dataset:
        """Every row as its mirror image (the world mirrored x → −x): the observation by
        :func:`pioneer.laser.mirror_observation` (sector k ↔ (24 − k) mod 24, φ ↔ −φ), the
        command (v, ω) → (v, −ω), the pose (x, y, θ) → (−x, y, π − θ); each scenario name
        gets the suffix ``~mirrored``. HR-RL mirrored is an HL-RR demonstration."""
        pose = self.pose.copy()
        pose[:, 0] = -pose[:, 0]
        pose[:, 2] = wrap_angles(np.pi - self.pose[:, 2])
        action = self.action.copy()
        action[:, 1] = -action[:, 1]
        meta = {**self.meta, "mirrored": True}
        return dataclasses.replace(
            self,
            obs=mirror_observation(self.obs),
            action=action,
            pose=pose,
            scenarios=tuple(f"{s}~mirrored" for s in self.scenarios),
            meta=meta,
        )

    @staticmethod
    def merge(datasets: Sequence[Dataset]) -> Dataset:
        """Concatenate datasets; scenario lists are united and episode ids kept distinct."""
        if not datasets:
            raise DataError(expect("merge", "at least one dataset", 0, "pass datasets"))
        names: list[str] = []
        for d in datasets:
            names += [s for s in d.scenarios if s not in names]
        cols: dict[str, list[NDArray[Any]]] = {k: [] for k in _FIELDS}
        offset = 0
        for d in datasets:
            remap = np.array([names.index(s) for s in d.scenarios], dtype=np.int64)
            for k, v in d._arrays().items():
                if k == "scenario":
                    v = remap[v] if len(remap) else v
                elif k == "episode":
                    v = v + offset
                cols[k].append(v)
            offset = int(max(offset, (d.episode.max() + 1 + offset) if len(d) else offset))
        sources = [d.meta.get("source", "?") for d in datasets]
        meta = {"source": "merge", "parts": sources}
        return Dataset(
            **{k: np.concatenate(v) for k, v in cols.items()}, scenarios=tuple(names), meta=meta
        )

    # ------------------------------------------------------------------ I/O
    def save(self, path: str | Path) -> None:
        """Write the dataset (atomically)."""
        meta = {
            **self.meta,  # free-form first: the computed fields below always win
            "format": FORMAT,
            "feature_names": observation_names(),
            "action_names": ["v", "omega"],
            "units": UNITS,
            "scenarios": list(self.scenarios),
            "n_samples": len(self),
            "n_positive": self.n_positive,
            "n_negative": self.n_negative,
        }
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(fh, **self._arrays(), metadata=np.array(json.dumps(meta)))

    @classmethod
    def load(cls, path: str | Path) -> Dataset:
        """Read and validate a dataset file; errors name the field and row."""
        p = Path(path)
        arrays = load_npz(p, "dataset", "regenerate it; the file is truncated or not a dataset")
        if "metadata" not in arrays:
            raise DataError(expect(f"{p}", "a 'metadata' entry", sorted(arrays), "regenerate"))
        try:
            meta = json.loads(str(arrays.pop("metadata")))
        except json.JSONDecodeError as exc:
            raise DataError(expect(f"{p}: metadata", "JSON", "invalid JSON", "regenerate")) from exc
        if meta.get("format") != FORMAT:
            raise DataError(
                expect(f"{p}: format", FORMAT, meta.get("format"), "regenerate the dataset")
            )
        scenarios = tuple(meta.get("scenarios", ()))
        _validate(arrays, scenarios, str(p))
        extra = {k: v for k, v in meta.items() if k not in ("format", "scenarios")}
        return cls(
            **{k: arrays[k].astype(_dtype(k), copy=False) for k in _FIELDS},
            scenarios=scenarios,
            meta=extra,
        )

    def summary(self) -> dict[str, Any]:
        """Counts per sign and scenario."""
        return {
            "samples": len(self),
            "positive": self.n_positive,
            "negative": self.n_negative,
            "episodes": int(np.unique(self.episode).size),
            "scenarios": {s: int(np.sum(self.scenario == i)) for i, s in enumerate(self.scenarios)},
        }


def _validate(arrays: dict[str, NDArray[Any]], scenarios: tuple[str, ...], where: str) -> None:
    missing = sorted(set(_FIELDS) - set(arrays))
    if missing:
        raise DataError(
            expect(f"{where}", f"fields {sorted(_FIELDS)}", f"missing {missing}", "regenerate")
        )
    n = arrays["gamma"].shape[0] if arrays["gamma"].ndim == 1 else -1
    if n < 1:
        raise DataError(
            expect(
                f"{where}: gamma",
                "at least one sample (N >= 1)",
                arrays["gamma"].shape,
                "record some demonstrations",
            )
        )
    for k, (kind, trail) in _FIELDS.items():
        a = arrays[k]
        if a.shape != (n, *trail):
            raise DataError(
                expect(f"{where}: {k}", f"shape {(n, *trail)}", a.shape, "all columns need N rows")
            )
        if a.dtype.kind not in (kind, "i" if kind == "i" else "f"):
            raise DataError(
                expect(f"{where}: {k}", f"dtype kind '{kind}'", str(a.dtype), "regenerate")
            )
        if kind == "f":
            bad = ~np.isfinite(a.reshape(n, -1)).all(axis=1)
            if bad.any():
                row = int(np.flatnonzero(bad)[0])
                raise DataError(
                    expect(
                        f"{where}: {k}[row {row}]",
                        "finite values",
                        a[row].tolist(),
                        "drop or fix the row",
                    )
                )
    g = arrays["gamma"]
    bad = (g < -1) | (g > 1)
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise DataError(
            expect(
                f"{where}: gamma[row {row}]",
                "a fidelity in [-1, 1]",
                float(g[row]),
                "clip γ to [-1, 1]",
            )
        )
    obs = arrays["obs"]
    angles = obs[:, 26:29]
    bad = (obs[:, :26] < 0).any(axis=1) | (np.abs(angles) > math.pi + 1e-5).any(axis=1)
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise DataError(
            expect(
                f"{where}: obs[row {row}]",
                "ranges >= 0 and angles in [-pi, pi]",
                obs[row].tolist(),
                "recompute the observation",
            )
        )
    sc = arrays["scenario"]
    bad = (sc < 0) | (sc >= len(scenarios))
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise DataError(
            expect(
                f"{where}: scenario[row {row}]",
                f"an index < {len(scenarios)} into {list(scenarios)}",
                int(sc[row]),
                "fix the scenario list",
            )
        )
