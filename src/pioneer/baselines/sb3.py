"""Stable-Baselines3 PPO on the Gymnasium environments, as a user of Gymnasium would train it.

``train_sb3_ppo`` makes ``pioneer/ElevatorHRRL-v1`` (or ``…HLRR-v1``; other scenarios through the
``scenario`` keyword) with ``stable_baselines3.common.env_util.make_vec_env``, trains SB3's
``PPO("MlpPolicy")`` with SB3's default hyperparameters on the environment's own reward (the
29-D LiDAR observation, absolute (v, ω) actions), and writes

- ``policy.safetensors``: the policy network's tensors, with the SB3 version, the network
  architecture, the spaces and the training settings as JSON metadata. SB3's own ``.zip``
  holds pickles, which this project never asks a user to load, so it is not written;
- ``curve.csv`` (appended after every rollout), ``curve.png`` and ``train.json``.

``make_sb3_policy`` rebuilds the policy from that file (no pickle) as the registry's
``sb3-ppo`` policy; it acts on the observation alone with the Gaussian's mean.

An interrupted run is not resumed (SB3 keeps its resumable state only in pickles); a run of the
scale used here takes minutes. Needs the ``sb3`` extra: ``pip install pioneer-nav[sb3]``.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.baselines.crowdnav.trainer import CURVE_COLUMNS as PPO_CURVE_COLUMNS
from pioneer.errors import ConfigError, DataError, expect
from pioneer.io import output_dir_kind, run_lock, to_json, write_text_atomic
from pioneer.registration import ENV_IDS, register_envs

__all__ = [
    "CURVE_COLUMNS",
    "SB3_FORMAT",
    "Sb3Policy",
    "env_id_for",
    "make_sb3_policy",
    "train_sb3_ppo",
]

SB3_FORMAT = "pioneer.sb3-ppo/1"
# the CrowdNav++ trainer's learning-curve columns, counted in SB3 rollouts instead of updates
CURVE_COLUMNS = ("rollout", *PPO_CURVE_COLUMNS[1:])
WINDOW = 100  # finished episodes in the curve's running statistics
_FALLBACK_ID = "pioneer/ElevatorHRRL-v1"  # any registered id; ``scenario=`` picks the world


def env_id_for(scenario: str) -> tuple[str, dict[str, Any]]:
    """The Gymnasium id (and keyword arguments) that make ``scenario``'s environment."""
    by_scenario = {name: env_id for env_id, name in ENV_IDS.items()}
    if scenario in by_scenario:
        return by_scenario[scenario], {}
    return _FALLBACK_ID, {"scenario": scenario}


def _curve_row(
    rollout: int, steps: int, episodes: int, window: list[tuple[float, str]], wall: float
) -> list[float]:
    if not window:
        return [rollout, steps, episodes, np.nan, np.nan, np.nan, np.nan, round(wall, 2)]
    returns = np.array([r for r, _ in window])
    events = [e for _, e in window]
    share = {e: events.count(e) / len(events) for e in ("success", "collision", "timeout")}
    return [
        rollout,
        steps,
        episodes,
        float(returns.mean()),
        share["success"],
        share["collision"],
        share["timeout"],
        round(wall, 2),
    ]


