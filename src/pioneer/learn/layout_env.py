"""The environments of the students' fine-tuning (:mod:`pioneer.learn.finetune`): many layouts
of a distribution stepped together, the student's inputs and the critic's privileged features.

:class:`LayoutEnvs` holds ``groups`` worlds, each ``group_size`` copies of one layout in one
batched :class:`~pioneer.sim.world.State`: the simulator's kernels step one world at a time
(walls, the people's parameters and the LiDAR belong to the world), so copies of one layout
share a call and a step of all copies costs ``groups`` kernel calls. A copy whose episode ends
(success, collision, the time limit: :func:`pioneer.sim.events.classify`) restarts in its
group's layout from a new training seed (:func:`pioneer.seeds.finetune_seed`); ``redraw`` gives
a group a new layout, cutting its episodes (the trainer redraws between two rollouts, so the
cut episodes are bootstrapped with the critic's value like any rollout's end).

Each step the copies read what the student reads (:class:`~pioneer.deploy.runtime.StudentInputs`:
o_t, and if it was trained with them o_{t−1} — o_t at an episode's first step — and the
command the robot ran, 0 at the first step), as :class:`~pioneer.learn.policy.StudentPolicy`
and the robot runtime give it. :func:`privileged` is the critic's extra view of the state,
which the deployed student never sees. :meth:`LayoutEnvs.teacher_labels` is what the
privileged teacher would command in chosen copies (teacher-guided fine-tuning).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from pioneer.deploy.inputs import StudentInputs
from pioneer.learn.curriculum import Curriculum
from pioneer.reward.crowdnav import CrowdNavRewardConfig, crowdnav_reward
from pioneer.seeds import finetune_seed
from pioneer.sim.events import Event, classify
from pioneer.sim.scenarios import ScenarioConfig, get_scenario, sample_state
from pioneer.sim.world import State, World, observe, step

__all__ = ["HUMAN_FEATURES", "LayoutEnvs", "ReplayMode", "privileged", "privileged_width"]

F32 = NDArray[np.float32]
ReplayMode = Literal["mix", "plr", "mastery"]
"""How ``replay`` prioritises a pool's layouts (:meth:`LayoutEnvs._draw`; ``"mastery"``:
:mod:`pioneer.learn.curriculum`)."""
F64 = NDArray[np.float64]
ROBOT_FEATURES = 6  # t / T, goal (x, y) in the robot's frame, its distance, (v, ω) last run
# per person slot: position and velocity in the robot's frame, radius, present, not yet
# walking (t < its delay), reacts to the robot
HUMAN_FEATURES = 8


def privileged_width(max_humans: int) -> int:
    """The width of :func:`privileged`'s rows for ``max_humans`` person slots."""
    return ROBOT_FEATURES + HUMAN_FEATURES * max_humans


def privileged(state: State, time_limit: float, max_humans: int) -> F32:
    """The critic's view of ``state`` (B copies), ``(B, privileged_width(max_humans))``:
    elapsed time over the limit (timeouts end episodes, so the value depends on it), the goal
    in the robot's frame, the command last run, and per person — in the state's order, unused
    slots zero — position and velocity in the robot's frame [m, m/s], radius [m], present,
    waiting to start and whether they react to the robot."""
    b, n = state.batch_size, state.n_humans
    c, s = np.cos(state.robot[:, 2]), np.sin(state.robot[:, 2])

    def frame(x: F64, y: F64) -> tuple[F64, F64]:
        return c[:, None] * x + s[:, None] * y, -s[:, None] * x + c[:, None] * y

    out = np.zeros((b, privileged_width(max_humans)), dtype=np.float32)
    g = state.goal - state.robot[:, :2]
    gx, gy = frame(g[:, :1], g[:, 1:])
    out[:, 0] = state.t / time_limit
    out[:, 1], out[:, 2] = gx[:, 0], gy[:, 0]
    out[:, 3] = np.hypot(g[:, 0], g[:, 1])
    out[:, 4:6] = state.command
    k = min(n, max_humans)
    if k:
        present = state.humans_present[:, :k]
        px, py = frame(
            state.h_pos[:, :k, 0] - state.robot[:, :1], state.h_pos[:, :k, 1] - state.robot[:, 1:2]
        )
        vx, vy = frame(state.h_vel[:, :k, 0], state.h_vel[:, :k, 1])
        cols = (
            px,
            py,
            vx,
            vy,
            state.h_radius[:, :k],
            present,
            state.t[:, None] < state.h_delay[:, :k],
            state.h_reacts[:, :k],
        )
        block = np.stack([np.where(present, x, 0.0) for x in cols[:5]] + list(cols[5:]), -1)
        out[:, ROBOT_FEATURES : ROBOT_FEATURES + HUMAN_FEATURES * k] = block.reshape(b, -1)
    return out


