"""Raster frames of a world state (Pillow) and GIF animations."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageDraw

from pioneer.errors import DataError, expect
from pioneer.io import atomic_path
from pioneer.sim.humans import ARRIVED, GONE
from pioneer.sim.lidar import beam_angles
from pioneer.sim.world import State, World

__all__ = ["render_frame", "save_gif"]

BG = (250, 250, 247)
WALL = (40, 40, 40)
ROBOT = (31, 119, 180)
GOAL = (44, 160, 44)
HUMAN = (214, 39, 40)
HUMAN_DONE = (230, 150, 150)
RAY = (160, 190, 230)


def render_frame(
    world: World,
    state: State,
    ranges: NDArray[np.float64] | None = None,
    size: int = 480,
    trail: NDArray[np.float64] | None = None,
    index: int = 0,
) -> NDArray[np.uint8]:
    """Draw copy ``index`` of ``state``: walls, door gap, humans (radius and heading), robot,
    goal, optional LiDAR rays ``(G,)`` and robot trail ``(T, 2)``. Returns ``(H, W, 3)`` uint8.
    """
    xmin, xmax, ymin, ymax = world.bounds
    pad = 0.3
    xmin, xmax, ymin, ymax = xmin - pad, xmax + pad, ymin - pad, ymax + pad
    scale = size / max(xmax - xmin, ymax - ymin)
    w = round((xmax - xmin) * scale)
    h = round((ymax - ymin) * scale)
    img = Image.new("RGB", (w, h), BG)
    dr = ImageDraw.Draw(img)

    def px(x: float, y: float) -> tuple[float, float]:
        return ((x - xmin) * scale, (ymax - y) * scale)

    def circle(
        x: float,
        y: float,
        r: float,
        fill: tuple[int, int, int] | None,
        outline: tuple[int, int, int],
    ) -> None:
        cx, cy = px(x, y)
        rr = r * scale
        dr.ellipse([cx - rr, cy - rr, cx + rr, cy + rr], fill=fill, outline=outline, width=2)

    rx, ry, th = state.robot[index]
    if ranges is not None:
        for a, r in zip(beam_angles(len(ranges)), ranges, strict=True):
            dr.line(
                [px(rx, ry), px(rx + r * math.cos(th + a), ry + r * math.sin(th + a))], fill=RAY
            )
    if trail is not None and len(trail) > 1:
        dr.line([px(float(x), float(y)) for x, y in trail], fill=ROBOT, width=2)
    for x1, y1, x2, y2 in world.walls:
        dr.line([px(x1, y1), px(x2, y2)], fill=WALL, width=4)
    gx, gy = state.goal[index]
    circle(gx, gy, world.sim.goal_tolerance, None, GOAL)
    for i in range(state.n_humans):
        status = state.h_status[index, i]
        if status == GONE:
            continue
        hx, hy = state.h_pos[index, i]
        col = HUMAN_DONE if status == ARRIVED else HUMAN
        circle(hx, hy, state.h_radius[index, i], col, (120, 20, 20))
        vx, vy = state.h_vel[index, i]
        sp = math.hypot(vx, vy)
        if sp > 1e-3:
            r = state.h_radius[index, i]
            dr.line([px(hx, hy), px(hx + r * vx / sp, hy + r * vy / sp)], fill=(90, 0, 0), width=2)
    rr = world.sim.robot.radius
    circle(rx, ry, rr, ROBOT, (10, 50, 90))
    dr.line(
        [px(rx, ry), px(rx + rr * math.cos(th), ry + rr * math.sin(th))],
        fill=(255, 255, 255),
        width=3,
    )
    dr.text((6, 4), f"t = {state.t[index]:.1f} s", fill=(0, 0, 0))
    return np.asarray(img, dtype=np.uint8)


def save_gif(
    frames: Sequence[NDArray[np.uint8]], path: str | os.PathLike[str], fps: float = 10.0
) -> None:
    """Write frames ``(H, W, 3)`` as a looping GIF (atomically)."""
    if not frames:
        raise DataError(expect("save_gif frames", "at least one frame", 0, "record the episode"))
    images = [Image.fromarray(f) for f in frames]
    with atomic_path(path) as tmp:
        images[0].save(
            tmp,
            format="GIF",
            save_all=True,
            append_images=images[1:],
            duration=round(1000 / fps),
            loop=0,
            optimize=False,
        )
