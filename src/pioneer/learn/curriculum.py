"""A curriculum of hard layouts practised to mastery (the fine-tuning's ``replay_mode =
"mastery"``; :mod:`pioneer.learn.finetune`).

Prioritised layouts redraw every group's layout every few updates, so a layout the student
fails is met often but never practised long enough to be learned. Here a small *active set*
of layouts stays in practice until each is mastered:

- the set holds up to ``size`` layouts of the pools that have more than one; a layout joins
  drawn in proportion to its running failure rate (one not yet met counting as failing,
  :attr:`pioneer.learn.layout_env.LayoutEnvs.failure`), from a pool chosen uniformly;
- a layout leaves *mastered* once ``threshold`` of its last ``window`` training episodes
  succeeded (under the exploration noise), or *dropped* after ``limit`` episodes in the set
  without that (a layout even the teacher may not solve must not hold a place for ever);
  either way a new one joins at once, and a layout that has left does not join again;
- with a ``ceiling`` — what a reference policy (the privileged teacher) achieves on each
  layout — the set follows *regret* instead of failure: only layouts whose ceiling reaches
  ``threshold`` (mastery is achievable there) join, each drawn in proportion to how far the
  student's running success falls below the ceiling (the premise of prioritised level
  replay, Jiang et al. 2021, with the teacher as the measure of what is achievable), so no
  practice goes to layouts even the teacher fails;
- :class:`~pioneer.learn.layout_env.LayoutEnvs` draws a group's layout from the set with
  probability ``replay``, otherwise as without a curriculum, so the other layouts — the
  mastered ones among them — stay in the mix.

Its state is JSON (:meth:`Curriculum.state`), saved in the fine-tuning's checkpoint; the
``history`` of layouts that left is reported in ``train.json``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["Curriculum"]


class Curriculum:
    """The active set over ``pools`` (module docstring); draws use the caller's generator.
    ``ceiling``: the reference success (0–1) of every layout of the pools with more than one
    (``None``: follow the failure rate)."""

    def __init__(
        self,
        pools: Sequence[Sequence[str]],
        size: int,
        threshold: float,
        window: int,
        limit: int,
        ceiling: Mapping[str, float] | None = None,
    ) -> None:
        self.ceiling = None if ceiling is None else {str(k): float(v) for k, v in ceiling.items()}
        self.pools = [list(p) for p in pools if len(p) > 1]
        if self.ceiling is not None:
            missing = [n for p in self.pools for n in p if n not in self.ceiling]
            if missing:
                raise ValueError(f"no ceiling for {len(missing)} layouts, e.g. {missing[0]}")
            self.pools = [[n for n in p if self.ceiling[n] >= threshold] for p in self.pools]
        self.size, self.threshold, self.window, self.limit = size, threshold, window, limit
        self.active: list[str] = []
        self.joined: dict[str, int] = {}  # the layout's episode count when it joined
        self.count: dict[str, int] = {}  # training episodes per layout, in the set or not
        self.recent: dict[str, list[int]] = {}  # the last ``window`` outcomes (1: success)
        self.history: list[dict[str, Any]] = []  # the layouts that left, in order

    def fill(self, rng: np.random.Generator, failure: dict[str, float]) -> None:
        """Let layouts join until the set is full or no pool has a candidate left."""
        left = {h["layout"] for h in self.history}
        while len(self.active) < self.size:
            open_ = [[n for n in p if n not in left and n not in self.active] for p in self.pools]
            pools = [c for c in open_ if c]
            if not pools:
                return
            cands = pools[int(rng.integers(len(pools)))]
            w = self._weights(cands, failure) + 1e-3
            name = cands[int(rng.choice(len(cands), p=w / w.sum()))]
            self.active.append(name)
            self.joined[name] = self.count.get(name, 0)

    def _weights(self, names: list[str], failure: dict[str, float]) -> NDArray[np.float64]:
        """Joining weights: the failure rate (one not yet met: 1), or with a ceiling the
        regret ``max(ceiling − (1 − failure), 0)``."""
        fail = np.array([failure.get(n, 1.0) for n in names])
        if self.ceiling is None:
            return fail
        top = np.array([self.ceiling[n] for n in names])
        return np.maximum(top - (1.0 - fail), 0.0)

    def draw(self, rng: np.random.Generator) -> str:
        """A layout of the active set, uniformly (the set must not be empty)."""
        return self.active[int(rng.integers(len(self.active)))]

    def record(
        self,
        name: str,
        success: bool,
        episode: int,
        rng: np.random.Generator,
        failure: dict[str, float],
    ) -> None:
        """Count one finished training episode of ``name``; a layout of the set that is now
        mastered (or has used its ``limit``) leaves it, and the set is filled again.
        ``episode`` is the run's episode count, kept in the history."""
        self.count[name] = self.count.get(name, 0) + 1
        recent = self.recent.setdefault(name, [])
        recent.append(int(success))
        del recent[: -self.window]
        if name not in self.active:
            return
        practised = self.count[name] - self.joined[name]
        mastered = len(recent) == self.window and np.mean(recent) >= self.threshold
        if not mastered and practised < self.limit:
            return
        self.active.remove(name)
        self.history.append(
            {
                "layout": name,
                "outcome": "mastered" if mastered else "dropped",
                "episodes_in_set": practised,
                "left_at_episode": episode,
                "recent_success": float(np.mean(recent)),
                **({"ceiling": self.ceiling[name]} if self.ceiling is not None else {}),
            }
        )
        self.fill(rng, failure)

    def state(self) -> dict[str, Any]:
        """Everything that changes, as JSON."""
        return {
            "active": self.active,
            "joined": self.joined,
            "count": self.count,
            "recent": self.recent,
            "history": self.history,
        }

    def restore(self, state: dict[str, Any]) -> None:
        """The inverse of :meth:`state`."""
        self.active = [str(n) for n in state["active"]]
        self.joined = {str(k): int(v) for k, v in state["joined"].items()}
        self.count = {str(k): int(v) for k, v in state["count"].items()}
        self.recent = {str(k): [int(x) for x in v] for k, v in state["recent"].items()}
        self.history = [dict(h) for h in state["history"]]
