"""A native Gymnasium ``VectorEnv``: B copies of a scenario in one batched simulator state.

``gymnasium.make_vec("pioneer/ElevatorHRRL-v1", num_envs=64)`` returns it (the ids register a
``vector_entry_point``); ``vectorization_mode="sync"`` still gives Gymnasium's
``SyncVectorEnv`` over :class:`~pioneer.envs.env.NavEnv` copies.

One ``step`` is one call of the world kernel for every copy, one event classification
(:func:`pioneer.sim.events.classify`) and one evaluation of the environment's
:class:`~pioneer.envs.reward.StepReward` (by default the CrowdNav++ reward) — the same
functions the single environment uses. Copy i has its own generator, seeded ``seed + i`` like
``SyncVectorEnv`` seeds its environments, and restarts by Gymnasium's default next-step
autoreset; so with the same seed and actions the native and the ``sync`` vector env return
identical observations, rewards and flags (tested).

``infos`` has the keys of the single environment's ``info``, each value stacked over the
copies: ``event`` (labels, ``None`` while going on), ``event_code`` (int8 codes of
:class:`~pioneer.sim.events.Event`), ``robot_pose``, ``goal``, ``min_gap``,
``episode_min_gap``, ``wall_gap`` [m], ``time`` [s], ``path_length`` [m],
``rewards`` (per term), and the batched ``state`` and the ``world``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space
from numpy.typing import NDArray

from pioneer.envs.env import spaces
from pioneer.envs.reward import StepReward, step_reward
from pioneer.errors import ConfigError, expect
from pioneer.reward.crowdnav import CrowdNavRewardConfig
from pioneer.sim.events import Event, classify
from pioneer.sim.scenarios import DEFAULT_SCENARIO, ScenarioConfig, get_scenario, sample_state
from pioneer.sim.world import State, World, observe, step

__all__ = ["NavVectorEnv"]

# Event code → its label (None while an episode goes on), indexed by the int8 codes at once.
_LABELS = np.array([e.label for e in Event], dtype=object)

F32 = NDArray[np.float32]


class NavVectorEnv(gym.vector.VectorEnv[F32, F32, NDArray[Any]]):
    """``num_envs`` copies of ``scenario`` stepped together (see the module docstring)."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP}  # noqa: RUF012

    def __init__(
        self,
        num_envs: int = 1,
        scenario: str | ScenarioConfig = DEFAULT_SCENARIO,
        reward: StepReward | CrowdNavRewardConfig | None = None,
        render_mode: str | None = None,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ConfigError(expect("num_envs", "an integer >= 1", num_envs, "e.g. 64"))
        if render_mode is not None:
            raise ConfigError(
                expect("render_mode", "None (render one NavEnv instead)", render_mode, "drop it")
            )
        self.scenario = get_scenario(scenario) if isinstance(scenario, str) else scenario
        self.num_envs = num_envs
        self.reward = step_reward(reward)
        self.world: World = self.scenario.world()
        self.single_observation_space, self.single_action_space = spaces(self.scenario)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.render_mode = None
        self._noisy = self.scenario.sim.lidar.noise_std > 0.0
        self._rngs = [np.random.default_rng() for _ in range(num_envs)]
        self._state: State | None = None
        self._autoreset = np.zeros(num_envs, dtype=np.bool_)
        self._ep_min_clear = np.full(num_envs, np.inf)

    @property
    def state(self) -> State:
        """The batched world state (B = ``num_envs``)."""
        if self._state is None:
            raise ConfigError(
                expect("NavVectorEnv.state", "a reset environment", None, "call reset()")
            )
        return self._state

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[F32, dict[str, Any]]:
        """Sample every copy's initial state; ``seed`` an int seeds copy i with ``seed + i``."""
        if options:
            raise ConfigError(expect("options", "None", sorted(options), "drop them"))
        seeds = self._seeds(seed)
        for i, s in enumerate(seeds):
            if s is not None or self._state is None:
                self._rngs[i] = gym.utils.seeding.np_random(s)[0]
        self._state = State.concat([sample_state(self.scenario, rng) for rng in self._rngs])
        self._autoreset[:] = False
        self._ep_min_clear = self._state.gap.copy()
        none = np.zeros(self.num_envs, dtype=np.int8)
        return self._observe(), self._info(self._state, none, {})

    def _seeds(self, seed: int | list[int | None] | None) -> list[int | None]:
        if seed is None:
            return [None] * self.num_envs
        if isinstance(seed, int):
            return [seed + i for i in range(self.num_envs)]
        if len(seed) != self.num_envs:
            raise ConfigError(
                expect("seed", f"an int or {self.num_envs} seeds", len(seed), "one per copy")
            )
        return list(seed)

    def step(
        self, actions: NDArray[np.floating]
    ) -> tuple[F32, NDArray[Any], NDArray[Any], NDArray[Any], dict[str, Any]]:
        """Apply ``(v, ω)`` of every copy, shape ``(num_envs, 2)``; copies that ended on the
        previous step restart instead (reward 0, both flags false)."""
        cmd = np.asarray(actions, dtype=np.float64).reshape(self.num_envs, 2)
        prev = self.state
        new = step(self.world, prev, cmd)
        event = classify(prev, new, self.world.sim.time_limit)  # the world ends episodes
        total, terms = self.reward(self.world, prev, new, event)
        np.minimum(self._ep_min_clear, new.gap, out=self._ep_min_clear)
        restart = np.flatnonzero(self._autoreset)
        for i in restart:
            new.put(int(i), sample_state(self.scenario, self._rngs[i]))
            self._ep_min_clear[i] = new.gap[i]
        total[restart] = 0.0
        event[restart] = Event.NONE
        for v in terms.values():
            v[restart] = 0.0
        self._state = new
        terminated = (event == Event.SUCCESS) | (event == Event.COLLISION)
        truncated = event == Event.TIMEOUT
        self._autoreset = terminated | truncated
        obs = self._observe()
        return obs, total, terminated, truncated, self._info(new, event, terms)

    def _observe(self) -> F32:
        if not self._noisy:
            return observe(self.world, self.state)
        # Each copy draws its LiDAR noise from its own generator, as a NavEnv would.
        return np.concatenate(
            [observe(self.world, self.state.take(i), rng) for i, rng in enumerate(self._rngs)]
        )

    def _info(
        self, state: State, event: NDArray[np.int8], rewards: dict[str, NDArray[np.float64]]
    ) -> dict[str, Any]:
        return {
            "event": _LABELS[event],
            "event_code": event,
            "robot_pose": state.robot.copy(),
            "goal": state.goal.copy(),
            "min_gap": state.gap.copy(),
            "episode_min_gap": self._ep_min_clear.copy(),
            "wall_gap": state.wall_gap.copy(),
            "time": state.t.copy(),
            "path_length": state.path_length.copy(),
            "rewards": rewards,
            "state": state,
            "world": self.world,
        }
