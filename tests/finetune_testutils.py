"""Helpers shared by the fine-tuning test modules: a tiny run's settings and a tiny student."""

from __future__ import annotations

from pathlib import Path

import torch

from pioneer.learn.finetune import FinetuneConfig
from pioneer.learn.models import StudentConfig, build_student, save_student

__all__ = ["TINY_FINETUNE", "tiny_student"]

TINY_FINETUNE = FinetuneConfig(
    total_steps=4 * 2 * 2 * 8,  # 4 updates
    groups=2,
    group_size=2,
    rollout=8,
    layout_period=2,
    epochs=2,
    minibatches=2,
    critic_warmup=1,
    critic_hidden=(16,),
    checkpoint_every=1,
)


def tiny_student(tmp_path: Path, seed: int, normalizer_seed: int, symmetric: bool = False) -> Path:
    """A 16-wide MDN student of o_{t−1} and u_{t−1}, its normaliser fitted to random rows,
    saved as ``tmp_path/start.safetensors`` with a DAgger record."""
    cfg = StudentConfig(
        hidden=(16,), previous_observation=True, previous_command=True, symmetric=symmetric
    )
    model = build_student(cfg, seed=seed)
    gen = torch.Generator().manual_seed(normalizer_seed)
    model.set_normalizer(
        torch.randn(64, cfg.input_dim, generator=gen), torch.rand(64, 2, generator=gen)
    )
    return save_student(model, tmp_path / "start.safetensors", {"dagger": {"seed": 7}})