def _make_callback(out: Path, total: int, progress: bool) -> Any:
    """An SB3 callback that keeps the learning curve (appended to ``curve.csv`` after every
    rollout) and a progress bar."""
    from stable_baselines3.common.callbacks import BaseCallback

    from pioneer.progress import progress_bar

    class _Curve(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.rows: list[list[float]] = []
            self.window: list[tuple[float, str]] = []
            self.episodes = 0
            self.t0 = time.perf_counter()
            self.bar = progress_bar(total=total, unit="step", desc="sb3-ppo", enabled=progress)

        def _on_step(self) -> bool:
            infos = self.locals.get("infos", [])
            for info in infos:
                ep = info.get("episode")
                if ep is not None:
                    self.episodes += 1
                    self.window = [*self.window, (float(ep["r"]), str(info["event"]))][-WINDOW:]
            self.bar.update(len(infos))
            return True

        def _on_rollout_end(self) -> None:
            row = _curve_row(
                len(self.rows) + 1,
                int(self.num_timesteps),
                self.episodes,
                self.window,
                time.perf_counter() - self.t0,
            )
            self.rows.append(row)
            with (out / "curve.csv").open("a", encoding="utf-8") as fh:
                fh.write(",".join(f"{v:.6g}" for v in row) + "\n")
            if row[4] == row[4]:  # not NaN
                self.bar.set_postfix({"return": f"{row[3]:.2f}", "SR": f"{row[4]:.2f}"})

        def _on_training_end(self) -> None:
            self.bar.close()

    return _Curve()


def train_sb3_ppo(
    scenario: str,
    out_dir: str | Path,
    steps: int,
    n_envs: int = 1,
    seed: int = 0,
    progress: bool = True,
    command: str = "",
) -> dict[str, Any]:
    """Train SB3's PPO (its defaults) on ``scenario``'s Gymnasium environment; returns the
    summary written to ``train.json``. A folder that holds a finished or partial run is
    refused (SB3's state cannot be resumed without pickles)."""
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    for name, value in (("steps", steps), ("n_envs", n_envs)):
        if value < 1:
            raise ConfigError(expect(f"sb3-ppo {name}", "an integer >= 1", value, "raise it"))
    out = output_dir_kind(out_dir)
    _check_fresh(out)
    register_envs()
    env_id, kwargs = env_id_for(scenario)
    gym.spec(env_id)  # an unknown id fails here, before any work
    torch.set_num_threads(1)
    venv = make_vec_env(env_id, n_envs=n_envs, seed=seed, env_kwargs=kwargs)
    model = PPO("MlpPolicy", venv, seed=seed, device="cpu", verbose=0)
    with run_lock(out):  # created only now: a refused run leaves nothing behind
        _check_fresh(out)
        return _learn(
            model, venv, out, (scenario, env_id), (steps, n_envs, seed), progress, command
        )


def _check_fresh(out: Path) -> None:
    if (out / "curve.csv").exists() or (out / "policy.safetensors").exists():
        raise ConfigError(
            expect("--out", "a folder without an SB3 run", str(out), "use a new --out")
        )


def _learn(
    model: Any,
    venv: Any,
    out: Path,
    names: tuple[str, str],
    counts: tuple[int, int, int],
    progress: bool,
    command: str,
) -> dict[str, Any]:
    """Train ``model`` for ``counts`` = (steps, environments, seed) and write the outputs into
    ``out``; returns the summary."""
    import stable_baselines3

    scenario, env_id = names
    steps, n_envs, seed = counts
    (out / "curve.csv").write_text(",".join(CURVE_COLUMNS) + "\n", encoding="utf-8")
    callback = _make_callback(out, steps, progress)
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps, callback=callback)
    wall = time.perf_counter() - t0
    venv.close()
    rows = callback.rows
    last = rows[-1] if rows else [np.nan] * len(CURVE_COLUMNS)
    hyper = {
        k: getattr(model, k)
        for k in ("n_steps", "batch_size", "n_epochs", "gamma", "gae_lambda", "ent_coef")
    }
    summary = {
        "scenario": scenario,
        "env_id": env_id,
        "command": command,
        "env_steps": int(model.num_timesteps),
        "episodes": callback.episodes,
        "wall_time_s": round(wall, 1),
        "steps_per_s": model.num_timesteps / max(wall, 1e-9),
        "final": dict(zip(CURVE_COLUMNS[3:7], last[3:7], strict=True)),
        "sb3": {
            "version": stable_baselines3.__version__,
            "algorithm": "PPO",
            "policy": "MlpPolicy",
            "n_envs": n_envs,
            "seed": seed,
            "learning_rate": float(model.learning_rate)
            if isinstance(model.learning_rate, float)
            else "schedule",
            "clip_range": float(model.clip_range(1.0))
            if callable(model.clip_range)
            else float(model.clip_range),
            **hyper,
        },
    }
    _save_policy(model.policy, out / "policy.safetensors", summary)
    arr = np.asarray(rows, dtype=np.float64).reshape(-1, len(CURVE_COLUMNS))
    from pioneer.viz.plots import plot_learning_curve

    plot_learning_curve(
        {c: arr[:, i] for i, c in enumerate(CURVE_COLUMNS)},
        out / "curve.png",
        title=f"Stable-Baselines3 PPO · {scenario}",
    )
    write_text_atomic(out / "train.json", to_json(summary, indent=2) + "\n")
    return summary


