"""Classical reference controllers (docs/baselines.md).

- ``goal``: drive straight at the goal, ignoring people (observation only);
- ``dwa``: the dynamic window approach (Fox et al. 1997) on the privileged state;
- ``sfm``: the robot driven by the social-force model the simulated humans obey.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Annotated, Any

import numpy as np
from annotated_types import Ge
from numpy.typing import NDArray

from pioneer.bounds import NonNegative, Positive
from pioneer.config import default
from pioneer.envs.policy import Decision
from pioneer.errors import ConfigError, expect
from pioneer.limits import OMEGA_MAX, V_MAX
from pioneer.sim.humans import GONE
from pioneer.sim.world import State, World

__all__ = ["DWAPolicy", "GoalPolicy", "SocialForceRobotPolicy"]


class GoalPolicy:
    """Pure go-to-goal: turn toward the goal bearing φ_g, drive when roughly facing it.

    ω = clip(k_ω φ_g, ±ω_max);  v = v_max · max(0, cos φ_g) · min(1, d_goal / d_slow).
    Uses only the observation's goal bearing and the goal distance from ``info``.
    """

    name = "goal"

    def __init__(
        self,
        v_max: Positive = V_MAX,
        omega_max: Positive = OMEGA_MAX,
        k_omega: Positive = 1.5,
        slow_distance: NonNegative = 0.5,
    ) -> None:
        self.v_max = v_max  # [m/s]
        self.omega_max = omega_max  # [rad/s]
        self.k_omega = k_omega  # [1/s]
        self.slow_distance = slow_distance  # [m]

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Stateless: nothing to reset."""

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """Command toward the goal."""
        bearing = float(obs[-1])
        d_goal = float(
            np.linalg.norm(np.asarray(info["goal"]) - np.asarray(info["robot_pose"])[:2])
        )
        w = float(np.clip(self.k_omega * bearing, -self.omega_max, self.omega_max))
        v = self.v_max * max(0.0, math.cos(bearing)) * min(1.0, d_goal / self.slow_distance)
        return np.array([v, w])


# --------------------------------------------------------------------------------------------
# Shared helpers (privileged state, B = 1)


def _wall_closest(p: NDArray[np.float64], walls: NDArray[np.float64]) -> NDArray[np.float64]:
    """Closest points ``(..., M, 2)`` on every wall ``(M, 4)`` to points ``p (..., 2)``."""
    a = walls[:, :2]
    e = walls[:, 2:] - a
    ll = np.maximum((e * e).sum(-1), 1e-300)
    s = np.clip(((p[..., None, :] - a) * e).sum(-1) / ll, 0.0, 1.0)
    return a + s[..., None] * e


def _heading_command(
    v_des: NDArray[np.float64], theta: float, k_omega: float, v_max: float, omega_max: float
) -> NDArray[np.float64]:
    """A desired planar velocity ``(2,)`` → unicycle (v, ω) by heading control.

    φ = wrap(angle(v_des) − θ);  ω = clip(k_ω φ, ±ω_max);  v = min(‖v_des‖, v_max)·max(0, cos φ).
    """
    speed = float(np.hypot(v_des[0], v_des[1]))
    if speed < 1e-9:
        return np.zeros(2)
    phi = math.remainder(math.atan2(v_des[1], v_des[0]) - theta, 2.0 * math.pi)
    w = float(np.clip(k_omega * phi, -omega_max, omega_max))
    return np.array([min(speed, v_max) * max(0.0, math.cos(phi)), w])


# --------------------------------------------------------------------------------------------
# Dynamic window approach


