"""Training SB3's PPO on a Gymnasium environment of PioneeR, resumable (what it does, what it
writes and how it resumes: :mod:`pioneer.baselines.sb3`)."""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from pioneer.baselines.sb3.checkpoint import (
    CHECKPOINT,
    CURVE_COLUMNS,
    CurveState,
    read_state,
    restore,
    save_policy,
    save_state,
)
from pioneer.errors import ConfigError, expect
from pioneer.interrupt import Interrupted, deferred
from pioneer.io import (
    output_dir_kind,
    remove_partial_writes,
    run_lock,
    to_json,
    write_text_atomic,
)
from pioneer.nn.ppo import curve_columns
from pioneer.registration import ENV_IDS, register_envs
from pioneer.reward.crowdnav import REWARDS, RewardName

__all__ = ["env_id_for", "train_sb3_ppo"]

WINDOW = 100  # finished episodes in the curve's running statistics
_FALLBACK_ID = "pioneer/ElevatorHRRL-v1"  # any registered id; ``scenario=`` picks the world
# The settings a checkpoint and a resuming command must share, with their flags.
_FLAGS = {
    "scenario": "--scenario",
    "env_id": "env_id",
    "n_envs": "--envs",
    "seed": "--seed",
    "reward": "--reward",
}
_UNSTORED = {"reward": "crowdnav"}  # a setting absent from the settings when it has this value


def env_id_for(scenario: str) -> tuple[str, dict[str, Any]]:
    """The Gymnasium id (and keyword arguments) that make ``scenario``'s environment."""
    by_scenario = {name: env_id for env_id, name in ENV_IDS.items()}
    if scenario in by_scenario:
        return by_scenario[scenario], {}
    return _FALLBACK_ID, {"scenario": scenario}


def _env_seed(seed: int, steps: int) -> int:
    """The environments' seed when training (re)starts at ``steps`` (environment i gets it + i,
    SB3's rule): ``seed`` at step 0, as in a fresh run; at a resume one derived from both, so
    that the restarted episodes, and the resumed run, are reproducible."""
    if steps == 0:
        return seed
    return int(np.random.SeedSequence([seed, steps]).generate_state(1)[0])


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


def _csv_line(row: list[float]) -> str:
    """A learning-curve row as ``curve.csv`` holds it (the counts as integers)."""
    return ",".join([*(str(int(v)) for v in row[:3]), *(f"{v:.6g}" for v in row[3:])]) + "\n"


