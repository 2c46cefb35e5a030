"""Fitting a student (:mod:`pioneer.learn.models`) to labelled frames: Adam on mini-batches,
seeded, with the output standardisation fitted on the data (paper §V-B.2's batch and rate)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import torch
from numpy.typing import NDArray

from pioneer.errors import ConfigError, DataError, expect
from pioneer.learn.models import ACTION_DIM, Student

__all__ = ["TRAIN_BATCH", "TRAIN_LR", "train_student"]

TRAIN_BATCH = 256  # frames per Adam step (paper §V-B.2)
TRAIN_LR = 1e-3  # Adam learning rate (paper §V-B.2)


def _as_tensor(x: NDArray[np.floating] | torch.Tensor, name: str, cols: int) -> torch.Tensor:
    t = torch.as_tensor(np.asarray(x, dtype=np.float32) if not torch.is_tensor(x) else x)
    t = t.to(torch.float32)
    if t.ndim != 2 or t.shape[1] != cols or t.shape[0] < 1:
        raise DataError(expect(name, f"shape (N >= 1, {cols})", tuple(t.shape), "fix the data"))
    if not bool(torch.isfinite(t).all()):
        raise DataError(expect(name, "finite values", "NaN or inf", "drop or fix those rows"))
    return t


def _as_targets(
    targets: tuple[NDArray[np.floating], NDArray[np.floating]], n: int
) -> tuple[torch.Tensor, torch.Tensor]:
    commands = torch.as_tensor(np.asarray(targets[0], dtype=np.float32))
    weights = torch.as_tensor(np.asarray(targets[1], dtype=np.float32))
    k = weights.shape[-1] if weights.ndim == 2 else -1
    if commands.shape != (n, k, ACTION_DIM) or weights.shape != (n, k):
        got = (tuple(commands.shape), tuple(weights.shape))
        raise DataError(expect("targets", f"shapes ({n}, k, 2) and ({n}, k)", got, "align them"))
    ok = torch.isfinite(commands).all() and torch.isfinite(weights).all()
    if not bool(ok) or bool((weights < 0).any()):
        raise DataError(expect("targets", "finite commands, weights >= 0", "other", "fix them"))
    return commands, weights


def train_student(
    model: Student,
    obs: NDArray[np.floating] | torch.Tensor,
    actions: NDArray[np.floating] | torch.Tensor,
    epochs: int = 50,
    batch: int = TRAIN_BATCH,
    lr: float = TRAIN_LR,
    seed: int = 0,
    progress: Callable[[int, float], None] | None = None,
    fit_normalizer: bool = True,
    targets: tuple[NDArray[np.floating], NDArray[np.floating]] | None = None,
) -> list[float]:
    """Fit ``model`` to ``(obs (N, input_dim), actions (N, 2))`` with Adam; returns the mean
    training loss of each epoch (NLL [nats] for the MDN, standardised MSE for the MLP).

    ``targets`` = ``(commands (N, k, 2), weights (N, k))`` trains on weighted targets instead
    (:meth:`Student.target_loss`: the teacher's scores distilled); ``actions`` still set the
    output standardisation.

    ``fit_normalizer`` first sets the standardisation buffers from this data (DAgger retrains
    on the aggregated set each round, so the scales follow the data). Mini-batches are drawn
    without replacement from a ``torch.Generator`` seeded by ``seed``; dropout runs under a
    forked torch RNG seeded by ``seed``, so the same call gives the same weights and the
    caller's RNG state is left untouched. ``progress(epoch, loss)`` is called after each epoch.
    The model is left in eval mode (dropout off).
    """
    x = _as_tensor(obs, "obs", model.config.input_dim)
    y = _as_tensor(actions, "actions", ACTION_DIM)
    if x.shape[0] != y.shape[0]:
        raise DataError(
            expect("obs/actions", "the same number of rows", (x.shape[0], y.shape[0]), "align")
        )
    for name, value in (("epochs", epochs), ("batch", batch)):
        if not (isinstance(value, int) and value >= 1):
            raise ConfigError(expect(name, "an integer >= 1", value, f"set {name} >= 1"))
    if not (math.isfinite(lr) and lr > 0):
        raise ConfigError(expect("lr", "a finite number > 0", lr, f"use {TRAIN_LR:g}"))
    target = None if targets is None else _as_targets(targets, x.shape[0])
    if fit_normalizer:
        model.set_normalizer(x, y)
    n = x.shape[0]
    gen = torch.Generator().manual_seed(int(seed))
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    history: list[float] = []
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(seed))
        model.train()
        try:
            for epoch in range(epochs):
                perm = torch.randperm(n, generator=gen)
                total = 0.0
                for start in range(0, n, batch):
                    idx = perm[start : start + batch]
                    if target is None:
                        loss = model.loss(x[idx], y[idx])
                    else:
                        loss = model.target_loss(x[idx], target[0][idx], target[1][idx])
                    opt.zero_grad(set_to_none=True)
                    loss.backward()
                    opt.step()
                    total += float(loss.detach()) * idx.shape[0]
                history.append(total / n)
                if not math.isfinite(history[-1]):
                    raise DataError(
                        expect("training loss", "finite", history[-1], "check the data scales")
                    )
                if progress is not None:
                    progress(epoch, history[-1])
        finally:
            model.eval()
    return history
