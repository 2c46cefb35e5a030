"""Plots of the student: DAgger learning curves and the safe/risky uncertainty histograms."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.viz._figure import pyplot, save_figure

__all__ = ["plot_dagger_curves", "plot_uncertainty_histogram"]


def plot_dagger_curves(rows: Sequence[Mapping[str, Any]], path: str | os.PathLike[str]) -> None:
    """Loss (training, and on each round's new frames before training on them) and the success
    rate of the episodes each round collected, against the DAgger round (PNG, atomic)."""
    plt = pyplot()
    rnd = np.array([int(r["round"]) for r in rows])
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.4))
    train = np.array([float(r["train_loss"]) for r in rows])
    new = np.array([float(r["loss_new_data"]) for r in rows])
    ax1.plot(rnd, train, "o-", label="training loss (aggregate)")
    if np.isfinite(new).any():
        ax1.plot(rnd, new, "s--", label="loss on the round's new frames")
    ax1.set_xlabel("DAgger round")
    ax1.set_ylabel("loss (MDN: NLL, MLP: std. MSE)")
    ax1.set_xticks(rnd)
    ax1.legend(fontsize=7)
    ax1.grid(alpha=0.3)
    sr = 100.0 * np.array([float(r["success_rate"]) for r in rows])
    colours = ["tab:gray" if r["driver"] == "teacher" else "tab:blue" for r in rows]
    ax2.bar(rnd, sr, color=colours)
    ax2.set_ylim(0, 105)
    ax2.set_xlabel("round (0: teacher drives; r: the student of round r − 1)")
    ax2.set_ylabel("success of the round's episodes [%]")
    ax2.set_xticks(rnd)
    ax2.grid(alpha=0.3, axis="y")
    save_figure(fig, path, dpi=110)


def plot_uncertainty_histogram(
    groups: Mapping[str, Mapping[str, NDArray[np.floating]]],
    path: str | os.PathLike[str],
    title: str = "",
) -> None:
    """Histograms of aleatoric and epistemic uncertainty of safe vs risky frames.

    ``groups[label][cls]`` holds one uncertainty array per class (``"safe"``, ``"risky"``);
    one panel per label (e.g. ``"hr-rl aleatoric"``), log-scaled x axis.
    """
    plt = pyplot()
    n = len(groups)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.3), squeeze=False)
    for ax, (label, by_cls) in zip(axes[0], groups.items(), strict=True):
        pooled = np.concatenate([np.asarray(v, dtype=float) for v in by_cls.values()])
        pooled = pooled[np.isfinite(pooled) & (pooled > 0)]
        if pooled.size == 0:
            ax.set_title(f"{label}: no data")
            continue
        lo, hi = float(pooled.min()), float(pooled.max())
        bins = np.geomspace(lo, hi * (1 + 1e-9), 40) if hi > lo else 10
        for cls, colour in (("safe", "tab:green"), ("risky", "tab:red")):
            v = np.asarray(by_cls.get(cls, []), dtype=float)
            v = v[np.isfinite(v) & (v > 0)]
            if v.size:
                mean = float(v.mean())
                ax.hist(
                    v,
                    bins=bins,
                    weights=np.full(v.size, 1.0 / v.size),  # share of the class's frames
                    alpha=0.55,
                    color=colour,
                    label=f"{cls} (n={v.size}, mean {mean:.3g})",
                )
        ax.set_xscale("log")
        ax.set_title(label, fontsize=9)
        ax.set_xlabel("uncertainty [(m/s)² + (rad/s)²]")
        ax.set_ylabel("share of the class's frames")
        ax.legend(fontsize=7)
    save_figure(fig, path, title=title, dpi=110)
