"""Pictures of the social-navigation measures (docs/metrics.md): how close each policy's robot
comes to people over time, and where it drives."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from pioneer.sim.world import World
from pioneer.viz._figure import pyplot, save_figure

__all__ = ["plot_clearance_distribution", "plot_occupancy"]

_ZONE_COLOURS = ("tab:red", "tab:orange", "tab:green", "tab:blue")


def plot_clearance_distribution(
    panels: Mapping[str, Mapping[str, ArrayLike]],
    path: str | os.PathLike[str],
    zones: Sequence[tuple[str, float, float]] = (),
    top: float = 4.0,
    title: str = "",
    contact: float | None = None,
) -> None:
    """Violins of the nearest person's clearance [m] over every step of every episode, one
    violin per policy and one panel per scenario (``panels[scenario][policy]`` = the values;
    infinite ones — nobody there — are left out, values above ``top`` are drawn at ``top``).
    ``zones`` (name, low, high) [m] are shaded behind, e.g. Hall's proxemic zones, and the
    clearance at ``contact`` [m] (the robot's radius: gap 0) is a dashed line. Under each
    name, the share of its steps below the second zone's upper bound. PNG, atomic."""
    plt = pyplot()
    n_pol = max((len(p) for p in panels.values()), default=1)
    fig, axes = plt.subplots(
        len(panels), 1, figsize=(max(6.0, 0.75 * n_pol + 1.5), 3.2 * len(panels)), squeeze=False
    )
    for ax, (scenario, by_policy) in zip(axes[:, 0], panels.items(), strict=True):
        names, data, shares = [], [], []
        for name, values in by_policy.items():
            v = np.asarray(values, dtype=np.float64)
            v = v[np.isfinite(v)]
            if v.size:
                names.append(name)
                data.append(np.minimum(v, top))
                shares.append(float(np.mean(v < zones[1][2])) if len(zones) > 1 else math.nan)
        for k, (zone, lo, hi) in enumerate(zones):
            ax.axhspan(lo, min(hi, top), color=_ZONE_COLOURS[k % 4], alpha=0.08, lw=0)
            ax.text(0.52, (lo + min(hi, top)) / 2, zone, fontsize=7, va="center", alpha=0.7)
        if contact is not None:
            ax.axhline(contact, color="tab:red", lw=0.8, ls="--")
            ax.text(len(names) + 0.55, contact, "contact", fontsize=7, va="bottom", ha="right")
        if data:
            parts = ax.violinplot(data, showmedians=True, widths=0.8)
            for body in parts["bodies"]:
                body.set_alpha(0.55)
            ax.set_xticks(np.arange(1, len(names) + 1))
            labels = [
                f"{n}\n{100 * s:.0f}% < {zones[1][2]:g} m" if math.isfinite(s) else n
                for n, s in zip(names, shares, strict=True)
            ]
            ax.set_xticklabels(labels, rotation=30, ha="right", fontsize=7)
        else:
            ax.text(0.5, 0.5, "no per-step series in these records", transform=ax.transAxes)
        ax.set_xlim(0.4, max(len(names), 1) + 0.6)
        ax.set_ylim(min([0.0, *(float(d.min()) for d in data)]) - 0.05, top + 0.1)
        ax.set_ylabel("nearest person: clearance [m]")
        ax.set_title(scenario, fontsize=9)
        ax.grid(alpha=0.3, axis="y")
    save_figure(fig, path, title=title, dpi=110)


def plot_occupancy(
    world: World,
    positions: Mapping[str, ArrayLike],
    path: str | os.PathLike[str],
    cell: float = 0.1,
    columns: int = 4,
    title: str = "",
) -> None:
    """Heat maps of where each policy's robot drives: the share of all its steps spent in
    each ``cell`` × ``cell`` square [m] (``positions[policy]`` = robot x, y of every step of
    every episode, shape ``(K, 2)``), log colour scale shared by the panels, walls drawn. PNG,
    atomic."""
    plt = pyplot()
    from matplotlib.colors import LogNorm

    xmin, xmax, ymin, ymax = (float(b) for b in world.bounds)
    pad = 0.3
    xe = np.arange(xmin - pad, xmax + pad + cell, cell)
    ye = np.arange(ymin - pad, ymax + pad + cell, cell)
    grids: dict[str, np.ndarray] = {}
    for name, xy in positions.items():
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if p.shape[0]:
            h, _, _ = np.histogram2d(p[:, 0], p[:, 1], bins=(xe, ye))
            grids[name] = h.T / p.shape[0]
    n = max(len(grids), 1)
    cols = min(columns, n)
    rows = math.ceil(n / cols)
    aspect = (ye[-1] - ye[0]) / (xe[-1] - xe[0])
    fig, axes = plt.subplots(
        rows,
        cols,
        figsize=(2.2 * cols + 1.0, 2.2 * rows * aspect + 0.5),
        squeeze=False,
        layout="constrained",
    )
    peak = max((float(g.max()) for g in grids.values()), default=1.0)
    norm = LogNorm(vmin=max(peak * 1e-3, 1e-6), vmax=max(peak, 2e-6))
    image = None
    for k, ax in enumerate(axes.ravel()):
        if k >= len(grids):
            ax.axis("off")
            continue
        name, g = list(grids.items())[k]
        image = ax.imshow(
            np.where(g > 0, g, np.nan),
            origin="lower",
            extent=(xe[0], xe[-1], ye[0], ye[-1]),
            norm=norm,
            cmap="magma_r",
            interpolation="nearest",
        )
        for x1, y1, x2, y2 in world.walls:
            ax.plot([x1, x2], [y1, y2], color="k", lw=2)
        ax.set_title(name, fontsize=8)
        ax.set_aspect("equal")
        ax.tick_params(labelsize=6)
    if image is not None:
        bar = fig.colorbar(image, ax=axes.ravel().tolist(), shrink=0.6, aspect=30)
        bar.set_label(f"share of the policy's steps per {100 * cell:.0f} cm cell", fontsize=8)
    save_figure(fig, path, title=title, dpi=110, tight=False)  # constrained layout
