"""CrowdNav++ graph observation from the privileged state, and the action → command map
(formulation in :mod:`pioneer.baselines.crowdnav`)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch
from numpy.typing import NDArray

from pioneer.baselines.crowdnav.network import CrowdNavConfig
from pioneer.sim.humans import GONE
from pioneer.sim.robot import RobotConfig
from pioneer.sim.world import State, World

__all__ = ["CrowdNavObs", "build_observation", "command_from_action", "obs_tensors"]

F32 = NDArray[np.float32]


# ------------------------------------------------------------------------------ observation
class CrowdNavObs(NamedTuple):
    """One graph observation per world copy (float32; see the module docstring)."""

    robot: F32  # (B, 8) robot node
    temporal: F32  # (B, 2) temporal edge [v, ω]
    spatial: F32  # (B, N_max, 2(K + 1)) robot-relative current + predicted human positions [m]
    mask: NDArray[np.bool_]  # (B, N_max) True: a detected human in this slot


def build_observation(state: State, world: World, config: CrowdNavConfig) -> CrowdNavObs:
    """The CrowdNav++ graph observation of every copy of ``state`` (privileged, ground truth)."""
    cfg = config
    b = state.batch_size
    rob = world.sim.robot
    p = state.robot[:, :2]
    th = state.robot[:, 2]
    goal_off = state.goal - p
    robot = np.stack(
        [
            p[:, 0],
            p[:, 1],
            np.full(b, rob.radius),
            goal_off[:, 0],
            goal_off[:, 1],
            np.full(b, rob.v_max),
            np.cos(th),
            np.sin(th),
        ],
        axis=-1,
    )
    n = state.n_humans
    m = cfg.max_humans
    spatial = np.zeros((b, m, cfg.spatial_dim), dtype=np.float32)
    mask = np.zeros((b, m), dtype=np.bool_)
    if n:
        ks = np.arange(cfg.n_pred + 1) * cfg.pred_dt  # (K+1,) [s]
        traj = state.h_pos[:, :, None, :] + state.h_vel[:, :, None, :] * ks[None, None, :, None]
        rel = (traj - p[:, None, None, :]).reshape(b, n, -1)  # (B, N, 2(K+1))
        dist = np.hypot(rel[:, :, 0], rel[:, :, 1])
        seen = (state.h_status != GONE) & (dist <= cfg.sensor_range)
        order = np.argsort(np.where(seen, dist, np.inf), axis=1, kind="stable")[:, :m]
        k = order.shape[1]
        seen_k = np.take_along_axis(seen, order, axis=1)
        edges = np.take_along_axis(rel, order[:, :, None], axis=1)
        spatial[:, :k] = np.where(seen_k[:, :, None], edges, 0.0)
        mask[:, :k] = seen_k
    return CrowdNavObs(robot.astype(np.float32), state.command.astype(np.float32), spatial, mask)


def command_from_action(
    action: NDArray[np.floating],
    v_prev: NDArray[np.floating],
    robot: RobotConfig,
    dt: float,
    config: CrowdNavConfig,
) -> NDArray[np.float64]:
    """Absolute commands ``(B, 2)`` (v [m/s], ω [rad/s]) from raw actions ``(B, 2)``.

    a is clipped to [−1, 1]² and scaled piecewise-linearly onto Δv ∈ ``dv_range``,
    Δθ ∈ ``dtheta_range``; v = clip(v_prev + Δv, v_min, v_max), ω = clip(Δθ/Δt, ±ω_max).
    """
    a = np.clip(np.asarray(action, dtype=np.float64).reshape(-1, 2), -1.0, 1.0)
    lo = np.array([config.dv_range[0], config.dtheta_range[0]])
    hi = np.array([config.dv_range[1], config.dtheta_range[1]])
    inc = np.where(a >= 0.0, a * hi, -a * lo)
    v = np.clip(np.asarray(v_prev, dtype=np.float64) + inc[:, 0], robot.v_min, robot.v_max)
    w = np.clip(inc[:, 1] / dt, -robot.omega_max, robot.omega_max)
    return np.stack([v, w], axis=-1)


def obs_tensors(obs: CrowdNavObs) -> tuple[torch.Tensor, ...]:
    """The four observation arrays as tensors (no copy)."""
    return tuple(torch.from_numpy(np.ascontiguousarray(x)) for x in obs)