class _Group:
    """``size`` copies of one layout."""

    def __init__(self, name: str, state: State, obs_rng: np.random.Generator) -> None:
        self.name = name
        self.scenario: ScenarioConfig = get_scenario(name)
        self.world: World = self.scenario.world()
        self.state = state
        self.obs_rng = obs_rng  # the LiDAR's noise of this group's copies


class LayoutEnvs:
    """``groups`` × ``group_size`` copies over the layouts ``names`` (module docstring): a
    sequence of name sets, each drawn equally often (or with the probabilities ``weights``), a
    layout uniformly within its set (e.g. ``[["general-0000", …], ["hr-rl"], ["hl-rr"]]``: a
    third each).

    ``rng`` draws the layouts and the episodes' seed numbers (its state is the caller's to
    save); ``seed`` is the run's, mixed into every episode's training seed.
    """

    def __init__(
        self,
        names: Sequence[Sequence[str]],
        groups: int,
        group_size: int,
        inputs: StudentInputs,
        reward: CrowdNavRewardConfig,
        rng: np.random.Generator,
        seed: int,
        max_humans: int,
        replay: float = 0.0,
        replay_mode: ReplayMode = "mix",
        curriculum: Curriculum | None = None,
        weights: Sequence[float] | None = None,
    ) -> None:
        self.names = [list(n) for n in names]
        if weights is not None and (len(weights) != len(names) or abs(sum(weights) - 1) > 1e-9):
            raise ValueError(f"weights: one per name set, summing to 1; got {list(weights)}")
        self.weights = None if weights is None else np.asarray(weights, dtype=np.float64)
        self.size, self.inputs, self.reward = group_size, inputs, reward
        self.rng, self.seed, self.max_humans = rng, seed, max_humans
        self.episode_count = 0  # episodes started: the k of finetune_seed
        # prioritised layouts: each layout's running failure rate (1 until it is first seen)
        self.replay, self.replay_mode = replay, replay_mode
        self.failure: dict[str, float] = {}
        # ``"mastery"``: the active set of hard layouts (filled here, before the first draw)
        if (replay_mode == "mastery") != (curriculum is not None):
            raise ValueError("a curriculum is given exactly when replay_mode is 'mastery'")
        self.curriculum = curriculum
        if self.curriculum is not None:
            self.curriculum.fill(rng, self.failure)
        self._teachers: dict[str, Any] = {}  # the teacher per base scenario (its reward's)
        self.groups: list[_Group] = []
        for _ in range(groups):
            self.groups.append(self._new_group())
        n = groups * group_size
        self.obs = np.zeros((n, self._obs_dim()), dtype=np.float32)
        self.prev_obs = np.zeros_like(self.obs)
        self.prev_cmd = np.zeros((n, 2), dtype=np.float64)
        for g in range(groups):
            self._observe_group(g, np.ones(group_size, dtype=np.bool_))

    @property
    def n(self) -> int:
        """All copies: groups × group_size."""
        return len(self.groups) * self.size

    def _obs_dim(self) -> int:
        return int(self.groups[0].world.sim.lidar.obs_dim)

    def _episode(self, scenario: ScenarioConfig) -> State:
        seed = finetune_seed(self.seed, self.episode_count)
        self.episode_count += 1
        return sample_state(scenario, np.random.default_rng(seed))

    def _new_group(self) -> _Group:
        cur = self.curriculum
        if cur is not None and cur.active and self.rng.random() < self.replay:
            name = cur.draw(self.rng)
        else:
            k = len(self.names)
            i = self.rng.integers(k) if self.weights is None else self.rng.choice(k, p=self.weights)
            pool = self.names[int(i)]
            name = pool[self._draw(pool)]
        sc = get_scenario(name)
        state = State.concat([self._episode(sc) for _ in range(self.size)])
        obs_rng = np.random.default_rng(finetune_seed(self.seed, self.episode_count, "lidar"))
        return _Group(name, state, obs_rng)

    def _draw(self, pool: list[str]) -> int:
        """A layout of ``pool`` (:data:`ReplayMode`): uniformly; or, ``"mix"``, with
        probability ``replay`` in proportion to its running failure rate, a layout not yet
        seen counting as failing; or, ``"plr"``, with probability ``replay`` a layout already
        seen in proportion to its failure rate, else one not yet seen, uniformly (all seen:
        any, uniformly) — prioritised level replay (Jiang et al., ICML 2021); ``"mastery"``:
        uniformly (the curriculum's share is drawn in :meth:`_new_group`)."""
        if self.replay <= 0.0 or len(pool) == 1 or self.replay_mode == "mastery":
            return int(self.rng.integers(len(pool)))
        if self.replay_mode == "plr":
            seen = np.array([n in self.failure for n in pool])
            if not seen.any():
                return int(self.rng.integers(len(pool)))
            if self.rng.random() < self.replay:  # replay: a seen layout by its failure rate
                idx = np.flatnonzero(seen)
                w = np.array([self.failure[pool[i]] for i in idx]) + 1e-3
                return int(idx[self.rng.choice(idx.size, p=w / w.sum())])
            explore = np.flatnonzero(~seen) if not seen.all() else np.arange(len(pool))
            return int(explore[self.rng.integers(explore.size)])
        w = np.array([self.failure.get(n, 1.0) for n in pool]) + 1e-3
        p = (1.0 - self.replay) / len(pool) + self.replay * w / w.sum()
        return int(self.rng.choice(len(pool), p=p / p.sum()))

    def redraw(self, g: int) -> None:
        """Group ``g`` restarts every copy in a newly drawn layout."""
        self.groups[g] = self._new_group()
        self._observe_group(g, np.ones(self.size, dtype=np.bool_))

    def _observe_group(self, g: int, fresh: NDArray[np.bool_]) -> None:
        grp, sl = self.groups[g], slice(g * self.size, (g + 1) * self.size)
        o = observe(grp.world, grp.state, grp.obs_rng)
        prev = np.where(fresh[:, None], o, self.obs[sl])
        self.prev_obs[sl] = prev
        self.prev_cmd[sl] = np.where(fresh[:, None], 0.0, grp.state.command)
        self.obs[sl] = o

    def student_inputs(self) -> F32:
        """What the student reads now, ``(n, inputs.width(obs_dim))``."""
        k = self.inputs
        return k.stack(
            self.obs,
            self.prev_obs if k.previous_observation else None,
            self.prev_cmd if k.previous_command else None,
        )

    def privileged(self) -> F32:
        """:func:`privileged` of every copy, ``(n, privileged_width(max_humans))``."""
        return np.concatenate(
            [privileged(g.state, g.world.sim.time_limit, self.max_humans) for g in self.groups]
        )

    def teacher_labels(self, copies: NDArray[np.int64]) -> F64:
        """The teacher's command ``(len(copies), 2)`` in each of ``copies`` now: the default
        teacher (:func:`~pioneer.control.teacher.make_teacher`, the reward of the layout's base
        scenario) from the privileged state and world, smoothed with the command the copy last
        ran — the label DAgger gives (:mod:`pioneer.learn.dagger`)."""
        from pioneer.sim.scenarios import scenario_base

        out = np.zeros((len(copies), 2))
        for k, i in enumerate(copies):
            grp = self.groups[int(i) // self.size]
            base = scenario_base(grp.name)
            if base not in self._teachers:
                from pioneer.control.teacher import make_teacher

                self._teachers[base] = make_teacher(base)
            state = grp.state.take(int(i) % self.size)
            decision = self._teachers[base].decide(grp.world, state, prev=state.command[0])
            out[k] = decision.command
        return out

    def step(self, commands: F64) -> tuple[F64, NDArray[np.int8]]:
        """Run ``commands (n, 2)`` one control period: the rewards ``(n,)`` and event codes
        ``(n,)`` of the step; ended copies restart (their next inputs are a new episode's)."""
        rewards, events = np.zeros(self.n), np.zeros(self.n, dtype=np.int8)
        for g, grp in enumerate(self.groups):
            sl = slice(g * self.size, (g + 1) * self.size)
            new = step(grp.world, grp.state, commands[sl])
            event = classify(grp.state, new, grp.world.sim.time_limit)
            rewards[sl] = crowdnav_reward(grp.world, grp.state, new, event, self.reward)
            events[sl] = event
            done = event != Event.NONE
            for i in np.flatnonzero(done):  # the layout's failure rate, a running mean
                failed = float(event[i] != Event.SUCCESS)
                self.failure[grp.name] = 0.9 * self.failure.get(grp.name, failed) + 0.1 * failed
                if self.curriculum is not None:
                    self.curriculum.record(
                        grp.name, not failed, self.episode_count, self.rng, self.failure
                    )
            for i in np.flatnonzero(done):
                new.put(int(i), self._episode(grp.scenario))
            grp.state = new
            self._observe_group(g, done)
        return rewards, events

    # ------------------------------------------------------------------ state for checkpoints
    def arrays(self) -> dict[str, NDArray[Any]]:
        """Every array of the copies' state, by name (a checkpoint's tensors)."""
        out: dict[str, NDArray[Any]] = {
            "obs": self.obs,
            "prev_obs": self.prev_obs,
            "prev_cmd": self.prev_cmd,
        }
        for g, grp in enumerate(self.groups):
            for k in State.fields():
                out[f"group{g}/{k}"] = getattr(grp.state, k)
        return out

    def meta(self) -> dict[str, Any]:
        """The JSON part: layouts, counters and the LiDAR generators' states."""
        return {
            "layouts": [g.name for g in self.groups],
            "episode_count": self.episode_count,
            "failure": self.failure,
            **({"curriculum": self.curriculum.state()} if self.curriculum is not None else {}),
            "lidar_rngs": [g.obs_rng.bit_generator.state for g in self.groups],
        }

    def restore(self, arrays: dict[str, NDArray[Any]], meta: dict[str, Any]) -> None:
        """The inverse of :meth:`arrays` and :meth:`meta`."""
        self.obs, self.prev_obs = arrays["obs"].copy(), arrays["prev_obs"].copy()
        self.prev_cmd = arrays["prev_cmd"].copy()
        self.episode_count = int(meta["episode_count"])
        self.failure = {str(k): float(v) for k, v in meta.get("failure", {}).items()}
        if self.curriculum is not None:
            self.curriculum.restore(meta["curriculum"])
        for g, name in enumerate(meta["layouts"]):
            state = State(**{k: arrays[f"group{g}/{k}"].copy() for k in State.fields()})
            rng = np.random.default_rng()
            rng.bit_generator.state = meta["lidar_rngs"][g]
            self.groups[g] = _Group(name, state, rng)
