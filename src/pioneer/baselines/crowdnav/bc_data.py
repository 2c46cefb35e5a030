"""The imitation data of CrowdNav++'s warm start (:mod:`pioneer.baselines.crowdnav.imitation`):
teacher-labelled episodes, stored one ``.npz`` each (:mod:`pioneer.imitation.store`), and
their aggregate :class:`BCData`."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.sim.events import Event

__all__ = ["STEP_KEYS", "BCData"]

# The per-step arrays of an episode file and of BCData; an episode file also holds its
# ``event`` ("success", "collision", "timeout"), ``env_seed`` and ``round``.
STEP_KEYS = ("robot", "temporal", "spatial", "mask", "action", "teacher_command", "command")


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

    @staticmethod
    def from_episodes(episodes: Sequence[Mapping[str, Any]]) -> BCData:
        """The ``episodes`` (the arrays of their files) one after the other."""
        steps = {k: np.concatenate([e[k] for e in episodes]) for k in STEP_KEYS}
        index = [np.full(len(e["action"]), i, dtype=np.int64) for i, e in enumerate(episodes)]
        return BCData(
            **steps,
            episode=np.concatenate(index),
            ep_seed=np.asarray([int(e["env_seed"]) for e in episodes], dtype=np.int64),
            ep_round=np.asarray([int(e["round"]) for e in episodes], dtype=np.int64),
            ep_event=np.asarray(
                [int(Event[str(e["event"]).upper()]) for e in episodes], dtype=np.int8
            ),
        )

    @property
    def n_episodes(self) -> int:
        """E."""
        return int(self.ep_seed.shape[0])

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