class DWAPolicy:
    """Dynamic window approach (Fox, Burgard & Thrun 1997), privileged (``dwa``).

    Every 0.1 s: the window is the set of commands reachable within one period from the last
    applied command u_{k−1} under the acceleration limits, v ∈ [v − a_v Δt, v + a_v Δt] ∩
    [0, v_max] and ω ∈ [ω − a_ω Δt, ω + a_ω Δt] ∩ [−ω_max, ω_max], sampled on an
    ``n_v × n_omega`` grid. Each command is held ``horizon`` seconds (exact unicycle arcs at
    ``sim_dt``) against the humans — frozen at their current positions (classic DWA) or moving
    at constant velocity (``human_model="constant_velocity"``) — and the walls. A command is
    admissible if its arc stays clear, or if the robot can still brake before the first contact
    (Fox et al.'s v ≤ √(2 a_v s_c) in its discrete form: the distance covered while braking in
    0.1 s steps is at most s_c, the arc length to the last clear pose). Among admissible commands

        G(v, ω) = α heading + β clearance + γ velocity
        heading = 1 − |φ_g(x_T)| / π   (goal bearing at the end pose; 1 if the arc reaches the goal)
        clearance = min(d_min, d_cap) / d_cap   (smallest body clearance along the arc)
        velocity = v / v_max

    is maximised. With none admissible the robot brakes as hard as the window allows and
    turns toward the goal.
    """

    name = "dwa"

    def __init__(
        self,
        accel_v: Positive = 0.5,
        accel_omega: Positive = 1.5,
        n_v: Annotated[int, Ge(2)] = 7,
        n_omega: Annotated[int, Ge(2)] = 15,
        horizon: Positive = 2.0,
        sim_dt: Positive = 0.1,
        w_heading: NonNegative = 1.0,
        w_clearance: NonNegative = 0.4,
        w_velocity: NonNegative = 1.0,
        clearance_cap: Positive = 1.0,
        safety_margin: NonNegative = 0.02,
        human_model: str = "static",
        k_omega: Positive = 1.5,
    ) -> None:
        if human_model not in ("static", "constant_velocity"):
            raise ConfigError(
                expect("DWAPolicy.human_model", "'static' or 'constant_velocity'", human_model, "")
            )
        if n_v < 2 or n_omega < 2:
            fix = f"use {default(DWAPolicy, 'n_v')}, {default(DWAPolicy, 'n_omega')}"
            raise ConfigError(expect("DWAPolicy.n_v/n_omega", ">= 2", (n_v, n_omega), fix))
        self.accel_v = accel_v  # [m/s²]
        self.accel_omega = accel_omega  # [rad/s²]
        self.n_v = n_v
        self.n_omega = n_omega
        self.horizon = horizon  # [s]
        self.sim_dt = sim_dt  # [s] prediction step
        self.w_heading = w_heading
        self.w_clearance = w_clearance
        self.w_velocity = w_velocity
        self.clearance_cap = clearance_cap  # [m]
        self.safety_margin = safety_margin  # [m] a predicted clearance below this is contact
        self.human_model = human_model
        self.k_omega = k_omega  # [1/s] heading gain of the no-admissible-command brake

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Stateless (the current velocity is the state's last command)."""

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """The best admissible command in the dynamic window."""
        return self.decide(info["world"], info["state"]).command

    def window(self, world: World, state: State) -> NDArray[np.float64]:
        """The sampled dynamic window, ``(n_v · n_omega, 2)`` commands."""
        rob = world.sim.robot
        dt = world.sim.dt
        v0, w0 = state.command[0]
        v = np.linspace(
            max(rob.v_min, v0 - self.accel_v * dt), min(rob.v_max, v0 + self.accel_v * dt), self.n_v
        )
        w = np.linspace(
            max(-rob.omega_max, w0 - self.accel_omega * dt),
            min(rob.omega_max, w0 + self.accel_omega * dt),
            self.n_omega,
        )
        vv, ww = np.meshgrid(v, w, indexing="ij")
        return np.stack([vv.ravel(), ww.ravel()], axis=1)

    def predict(self, pose: NDArray[np.float64], cmds: NDArray[np.float64]) -> NDArray[np.float64]:
        """Poses ``(C, K, 3)`` of every command held for the horizon (exact arcs)."""
        k = max(1, round(self.horizon / self.sim_dt))
        h = self.sim_dt
        v, w = cmds[:, 0:1], cmds[:, 1:2]
        t = h * np.arange(k + 1)[None, :]  # (1, K+1)
        th = pose[2] + w * t  # headings at the step boundaries
        half = 0.5 * w * h
        sinc = np.where(np.abs(half) > 1e-6, np.sin(half) / np.where(half == 0, 1, half), 1.0)
        chord = v * h * sinc  # (C, 1)
        mid = th[:, :-1] + half
        x = pose[0] + np.cumsum(chord * np.cos(mid), axis=1)
        y = pose[1] + np.cumsum(chord * np.sin(mid), axis=1)
        return np.stack([x, y, th[:, 1:]], axis=-1)

    def braking_distance(self, v: NDArray[np.float64], dt: float) -> NDArray[np.float64]:
        """Distance [m] covered from speed ``v`` when braking at ``accel_v`` in steps of ``dt``
        (v is held for the first step): the discrete form of Fox et al.'s v²/(2 a)."""
        dv = self.accel_v * dt
        n = np.ceil(v / dv - 1e-9)
        return dt * (n * v - dv * n * (n - 1) / 2.0)

    def decide(
        self, world: World, state: State, prev: NDArray[np.float64] | None = None
    ) -> Decision:
        """Score the window from ``state`` (B = 1); the current velocity is the state's last
        command (``prev`` is not used)."""
        rob = world.sim.robot
        r_r = rob.radius
        cmds = self.window(world, state)
        poses = self.predict(state.robot[0], cmds)  # (C, K, 3)
        p = poses[..., :2]
        k = p.shape[1]
        clear = np.full(p.shape[:2], np.inf)
        present = state.h_status[0] != GONE
        if present.any():
            hp = state.h_pos[0, present]  # (N, 2)
            if self.human_model == "constant_velocity":
                t = self.sim_dt * np.arange(1, k + 1)
                hp = hp[None, :, :] + t[:, None, None] * state.h_vel[0, present][None]  # (K, N, 2)
            d = np.linalg.norm(p[:, :, None, :] - hp, axis=-1) - r_r - state.h_radius[0, present]
            clear = d.min(axis=-1)
        if world.walls.shape[0]:
            dw = np.linalg.norm(p[..., None, :] - _wall_closest(p, world.walls), axis=-1) - r_r
            clear = np.minimum(clear, dw.min(axis=-1))
        hit = clear < self.safety_margin  # (C, K)
        first = np.where(hit.any(axis=1), hit.argmax(axis=1), k)
        s_c = cmds[:, 0] * self.sim_dt * first  # arc length to the last clear pose [m]
        admissible = ~hit.any(axis=1) | (self.braking_distance(cmds[:, 0], world.sim.dt) <= s_c)
        admissible &= ~hit[:, 0]  # never a command that touches within the first step
        d_min = clear.min(axis=1)
        goal = state.goal[0]
        to_goal = goal - p[:, -1]
        phi = np.angle(np.exp(1j * (np.arctan2(to_goal[:, 1], to_goal[:, 0]) - poses[:, -1, 2])))
        heading = 1.0 - np.abs(phi) / math.pi
        reach = (np.linalg.norm(p - goal, axis=-1) < world.sim.goal_tolerance).any(axis=1)
        heading = np.where(reach, 1.0, heading)
        score = (
            self.w_heading * heading
            + self.w_clearance * np.clip(d_min, 0.0, self.clearance_cap) / self.clearance_cap
            + self.w_velocity * cmds[:, 0] / rob.v_max
        )
        if not admissible.any():
            v0, w0 = state.command[0]
            x, y, th = state.robot[0]
            phi_g = math.remainder(math.atan2(goal[1] - y, goal[0] - x) - th, 2.0 * math.pi)
            w_lim = self.accel_omega * world.sim.dt
            w = float(np.clip(self.k_omega * phi_g, w0 - w_lim, w0 + w_lim))
            v = max(rob.v_min, v0 - self.accel_v * world.sim.dt)
            return Decision(np.array([v, float(np.clip(w, -rob.omega_max, rob.omega_max))]))
        return Decision(cmds[int(np.argmax(np.where(admissible, score, -np.inf)))].copy())


# --------------------------------------------------------------------------------------------
# Social-force robot


class SocialForceRobotPolicy:
    """The robot driven by the social-force model of :mod:`pioneer.sim.humans` (``sfm``).

        f = (v_pref e_g − v_r) / τ
            + Σ_h A exp((r_r + r_h − d_rh) / B) n_hr          (every present human)
            + Σ_w A_w exp((r_r − d_rw) / B_w) n_wr            (closest point of every wall)

    with v_r = v (cos θ, sin θ) the robot's current velocity (last command) and n the unit
    vector pointing from the other body to the robot. The desired velocity v_d = v_r + f Δt
    (speed capped at v_max) becomes a unicycle command by heading control:
    φ = wrap(angle(v_d) − θ), ω = clip(k_ω φ, ±ω_max), v = ‖v_d‖ max(0, cos φ).

    Parameters left ``None`` take the world's social-force preset (A = a_human, B = b_human for
    humans — how people avoid each other, not how they react to the robot; a_wall for walls;
    τ), so the robot obeys the same model as the people. One
    exception: the wall range defaults to B_w = 0.5 m (the preset's B) rather than the humans'
    0.2 m, because simulated humans also have hard walls (projection) and the robot does not —
    with 0.2 m the robot grazed a door jamb or cabin wall in about half of the elevator
    episodes (11/20 HR-RL seeds); with 0.5 m it reached the goal in 20/20.
    """

    name = "sfm"

    def __init__(
        self,
        v_pref: Positive = 0.8,
        tau: Positive | None = None,
        a_human: NonNegative | None = None,
        b_human: Positive | None = None,
        a_wall: NonNegative | None = None,
        b_wall: Positive | None = 0.5,
        k_omega: Positive = 1.5,
    ) -> None:
        self.v_pref = v_pref  # [m/s]
        self.tau = tau  # [s]
        self.a_human = a_human  # [m/s²]
        self.b_human = b_human  # [m]
        self.a_wall = a_wall  # [m/s²]
        self.b_wall = b_wall  # [m]
        self.k_omega = k_omega  # [1/s]
        self.slow_distance = 0.5  # [m] the driving speed falls linearly inside this goal distance

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Stateless."""

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """Heading control toward the social-force velocity."""
        return self.decide(info["world"], info["state"]).command

    def force(self, world: World, state: State) -> NDArray[np.float64]:
        """The social force on the robot ``(2,)`` [m/s²]."""
        sf = world.sim.social_force
        tau = self.tau if self.tau is not None else sf.tau
        a_h = self.a_human if self.a_human is not None else sf.a_human
        b_h = self.b_human if self.b_human is not None else sf.b_human
        a_w = self.a_wall if self.a_wall is not None else sf.a_wall
        b_w = self.b_wall if self.b_wall is not None else sf.b_wall
        r_r = world.sim.robot.radius
        x, y, th = state.robot[0]
        p = np.array([x, y])
        v_r = state.command[0, 0] * np.array([math.cos(th), math.sin(th)])
        to_goal = state.goal[0] - p
        d_goal = float(np.hypot(to_goal[0], to_goal[1]))
        e_g = to_goal / d_goal if d_goal > 1e-9 else np.zeros(2)
        speed = self.v_pref * min(1.0, d_goal / self.slow_distance)
        f = (speed * e_g - v_r) / tau
        present = state.h_status[0] != GONE
        if present.any():
            diff = p - state.h_pos[0, present]  # (N, 2) from human to robot
            d = np.maximum(np.linalg.norm(diff, axis=1), 1e-9)
            mag = a_h * np.exp((r_r + state.h_radius[0, present] - d) / b_h)
            f = f + (mag[:, None] * diff / d[:, None]).sum(axis=0)
        if world.walls.shape[0]:
            diff = p - _wall_closest(p, world.walls)  # (M, 2)
            d = np.maximum(np.linalg.norm(diff, axis=1), 1e-9)
            mag = a_w * np.exp((r_r - d) / b_w)
            f = f + (mag[:, None] * diff / d[:, None]).sum(axis=0)
        return f

    def decide(
        self, world: World, state: State, prev: NDArray[np.float64] | None = None
    ) -> Decision:
        """One command from ``state`` (B = 1); the current velocity is the state's last
        command (``prev`` is not used)."""
        rob = world.sim.robot
        th = float(state.robot[0, 2])
        v_r = state.command[0, 0] * np.array([math.cos(th), math.sin(th)])
        v_d = v_r + self.force(world, state) * world.sim.dt
        return Decision(_heading_command(v_d, th, self.k_omega, rob.v_max, rob.omega_max))
