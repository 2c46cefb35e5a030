"""Gymnasium environment over the pure world core (docs/simulator.md).

Observation ``Box(29,)`` float32 (paper §III-A); action ``Box([0, −0.4π], [0.8, 0.4π])`` = (v, ω);
10 Hz. ``terminated`` on success or collision, ``truncated`` at the time limit (30 s).

The environment's scalar reward is a :class:`~pioneer.envs.reward.StepReward`; by default the
CrowdNav++ reward (:mod:`pioneer.reward.crowdnav`,
Liu et al., ICRA 2023), the one the CrowdNav++ baseline trains on; PioneeR's own learned reward is
:mod:`pioneer.reward.density`. Its per-term breakdown is in ``info["rewards"]``.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from pioneer.envs.reward import StepReward, step_reward
from pioneer.errors import ConfigError, expect
from pioneer.registration import ENV_IDS, register_envs
from pioneer.reward.crowdnav import CrowdNavRewardConfig
from pioneer.sim.events import Event, classify
from pioneer.sim.scenarios import DEFAULT_SCENARIO, ScenarioConfig, get_scenario, sample_state
from pioneer.sim.world import State, World, observe, step

__all__ = ["ENV_IDS", "NavEnv", "register_envs", "spaces"]


def spaces(
    scenario: ScenarioConfig,
) -> tuple[gym.spaces.Space[NDArray[np.float32]], gym.spaces.Space[NDArray[np.float32]]]:
    """Observation ``Box(29,)`` (paper §III-A) and action ``Box(2,)`` (v, ω) of one copy."""
    sim = scenario.sim
    lid = sim.lidar
    n_dist, n_ang = lid.n_sectors + lid.n_nearest, lid.n_nearest + 1
    observation: gym.spaces.Space[NDArray[np.float32]] = gym.spaces.Box(
        low=np.array([0.0] * n_dist + [-math.pi] * n_ang, dtype=np.float32),
        high=np.array([lid.max_range] * n_dist + [math.pi] * n_ang, dtype=np.float32),
        dtype=np.float32,
    )
    action: gym.spaces.Space[NDArray[np.float32]] = gym.spaces.Box(
        low=sim.robot.command_low.astype(np.float32),
        high=sim.robot.command_high.astype(np.float32),
        dtype=np.float32,
    )
    return observation, action


class NavEnv(gym.Env[NDArray[np.float32], NDArray[np.float32]]):
    """A PioneeR scenario as a Gymnasium environment.

    ``info`` carries ``event`` (``"success"``, ``"collision"``, ``"timeout"`` or ``None``) and
    its ``event_code`` (:class:`~pioneer.sim.events.Event`),
    ``robot_pose`` (x, y, θ), ``goal``, ``min_gap`` (swept surface-to-surface gap to the
    nearest human over the last step [m]), ``episode_min_gap``, ``time`` [s], ``path_length`` [m],
    ``rewards`` (per term), and ``state``/``world`` for privileged controllers.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}  # noqa: RUF012

    def __init__(
        self,
        scenario: str | ScenarioConfig = DEFAULT_SCENARIO,
        render_mode: str | None = None,
        reward: StepReward | CrowdNavRewardConfig | None = None,
    ) -> None:
        self.scenario = get_scenario(scenario) if isinstance(scenario, str) else scenario
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError(
                expect("render_mode", f"one of {self.metadata['render_modes']}", render_mode, "")
            )
        self.render_mode = render_mode
        self.reward = step_reward(reward)
        self.world: World = self.scenario.world()
        self.observation_space, self.action_space = spaces(self.scenario)
        self._state: State | None = None
        self._ep_min_clear = math.inf

    @property
    def state(self) -> State:
        """The current world state (B = 1)."""
        if self._state is None:
            raise ConfigError(expect("NavEnv.state", "a reset environment", None, "call reset()"))
        return self._state

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """Sample an initial state from ``self.np_random`` (or take ``options["state"]``)."""
        super().reset(seed=seed)
        opts = options or {}
        start = opts.get("state")
        if start is not None:
            if not isinstance(start, State) or start.batch_size != 1:
                raise ConfigError(
                    expect("options['state']", "a State with B = 1", start, "take(0)")
                )
            self._state = start.copy()
        else:
            self._state = sample_state(self.scenario, self.np_random)
        self._ep_min_clear = float(self._state.gap[0])
        obs = observe(self.world, self._state, self.np_random)[0]
        return obs, self._info(Event.NONE, {})

    def step(
        self, action: NDArray[np.floating] | list[float]
    ) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        """Apply ``(v, ω)`` for one control period."""
        prev = self.state
        new = step(self.world, prev, np.asarray(action, dtype=np.float64))
        self._state = new
        self._ep_min_clear = min(self._ep_min_clear, float(new.gap[0]))
        codes = classify(prev, new, self.world.sim.time_limit)  # the world ends episodes
        total, terms = self.reward(self.world, prev, new, codes)
        event = Event(int(codes[0]))
        obs = observe(self.world, new, self.np_random)[0]
        info = self._info(event, {k: float(v[0]) for k, v in terms.items()})
        ended = event in (Event.SUCCESS, Event.COLLISION)
        return obs, float(total[0]), ended, event is Event.TIMEOUT, info

    def _info(self, event: Event, rewards: dict[str, float]) -> dict[str, Any]:
        s = self.state
        return {
            "event": event.label,
            "event_code": int(event),
            "robot_pose": s.robot[0].copy(),
            "goal": s.goal[0].copy(),
            "min_gap": float(s.gap[0]),
            "episode_min_gap": self._ep_min_clear,
            "wall_gap": float(s.wall_gap[0]),
            "time": float(s.t[0]),
            "path_length": float(s.path_length[0]),
            "rewards": rewards,
            "state": s,
            "world": self.world,
        }

    def render(self) -> NDArray[np.uint8] | None:
        """An RGB frame drawn by :mod:`pioneer.viz` (only ``render_mode="rgb_array"``)."""
        if self.render_mode != "rgb_array":
            return None
        from pioneer.viz.frames import render_frame

        return render_frame(self.world, self.state)
