"""Generate demonstration datasets (paper §V-A): positives that drive well, negatives that
collide.

Positives (γ = +1), by ``demonstrator``:

- ``"teacher"`` (the default in the elevator): *efficient* successes of the rules-only
  teacher (goal and obstacle terms, no density: the paper's Table II "w/o R_den" row) — the
  episodes a skilled operator would drive, kept only when they end within ``max_time_s`` and
  ``max_path_m`` and never come closer than ``min_gap_m`` to a person (:class:`Selection`).
  The density fitted on them pays for states and commands like theirs (docs/demonstrations.md
  says why these and not slower, courteous ones);
- ``"courteous"``: successes of the scripted courteous driver (privileged: lets the exiting
  person out, keeps its distance, then drives to its goal), filtered the same way;
- the static study always uses the corridor driver.

Negatives (γ = −1): the frames in the last 1.0 s before a collision of the careless driver
(elevator: straight to its goal, ignoring people) or of the corridor driver aimed at the
human (static study). Episodes are seeded ``training_seed(seed, k)`` (training seeds,
disjoint from the evaluation and validation seeds of :mod:`pioneer.seeds`); collection stops at
the requested counts (the last episode is truncated to hit them exactly).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any, Literal

import numpy as np

from pioneer.bounds import NonNegative, Positive
from pioneer.config import Config, check_count
from pioneer.demos.scripted import CarelessDriver, CorridorDriver, CourteousDriver
from pioneer.envs.env import NavEnv
from pioneer.envs.episode import Episode, Step
from pioneer.envs.policy import Policy
from pioneer.errors import ConfigError, expect
from pioneer.progress import progress_bar
from pioneer.reward.dataset import Dataset
from pioneer.seeds import training_seed
from pioneer.sim.scenarios import get_scenario

__all__ = ["DEFAULT_SIZES", "DEMONSTRATORS", "Frame", "Selection", "generate", "record_episode"]

# The paper's demonstration counts (positive, negative), §V-A and §V-B.
DEFAULT_SIZES = {"hr-rl": (732, 170), "hl-rr": (662, 194), "static": (446, 337)}
NEGATIVE_WINDOW = 1.0  # [s] frames this long before a collision are labelled γ = −1
MAX_EPISODES = 500

Frame = dict[str, Any]
Demonstrator = Literal["teacher", "courteous"]
DEMONSTRATORS: tuple[str, ...] = ("teacher", "courteous")


@dataclasses.dataclass(frozen=True)
class Selection(Config):
    """Which successful episodes make positive demonstrations: efficient and with a margin.

    The defaults keep what a skilled operator drives in the paper world (the paper's teacher:
    12.2–12.9 s, 3.7–3.9 m): a demonstration that lingers teaches the density to linger.
    """

    max_time_s: Positive = 14.0  # [s] episode time at most
    max_path_m: Positive = 4.3  # [m] path length at most
    min_gap_m: NonNegative = 0.0  # [m] closest approach to a person (surface to surface) at least

    def keeps(self, time_s: float, path_m: float, gap_m: float) -> bool:
        """Whether a successful episode with these statistics is kept."""
        return time_s <= self.max_time_s and path_m <= self.max_path_m and gap_m >= self.min_gap_m


def record_episode(
    env: NavEnv, policy: Policy, seed: int
) -> tuple[list[Frame], str, dict[str, float]]:
    """Run one episode; return its frames (state–action pairs), the final event and the
    episode's statistics (``time_s``, ``path_length_m``, ``min_gap_m`` to people)."""
    frames: list[Frame] = []

    def keep(step: Step) -> None:
        i = step.info
        frames.append(
            {
                "step": step.index,
                "time": i["time"],
                "obs": step.obs,
                "action": step.command,
                "pose": i["robot_pose"],
            }
        )

    episode = Episode(env, policy, seed)
    info = episode.run(keep)
    clear = float(info["episode_min_gap"])
    stats = {
        "time_s": float(info["time"]),
        "path_length_m": float(info["path_length"]),
        "min_gap_m": clear if math.isfinite(clear) else math.inf,
    }
    return frames, str(episode.event), stats