def _make_callback(
    out: Path, curve: CurveState, bar: Any, checkpoint: Callable[[float], None]
) -> Any:
    """An SB3 callback that keeps the learning curve (appended to ``curve.csv`` after every
    rollout) and the progress bar, and holds signals from the end of a rollout until the
    update that follows it is checkpointed (``checkpoint(elapsed)``, as the next rollout
    starts): an update is never cut in two and a stopped run keeps every finished one."""
    from stable_baselines3.common.callbacks import BaseCallback

    class _Curve(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.t0 = time.perf_counter() - curve.wall
            self.held = contextlib.ExitStack()  # the deferred() block of the update under way
            self.saved = -1  # SB3's _n_updates at the last checkpoint

        def elapsed(self) -> float:
            return time.perf_counter() - self.t0

        def save(self) -> None:
            """Write the checkpoint if the model trained since the last one."""
            if self.model._n_updates != self.saved:
                checkpoint(self.elapsed())
                self.saved = self.model._n_updates

        def _on_training_start(self) -> None:
            self.saved = self.model._n_updates  # the state the run started from is on disk

        def _on_rollout_start(self) -> None:
            self.save()
            self.held.close()  # a signal held during the update stops the run here

        def _on_step(self) -> bool:
            infos = self.locals.get("infos", [])
            for info in infos:
                ep = info.get("episode")
                if ep is not None:
                    curve.episodes += 1
                    curve.window = [*curve.window, (float(ep["r"]), str(info["event"]))][-WINDOW:]
            bar.update(len(infos))
            return True

        def _on_rollout_end(self) -> None:
            self.held.enter_context(deferred())  # until the update is checkpointed
            row = _curve_row(
                len(curve.rows) + 1,
                int(self.num_timesteps),
                curve.episodes,
                curve.window,
                self.elapsed(),
            )
            curve.rows.append(row)
            with (out / "curve.csv").open("a", encoding="utf-8") as fh:
                fh.write(_csv_line(row))
            if row[4] == row[4]:  # not NaN
                bar.set_postfix({"return": f"{row[3]:.2f}", "SR": f"{row[4]:.2f}"})

    return _Curve()


def train_sb3_ppo(
    scenario: str,
    out_dir: str | Path,
    steps: int,
    n_envs: int = 1,
    seed: int = 0,
    resume: bool | None = None,
    progress: bool = True,
    command: str = "",
    reward: RewardName = "crowdnav",
) -> dict[str, Any]:
    """Train (or resume) SB3's PPO (its defaults) on ``scenario``'s Gymnasium environment up
    to ``steps`` environment steps in all; returns the summary written to ``train.json``.
    ``reward``: the environment's own, the CrowdNav++ reward (``"crowdnav"``), or another of
    :data:`pioneer.reward.crowdnav.REWARDS` passed to the environment.

    ``resume``: ``None`` continues from ``out/checkpoint.safetensors`` if there is one,
    ``True`` requires it, ``False`` refuses an ``out`` that holds one (nothing is deleted).
    Every setting is checked before ``out`` is created or changed; one run writes to it at a
    time (:func:`pioneer.io.run_lock`).
    """
    import gymnasium as gym
    import torch

    for name, value in (("steps", steps), ("n_envs", n_envs)):
        if value < 1:
            raise ConfigError(expect(f"sb3-ppo {name}", "an integer >= 1", value, "raise it"))
    out = output_dir_kind(out_dir)
    register_envs()
    env_id, kwargs = env_id_for(scenario)
    gym.spec(env_id)  # an unknown id fails here, before any work
    settings: dict[str, Any] = {
        "scenario": scenario,
        "env_id": env_id,
        "steps": steps,
        "n_envs": n_envs,
        "seed": seed,
    }
    if reward != _UNSTORED["reward"]:  # absent for the environment's own: older runs resume
        kwargs = {**kwargs, "reward": REWARDS[reward]}
        settings["reward"] = reward
    _check_out(out, resume, settings)
    torch.set_num_threads(1)
    model, venv = _build(env_id, kwargs, n_envs, seed)
    # the lock, and with it the folder, is created only now: a refused run leaves nothing behind
    with contextlib.closing(venv), run_lock(out):
        resuming = _check_out(out, resume, settings)  # again, holding the lock
        return _learn(model, out, settings, resuming, progress, command)


def _build(env_id: str, kwargs: Mapping[str, Any], n_envs: int, seed: int) -> tuple[Any, Any]:
    """SB3's vector environment and ``PPO("MlpPolicy")`` as a fresh run makes them."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.logger import Logger

    venv = make_vec_env(env_id, n_envs=n_envs, seed=seed, env_kwargs=dict(kwargs))
    model = PPO("MlpPolicy", venv, seed=seed, device="cpu", verbose=0)
    # a logger of its own: SB3's default makes an empty folder /tmp/SB3-<time> on every learn()
    model.set_logger(Logger(folder=None, output_formats=[]))
    return model, venv


def _check_out(out: Path, resume: bool | None, settings: Mapping[str, Any]) -> bool:
    """Whether the run resumes from ``out``'s checkpoint: one there with the same settings
    (except ``steps``); refuses ``--resume`` without one, a fresh start (``resume=False``) with
    one, other settings, and a run written before checkpoints (``policy.safetensors`` alone)."""
    ckpt = out / CHECKPOINT
    if not ckpt.is_file():
        if resume is True:
            raise ConfigError(
                expect(
                    "--resume", f"a checkpoint at {ckpt}", "none", "drop --resume to start afresh"
                )
            )
        if (out / "policy.safetensors").exists() or (out / "curve.csv").exists():
            raise ConfigError(
                expect(
                    "--out",
                    f"a new folder or an SB3 run with its {CHECKPOINT}",
                    f"{out}: a run without one (made before SB3 runs were resumable)",
                    "use a new --out (that run cannot be continued)",
                )
            )
        return False
    if resume is False:
        raise ConfigError(
            expect("--out", "a folder without a checkpoint", str(out), "resume or use a new --out")
        )
    stored = json.loads(read_state(ckpt, tensors=False)[0]["settings"])
    diff = [k for k in _FLAGS if stored.get(k) != settings.get(k)]
    if diff:
        was = {_FLAGS[k]: stored.get(k, _UNSTORED.get(k)) for k in diff}
        raise ConfigError(
            expect(
                f"{ckpt}: settings",
                f"the checkpoint's {was} (only --steps may change)",
                {_FLAGS[k]: settings.get(k, _UNSTORED.get(k)) for k in diff},
                "repeat the original command's settings or use a new --out",
            )
        )
    return True


def _learn(
    model: Any,
    out: Path,
    settings: Mapping[str, Any],
    resuming: bool,
    progress: bool,
    command: str,
) -> dict[str, Any]:
    """Train ``model`` (from ``out``'s checkpoint when ``resuming``) up to ``settings["steps"]``
    and write the outputs into ``out``; returns the summary."""
    from pioneer.progress import progress_bar

    ckpt = out / CHECKPOINT
    steps, seed = int(settings["steps"]), int(settings["seed"])
    if resuming:
        curve = restore(ckpt, model)
        remove_partial_writes(out)  # the temporary file of a write that was killed
        model.env.seed(_env_seed(seed, model.num_timesteps))  # episodes restart (docstring)
    else:
        curve = CurveState()
        save_state(ckpt, model, curve, 0.0, settings)  # from now on, the folder is a run
    resumed_from = model.num_timesteps if resuming else None
    # curve.csv as the checkpoint has it (a killed run may have appended a row after it)
    write_text_atomic(
        out / "curve.csv", ",".join(CURVE_COLUMNS) + "\n" + "".join(map(_csv_line, curve.rows))
    )
    per_update = model.n_steps * model.n_envs
    updates = -(-steps // per_update)
    bar = progress_bar(
        total=updates * per_update,
        initial=model.num_timesteps,
        unit="step",
        desc="sb3-ppo",
        enabled=progress,
    )
    saved_rows = len(curve.rows)

    def checkpointed(wall: float) -> None:
        nonlocal saved_rows
        save_state(ckpt, model, curve, wall, settings)
        saved_rows = len(curve.rows)

    callback = _make_callback(out, curve, bar, checkpointed)
    t0, s0 = time.perf_counter(), model.num_timesteps
    try:
        with callback.held:  # the last update's deferred() block ends here
            if model.num_timesteps < steps:
                # SB3 adds num_timesteps to total_timesteps when it does not reset them
                model.learn(
                    total_timesteps=steps - model.num_timesteps,
                    reset_num_timesteps=False,
                    callback=callback,
                )
                callback.save()
                curve.wall = callback.elapsed()
        summary = _summary(model, settings, curve, command, resumed_from)
        summary["steps_per_s"] = (model.num_timesteps - s0) / max(time.perf_counter() - t0, 1e-9)
        _write_outputs(model, out, summary, curve)
    except Interrupted as exc:  # between two updates (they run deferred): keep every one
        info = _summary(model, settings, curve, command, resumed_from)
        save_policy(model.policy, out / "policy.safetensors", info)
        exc.kept = f"update {saved_rows} of {updates} kept in {ckpt}"
        raise
    finally:
        bar.close()
    return summary


def _summary(
    model: Any,
    settings: Mapping[str, Any],
    curve: CurveState,
    command: str,
    resumed_from: int | None,
) -> dict[str, Any]:
    import stable_baselines3

    last = curve.rows[-1] if curve.rows else [np.nan] * len(CURVE_COLUMNS)
    hyper = {
        k: getattr(model, k)
        for k in ("n_steps", "batch_size", "n_epochs", "gamma", "gae_lambda", "ent_coef")
    }
    return {
        "scenario": settings["scenario"],
        "env_id": settings["env_id"],
        "reward": settings.get("reward", _UNSTORED["reward"]),
        "command": command,
        "env_steps": int(model.num_timesteps),
        "updates": len(curve.rows),
        "episodes": curve.episodes,
        "wall_time_s": round(curve.wall, 1),
        "resumed_from_steps": resumed_from,
        "final": dict(zip(CURVE_COLUMNS[3:7], last[3:7], strict=True)),
        "sb3": {
            "version": stable_baselines3.__version__,
            "algorithm": "PPO",
            "policy": "MlpPolicy",
            "n_envs": settings["n_envs"],
            "seed": settings["seed"],
            "learning_rate": float(model.learning_rate)
            if isinstance(model.learning_rate, float)
            else "schedule",
            "clip_range": float(model.clip_range(1.0))
            if callable(model.clip_range)
            else float(model.clip_range),
            **hyper,
        },
    }


def _write_outputs(model: Any, out: Path, summary: dict[str, Any], curve: CurveState) -> None:
    from pioneer.viz.plots import plot_learning_curve

    save_policy(model.policy, out / "policy.safetensors", summary)
    plot_learning_curve(
        curve_columns(CURVE_COLUMNS, curve.rows),
        out / "curve.png",
        title=f"Stable-Baselines3 PPO · {summary['scenario']}",
    )
    write_text_atomic(out / "train.json", to_json(summary, indent=2) + "\n")
