"""The three kinds of episode seeds, named in one place and disjoint by construction.

- **evaluation** (``evaluation_seed``): the episodes every reported result is measured on
  (paper Tables I–IV), derived from (scenario, seed, trial); values in [0, 2³²).
- **validation** (``validation_seed``): every choice and every tuning — the world's free
  parameters (``pioneer calibrate``), thresholds, mode vs mixture mean, the DAgger round a
  run ships (purpose ``"dagger-select"``); values in
  [2³², 2³³), so never an evaluation episode.
- **training**: demonstrations (``training_seed``: values in [2³³, 2³³ + 2³²)) and DAgger
  rollouts (``dagger_seed``) and the students' fine-tuning episodes (``finetune_seed``), both
  with values in [2³³ + 2³², 2³⁴).

Each seed seeds one episode (``env.reset(seed=...)``) and the policy's own generator.

The evaluation harness runs a *seed set* (:data:`SEED_SETS`): ``"evaluation"`` (the default,
every reported result) or ``"validation"`` (every choice: ``pioneer eval --seed-set
validation``); :func:`episode_seed` maps (scenario, seed, trial) into either.
"""

from __future__ import annotations

import typing
import zlib
from typing import Literal

import numpy as np

__all__ = [
    "DAGGER_BASE",
    "SEED_SETS",
    "TRAINING_BASE",
    "VALIDATION_BASE",
    "SeedSet",
    "dagger_seed",
    "episode_seed",
    "evaluation_seed",
    "finetune_seed",
    "training_seed",
    "validation_seed",
]

VALIDATION_BASE = 2**32  # validation seeds live in [2³², 2³³)
TRAINING_BASE = 2**33  # training seeds live in [2³³, 2³⁴)
DAGGER_BASE = 2**33 + 2**32  # DAgger's hashed half of the training range
SeedSet = Literal["evaluation", "validation"]
SEED_SETS: tuple[str, ...] = typing.get_args(SeedSet)


def _hash32(*parts: int | str) -> int:
    keys = [zlib.crc32(p.encode()) if isinstance(p, str) else int(p) for p in parts]
    return int(np.random.SeedSequence(keys).generate_state(1, dtype=np.uint32)[0])


def evaluation_seed(scenario: str, seed: int, trial: int) -> int:
    """The environment seed of trial ``trial`` of seed ``seed`` in ``scenario``."""
    return _hash32(scenario, seed, trial)


def episode_seed(seed_set: str, scenario: str, seed: int, trial: int) -> int:
    """The environment seed of trial ``trial`` of seed ``seed`` in ``scenario`` for the
    harness: an evaluation seed, or a validation seed (purpose ``"episode"``) that no
    evaluation episode can share."""
    if seed_set == "evaluation":
        return evaluation_seed(scenario, seed, trial)
    if seed_set == "validation":
        return VALIDATION_BASE + _hash32("validation", "episode", scenario, seed, trial)
    raise ValueError(f"seed set {seed_set!r} is not one of {SEED_SETS}")


def validation_seed(purpose: str, scenario: str, k: int) -> int:
    """The ``k``-th validation episode of ``scenario`` for ``purpose`` (e.g. "calibrate")."""
    return VALIDATION_BASE + _hash32("validation", purpose, scenario, k)


def training_seed(offset: int, k: int) -> int:
    """The ``k``-th training episode of a stream starting at ``offset`` (demonstrations use
    ``seed`` for positives and ``seed + 100000`` for negatives)."""
    return TRAINING_BASE + int(offset) + int(k)


def dagger_seed(scenario: str, seed: int, rnd: int, episode: int) -> int:
    """The environment seed of ``episode`` in DAgger round ``rnd`` of a run seeded ``seed``:
    a training seed in [2³³ + 2³², 2³⁴), so never an evaluation, validation or demonstration
    episode."""
    return DAGGER_BASE + _hash32("dagger", scenario, seed, rnd, episode)


def finetune_seed(seed: int, k: int, purpose: str = "episode") -> int:
    """The ``k``-th episode of a students' fine-tuning run seeded ``seed`` (``purpose``
    ``"lidar"``: the LiDAR noise of the group started there): a training seed in DAgger's half
    of the range, [2³³ + 2³², 2³⁴), hashed apart from DAgger's own."""
    return DAGGER_BASE + _hash32("finetune", purpose, seed, k)
