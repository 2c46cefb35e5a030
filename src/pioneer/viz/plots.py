"""Static plots (matplotlib, Agg backend): trajectories of an episode, learning curves."""

from __future__ import annotations

import os
from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike

from pioneer.sim.humans import GONE
from pioneer.sim.world import State, World
from pioneer.viz._figure import pyplot, save_figure

__all__ = ["plot_learning_curve", "plot_trajectory"]


def plot_trajectory(
    world: World, states: list[State], path: str | os.PathLike[str], title: str = ""
) -> None:
    """Plot the robot's and the humans' paths of one episode into a PNG (atomically)."""
    plt = pyplot()
    robot = np.stack([s.robot[0] for s in states])
    humans = np.stack([s.h_pos[0] for s in states])
    present = np.stack([s.h_status[0] != GONE for s in states])
    fig, ax = plt.subplots(figsize=(5, 5), dpi=120)
    for x1, y1, x2, y2 in world.walls:
        ax.plot([x1, x2], [y1, y2], color="k", lw=3)
    for i in range(humans.shape[1]):
        pts = humans[present[:, i], i]
        if len(pts):
            ax.plot(pts[:, 0], pts[:, 1], color="tab:red", lw=1.5, alpha=0.8)
            ax.add_patch(plt.Circle(pts[-1], states[0].h_radius[0, i], color="tab:red", alpha=0.25))
            ax.plot(*pts[0], "o", color="tab:red", ms=4)
    ax.plot(robot[:, 0], robot[:, 1], color="tab:blue", lw=2, label="robot")
    ax.add_patch(plt.Circle(robot[-1, :2], world.sim.robot.radius, color="tab:blue", alpha=0.4))
    g = states[0].goal[0]
    ax.add_patch(plt.Circle(g, world.sim.goal_tolerance, fill=False, color="tab:green", lw=2))
    xmin, xmax, ymin, ymax = world.bounds
    ax.set_xlim(xmin - 0.3, xmax + 0.3)
    ax.set_ylim(ymin - 0.3, ymax + 0.3)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title)
    save_figure(fig, path)


def plot_learning_curve(
    curve: Mapping[str, ArrayLike], path: str | os.PathLike[str], title: str = ""
) -> None:
    """Plot an RL learning curve into a PNG (atomically).

    ``curve`` maps column names to equal-length arrays: ``env_steps`` (x axis) and
    ``mean_return``; optional ``success_rate``, ``collision_rate``, ``timeout_rate`` (fractions
    in [0, 1]) go to a second panel. NaN entries (no finished episode yet) are skipped.
    """
    plt = pyplot()
    x = np.asarray(curve["env_steps"], dtype=np.float64)
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(6, 5), dpi=120, sharex=True)
    ax1.plot(x, np.asarray(curve["mean_return"], dtype=np.float64), color="tab:blue")
    ax1.set_ylabel("mean episode return")
    ax1.grid(alpha=0.3)
    colors = {"success_rate": "tab:green", "collision_rate": "tab:red", "timeout_rate": "tab:gray"}
    for key, color in colors.items():
        if key in curve:
            y = 100.0 * np.asarray(curve[key], dtype=np.float64)
            ax2.plot(x, y, color=color, label=key.removesuffix("_rate"))
    ax2.set_ylabel("episodes (%)")
    ax2.set_ylim(-2, 102)
    ax2.set_xlabel("environment steps")
    ax2.legend(loc="best", fontsize=8)
    ax2.grid(alpha=0.3)
    if title:
        ax1.set_title(title)
    save_figure(fig, path)
