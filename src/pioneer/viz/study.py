"""The synthetic static-study figure (paper Fig. 3): reward maps and trajectories."""

from __future__ import annotations

import os

import numpy as np
from numpy.typing import NDArray

from pioneer.sim.world import World
from pioneer.viz._figure import pyplot, save_figure

__all__ = ["plot_static_study"]


def plot_static_study(
    world: World,
    human: NDArray[np.float64],
    human_radius: float,
    maps: list[tuple[str, NDArray[np.float64]]],
    grid_x: NDArray[np.float64],
    grid_y: NDArray[np.float64],
    demos_pos: NDArray[np.float64],
    demos_neg: NDArray[np.float64],
    trajectories: list[NDArray[np.float64]],
    path: str | os.PathLike[str],
) -> None:
    """Three panels of reward maps over (x, y); demos on (a, b), trajectories on (c)."""
    plt = pyplot()
    fig, axes = plt.subplots(1, len(maps), figsize=(4.2 * len(maps), 5.2), dpi=120)
    for k, (ax, (title, z)) in enumerate(zip(np.atleast_1d(axes), maps, strict=True)):
        lim = float(np.max(np.abs(z))) or 1.0
        im = ax.pcolormesh(grid_x, grid_y, z, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="auto")
        fig.colorbar(im, ax=ax, fraction=0.046, pad=0.02)
        for x1, y1, x2, y2 in world.walls:
            ax.plot([x1, x2], [y1, y2], color="k", lw=3)
        ax.add_patch(plt.Circle(human, human_radius, fill=False, color="k", lw=1.5, ls="--"))
        if k < 2:
            ax.scatter(demos_pos[:, 0], demos_pos[:, 1], s=3, c="navy", alpha=0.5, label="positive")
            if k == 1 and len(demos_neg):
                ax.scatter(
                    demos_neg[:, 0], demos_neg[:, 1], s=3, c="crimson", alpha=0.7, label="negative"
                )
            ax.legend(loc="lower right", fontsize=7, markerscale=3)
        else:
            for tr in trajectories:
                ax.plot(tr[:, 0], tr[:, 1], color="k", lw=1.5)
                ax.plot(tr[0, 0], tr[0, 1], "o", color="k", ms=3)
        ax.set_title(title, fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
    np.atleast_1d(axes)[0].set_ylabel("y [m]")
    save_figure(fig, path)