def _box(space: Any) -> dict[str, list[float]]:
    return {"low": space.low.tolist(), "high": space.high.tolist()}


def _save_policy(policy: Any, path: Path, info: Mapping[str, Any]) -> None:
    from pioneer.nn.checkpoint import write_checkpoint

    config = {
        "net_arch": policy.net_arch,
        "activation_fn": policy.activation_fn.__name__,
        "observation_space": _box(policy.observation_space),
        "action_space": _box(policy.action_space),
    }
    write_checkpoint(policy, config, path, SB3_FORMAT, info)


# ------------------------------------------------------------------------------ the policy
class Sb3Policy:
    """A PPO policy trained by :func:`train_sb3_ppo`, acting on the 29-D observation alone."""

    def __init__(self, policy: Any, name: str = "sb3-ppo") -> None:
        self.policy = policy
        self.name = name

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Nothing to reset (a feed-forward policy)."""

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """The mean action, clipped to the action space (as SB3's ``predict``)."""
        action, _ = self.policy.predict(np.asarray(obs, dtype=np.float32), deterministic=True)
        return np.asarray(action, dtype=np.float64).reshape(2)


def _obs_dim(scenario: str | None) -> int:
    """The width of the observation the policy is given (its scenario's LiDAR's)."""
    from pioneer.sim.lidar import OBS_DIM
    from pioneer.sim.scenarios import get_scenario

    return get_scenario(scenario).sim.lidar.obs_dim if scenario is not None else OBS_DIM


def make_sb3_policy(weights: str, scenario: str | None = None, name: str = "sb3-ppo") -> Sb3Policy:
    """Policy factory: the SB3 policy in ``weights`` (a ``policy.safetensors`` written by
    ``pioneer train sb3-ppo``; ``{scenario}`` is filled in)."""
    import gymnasium as gym
    import torch
    from stable_baselines3.common.policies import ActorCriticPolicy

    from pioneer.nn.checkpoint import load_checked, read_checkpoint

    p = Path(weights.format(scenario=scenario) if scenario else weights)
    fix = "train one with `pioneer train sb3-ppo --out DIR` and pass weights=DIR/policy.safetensors"
    meta, arrays = read_checkpoint(p, SB3_FORMAT, "sb3-ppo weights", fix, fix, tensors=True)
    cfg = meta["config"]
    try:
        spaces = [
            gym.spaces.Box(
                np.array(cfg[k]["low"], dtype=np.float32),
                np.array(cfg[k]["high"], dtype=np.float32),
            )
            for k in ("observation_space", "action_space")
        ]
        policy = ActorCriticPolicy(
            spaces[0],
            spaces[1],
            lr_schedule=lambda _: 0.0,
            net_arch=cfg["net_arch"],
            activation_fn=getattr(torch.nn, cfg["activation_fn"]),
        )
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise DataError(expect(f"{p}: config", "an SB3 policy config", f"{exc}", fix)) from exc
    wanted = (_obs_dim(scenario),)
    if spaces[0].shape != wanted:
        raise DataError(expect(f"{p}: observation_space", f"shape {wanted}", spaces[0].shape, fix))
    load_checked(policy, arrays, p, f"SB3 MlpPolicy {cfg['net_arch']}", fix)
    policy.set_training_mode(False)
    torch.set_num_threads(1)
    return Sb3Policy(policy, name=name)
