"""Generate demonstration datasets with the scripted demonstrators (SPEC 2).

Positives (γ = +1): every frame of successful episodes of the courteous driver (elevator) or
the corridor driver (static study). Negatives (γ = −1): the frames in the last 1.0 s before a
collision of the careless driver (elevator) or of the corridor driver aimed at the human
(static study). Episodes are seeded ``training_seed(seed, k)`` (training seeds, disjoint from
the evaluation and validation seeds of :mod:`pioneer.seeds`); collection stops at the
requested counts (the last episode is truncated to hit them exactly).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from pioneer.control.policy import Policy
from pioneer.demos.scripted import CarelessDriver, CorridorDriver, CourteousDriver
from pioneer.envs.env import NavEnv
from pioneer.errors import ConfigError, expect
from pioneer.progress import progress_bar
from pioneer.reward.dataset import Dataset
from pioneer.seeds import training_seed
from pioneer.sim.scenarios import get_scenario

__all__ = ["DEFAULT_SIZES", "Frame", "generate", "record_episode"]

# The paper's demonstration counts (positive, negative), §V-A and §V-B.
DEFAULT_SIZES = {"hr-rl": (732, 170), "hl-rr": (662, 194), "static": (446, 337)}
NEGATIVE_WINDOW = 1.0  # [s] frames this long before a collision are labelled γ = −1
MAX_EPISODES = 500

Frame = dict[str, Any]


def record_episode(env: NavEnv, policy: Policy, seed: int) -> tuple[list[Frame], str]:
    """Run one episode; return its frames (state–action pairs) and the final event."""
    obs, info = env.reset(seed=seed)
    policy.reset(info, np.random.default_rng(seed))
    frames: list[Frame] = []
    event = None
    k = 0
    while event is None:
        u = np.asarray(policy.act(obs, info), dtype=np.float64)
        frames.append(
            {"step": k, "time": info["time"], "obs": obs, "action": u, "pose": info["robot_pose"]}
        )
        obs, _, _, _, info = env.step(u)
        event = info["event"]
        k += 1
    return frames, str(event)


def negative_frames(frames: list[Frame], dt: float, window: float = NEGATIVE_WINDOW) -> list[Frame]:
    """The frames of the last ``window`` seconds before a collision (inclusive of the last)."""
    t_end = frames[-1]["time"] + dt
    return [f for f in frames if f["time"] >= t_end - window - 1e-9]


def _sample_counts(name: str, n_positive: int | None, n_negative: int | None) -> tuple[int, int]:
    """The requested counts, or the scenario's defaults (the paper's); checked."""
    pos_default, neg_default = DEFAULT_SIZES.get(name, (700, 180))
    n_pos = pos_default if n_positive is None else n_positive
    n_neg = neg_default if n_negative is None else n_negative
    if n_pos < 0 or n_neg < 0 or n_pos + n_neg == 0:
        raise ConfigError(
            expect(
                "sample counts",
                "n_positive, n_negative >= 0, not both 0",
                (n_pos, n_neg),
                "fix the counts",
            )
        )
    return n_pos, n_neg


def generate(
    scenario: str,
    n_positive: int | None = None,
    n_negative: int | None = None,
    seed: int = 0,
    progress: bool = True,
    command: str = "",
) -> Dataset:
    """A dataset of ``n_positive`` γ = +1 and ``n_negative`` γ = −1 samples for ``scenario``."""
    cfg = get_scenario(scenario)
    n_pos, n_neg = _sample_counts(cfg.name, n_positive, n_negative)
    env = NavEnv(cfg)
    dt = cfg.sim.dt
    static = cfg.name == "static"
    cols: dict[str, list[Any]] = {
        k: []
        for k in ("episode", "step", "time", "obs", "action", "gamma", "pose", "scenario", "seed")
    }
    episode = 0

    def add(frames: list[Frame], gamma: float, ep_seed: int, limit: int) -> int:
        nonlocal episode
        # Truncating: positives keep their first frames, negatives the ones nearest the collision.
        frames = frames[:limit] if gamma > 0 else frames[-limit:]
        Dataset.add_frames(cols, frames, gamma, episode, ep_seed)
        episode += 1
        return len(frames)

    def collect(
        make: Callable[[int], Policy], want: int, gamma: float, offset: int, label: str
    ) -> None:
        got = 0
        bar = progress_bar(total=want, desc=f"{cfg.name} {label}", unit="sample", enabled=progress)
        for k in range(MAX_EPISODES):
            if got >= want:
                break
            ep_seed = training_seed(seed + offset, k)
            frames, event = record_episode(env, make(k), ep_seed)
            if gamma > 0 and event == "success":
                n = add(frames, 1.0, ep_seed, want - got)
            elif gamma < 0 and event == "collision":
                n = add(negative_frames(frames, dt), -1.0, ep_seed, want - got)
            else:
                n = 0
            got += n
            bar.update(n)
        bar.close()
        if got < want:
            raise ConfigError(
                expect(
                    f"{cfg.name} {label} demos",
                    f"{want} samples within {MAX_EPISODES} episodes",
                    got,
                    "ask for fewer samples",
                )
            )

    if static:
        # Positives: mostly the right corridor (the paper's demos were biased to the right).
        collect(lambda k: CorridorDriver(side=1.0 if k % 3 else -1.0), n_pos, 1.0, 0, "positive")
        collect(lambda k: CorridorDriver(through_middle=True), n_neg, -1.0, 100_000, "negative")
    else:
        collect(lambda k: CourteousDriver(), n_pos, 1.0, 0, "positive")
        collect(lambda k: CarelessDriver(), n_neg, -1.0, 100_000, "negative")
    meta = {
        "source": "scripted",
        "demonstrators": "corridor" if static else "courteous (+1), careless (-1)",
        "command": command or f"pioneer demos generate --scenario {cfg.name} --seed {seed}",
        "negative_window_s": NEGATIVE_WINDOW,
        "generator_seed": seed,
    }
    return Dataset.from_rows(cols, scenarios=[cfg.name], meta=meta)