def negative_frames(frames: list[Frame], dt: float, window: float = NEGATIVE_WINDOW) -> list[Frame]:
    """The frames of the last ``window`` seconds before a collision (inclusive of the last)."""
    t_end = frames[-1]["time"] + dt
    return [f for f in frames if f["time"] >= t_end - window - 1e-9]


MAX_SAMPLES = 1_000_000  # samples one dataset may ask for (the paper's: 880)


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
                "ask for at least one sample (--positive N or --negative N), none below 0",
            )
        )
    check_count("samples (--positive + --negative)", n_pos + n_neg, MAX_SAMPLES, "ask for fewer")
    return n_pos, n_neg


def generate(
    scenario: str,
    n_positive: int | None = None,
    n_negative: int | None = None,
    seed: int = 0,
    progress: bool = True,
    command: str = "",
    demonstrator: Demonstrator = "teacher",
    selection: Selection | None = None,
) -> Dataset:
    """A dataset of ``n_positive`` γ = +1 and ``n_negative`` γ = −1 samples for ``scenario``:
    positives from ``demonstrator``'s successful episodes that ``selection`` keeps (module
    docstring), negatives from the careless driver's collisions."""
    if demonstrator not in DEMONSTRATORS:
        raise ConfigError(
            expect("demonstrator", f"one of {DEMONSTRATORS}", demonstrator, "pick one")
        )
    select = selection or Selection()
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
            frames, event, st = record_episode(env, make(k), ep_seed)
            kept = static or select.keeps(st["time_s"], st["path_length_m"], st["min_gap_m"])
            if gamma > 0 and event == "success" and kept:
                stats.append(st)
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

    stats: list[dict[str, float]] = []
    if static:
        # Positives: mostly the right corridor (the paper's demos were biased to the right).
        collect(lambda k: CorridorDriver(side=1.0 if k % 3 else -1.0), n_pos, 1.0, 0, "positive")
        collect(lambda k: CorridorDriver(through_middle=True), n_neg, -1.0, 100_000, "negative")
    else:
        collect(_positive_driver(cfg.name, demonstrator), n_pos, 1.0, 0, "positive")
        collect(lambda k: CarelessDriver(), n_neg, -1.0, 100_000, "negative")
    positives = "corridor" if static else demonstrator
    meta = {
        "source": "scripted" if static or demonstrator == "courteous" else "rules-only teacher",
        "demonstrators": "corridor" if static else f"{positives} (+1), careless (-1)",
        "command": command or f"pioneer demos generate --scenario {cfg.name} --seed {seed}",
        "negative_window_s": NEGATIVE_WINDOW,
        "generator_seed": seed,
        "selection": None if static else dataclasses.asdict(select),
        "positive_episodes": _episode_stats(stats),
    }
    return Dataset.from_rows(cols, scenarios=[cfg.name], meta=meta)


def _positive_driver(scenario: str, demonstrator: str) -> Callable[[int], Policy]:
    """The positive demonstrator's policy for episode k."""
    if demonstrator == "courteous":
        return lambda k: CourteousDriver()
    from pioneer.control.teacher import make_teacher

    teacher = make_teacher(scenario, density=False, name="teacher-no-density")
    return lambda k: teacher


def _episode_stats(stats: list[dict[str, float]]) -> dict[str, float | int]:
    """The kept positive episodes' count and mean time, path length and closest approach."""
    if not stats:
        return {"episodes": 0}
    clear = [s["min_gap_m"] for s in stats if math.isfinite(s["min_gap_m"])]
    return {
        "episodes": len(stats),
        "time_mean_s": float(np.mean([s["time_s"] for s in stats])),
        "path_length_mean_m": float(np.mean([s["path_length_m"] for s in stats])),
        "min_gap_mean_m": float(np.mean(clear)) if clear else math.nan,
    }
