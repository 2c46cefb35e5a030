"""The three kinds of episode seeds, named in one place and disjoint by construction.

- **evaluation** (``evaluation_seed``): the episodes every reported result is measured on
  (paper Tables I–IV), derived from (scenario, seed, trial); values in [0, 2³²).
- **validation** (``validation_seed``): every choice and every tuning — the world's free
  parameters (``pioneer calibrate``), thresholds, mode vs mixture mean; values in
  [2³², 2³³), so never an evaluation episode.
- **training** (``training_seed``): demonstrations (and, from the next re-training on,
  DAgger rollouts); values in [2³³, 2³⁴).

Each seed seeds one episode (``env.reset(seed=...)``) and the policy's own generator.
"""

from __future__ import annotations

import zlib

import numpy as np

__all__ = [
    "TRAINING_BASE",
    "VALIDATION_BASE",
    "evaluation_seed",
    "training_seed",
    "validation_seed",
]

VALIDATION_BASE = 2**32  # validation seeds live in [2³², 2³³)
TRAINING_BASE = 2**33  # training seeds live in [2³³, 2³⁴)


def _hash32(*parts: int | str) -> int:
    keys = [zlib.crc32(p.encode()) if isinstance(p, str) else int(p) for p in parts]
    return int(np.random.SeedSequence(keys).generate_state(1, dtype=np.uint32)[0])


def evaluation_seed(scenario: str, seed: int, trial: int) -> int:
    """The environment seed of trial ``trial`` of seed ``seed`` in ``scenario``."""
    return _hash32(scenario, seed, trial)


def validation_seed(purpose: str, scenario: str, k: int) -> int:
    """The ``k``-th validation episode of ``scenario`` for ``purpose`` (e.g. "calibrate")."""
    return VALIDATION_BASE + _hash32("validation", purpose, scenario, k)


def training_seed(offset: int, k: int) -> int:
    """The ``k``-th training episode of a stream starting at ``offset`` (demonstrations use
    ``seed`` for positives and ``seed + 100000`` for negatives)."""
    return TRAINING_BASE + int(offset) + int(k)
