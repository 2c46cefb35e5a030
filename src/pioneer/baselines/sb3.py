"""Stable-Baselines3 PPO on the Gymnasium environments, as a user of Gymnasium would train it.

``train_sb3_ppo`` makes ``pioneer/ElevatorHRRL-v1`` (or ``…HLRR-v1``; other scenarios through the
``scenario`` keyword) with ``stable_baselines3.common.env_util.make_vec_env``, trains SB3's
``PPO("MlpPolicy")`` with SB3's default hyperparameters on the environment's own reward (the
29-D LiDAR observation, absolute (v, ω) actions; ``reward="no-intrusion"`` passes the
CrowdNav++ reward without its intrusion term to the environments instead), and writes (each
file atomically, except the appended curve)

- ``policy.safetensors``: the policy network's tensors, with the SB3 version, the network
  architecture, the spaces and the training settings as JSON metadata. SB3's own ``.zip``
  holds pickles, which this project never asks a user to load, so it is not written;
- ``checkpoint.safetensors``: the training state, when training starts, after every PPO update
  (as the next rollout starts) and at the end: the policy's tensors, Adam's moments and step
  counts (one named tensor each), torch's global RNG state and the state of numpy's global
  RNG (SB3 draws its minibatches from it; the key array as a tensor), and as JSON the
  settings, SB3's ``num_timesteps`` and ``_n_updates`` and the learning curve's running state
  (its rows, the episode count, the window of (return, event) pairs, the elapsed time).
  Safetensors and JSON only: loading it runs no code;
- ``curve.csv`` (appended after every rollout), ``curve.png`` and ``train.json``.

``make_sb3_policy`` rebuilds the policy from that file (no pickle) as the registry's
``sb3-ppo`` policy; it acts on the observation alone with the Gaussian's mean.

Resuming: running the same command on an ``--out`` that holds a run continues from its
checkpoint (``--resume`` insists on one) up to ``--steps`` in all; ``curve.csv`` keeps its
rows and is appended to. A larger ``--steps`` extends a finished run; any other setting
(scenario, environments, seed, reward) must match the checkpoint's, otherwise the command is refused
(use a new ``--out``), as is a folder written before runs were resumable (a
``policy.safetensors`` without a checkpoint). Nothing is deleted. Ctrl-C or SIGTERM during an
update lets it finish and writes the checkpoint; during a rollout it stops at once (the
checkpoint written as that rollout started holds everything, and the rollout is collected
again). The run then prints what it kept and the command that resumes it.

A resumed run continues with the same weights, optimizer state, step count and RNG states,
but it is not bit-identical to an uninterrupted one: SB3's vector environment cannot save the
episodes in progress, so the environments restart their episodes at the resume. Their seeds
then come from the seed and ``num_timesteps`` (:func:`_env_seed`; at step 0 the seed itself,
as in a fresh run), so a resumed run is itself reproducible: the same sequence of commands
gives the same weights bit for bit.

Needs the ``sb3`` extra: ``pip install pioneer-nav[sb3]``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.baselines.crowdnav.trainer import CURVE_COLUMNS as PPO_CURVE_COLUMNS
from pioneer.errors import ConfigError, DataError, expect
from pioneer.interrupt import Interrupted, deferred
from pioneer.io import (
    atomic_path,
    output_dir_kind,
    remove_partial_writes,
    run_lock,
    to_json,
    write_text_atomic,
)
from pioneer.registration import ENV_IDS, register_envs
from pioneer.reward.crowdnav import REWARDS, RewardName

__all__ = [
    "CHECKPOINT",
    "CURVE_COLUMNS",
    "SB3_FORMAT",
    "TRAIN_FORMAT",
    "Sb3Policy",
    "env_id_for",
    "make_sb3_policy",
    "train_sb3_ppo",
]

SB3_FORMAT = "pioneer.sb3-ppo/1"
TRAIN_FORMAT = "pioneer.sb3-ppo-train/1"  # checkpoint.safetensors
CHECKPOINT = "checkpoint.safetensors"
# the CrowdNav++ trainer's learning-curve columns, counted in SB3 rollouts instead of updates
CURVE_COLUMNS = ("rollout", *PPO_CURVE_COLUMNS[1:])
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


@dataclasses.dataclass
class _CurveState:
    """The learning curve's running state (kept in the checkpoint)."""

    rows: list[list[float]] = dataclasses.field(default_factory=list)
    episodes: int = 0
    window: list[tuple[float, str]] = dataclasses.field(default_factory=list)
    wall: float = 0.0  # [s] of training before this process


def _make_callback(
    out: Path, curve: _CurveState, bar: Any, checkpoint: Callable[[float], None]
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

    venv = make_vec_env(env_id, n_envs=n_envs, seed=seed, env_kwargs=dict(kwargs))
    return PPO("MlpPolicy", venv, seed=seed, device="cpu", verbose=0), venv


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
    stored = json.loads(_read_state(ckpt, tensors=False)[0]["settings"])
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


# ------------------------------------------------------------------------------ checkpoint
def _save_state(
    path: Path, model: Any, curve: _CurveState, wall: float, settings: Mapping[str, Any]
) -> None:
    """The training state of ``model`` and the curve (at ``wall`` seconds of training) to
    ``path``: safetensors + JSON metadata, atomically (see the module docstring)."""
    import stable_baselines3
    import torch
    from safetensors.torch import save

    from pioneer.nn.checkpoint import optimizer_tensors

    tensors: dict[str, torch.Tensor] = {
        f"policy/{k}": v.detach().cpu().clone().contiguous()
        for k, v in model.policy.state_dict().items()
    }
    osd = model.policy.optimizer.state_dict()
    tensors.update(optimizer_tensors(osd, "optim"))
    tensors["rng/torch"] = torch.get_rng_state()
    rng = np.random.get_state(legacy=False)  # noqa: NPY002 (SB3's generator: saved, not drawn)
    if not isinstance(rng, dict):
        raise TypeError("numpy returned its legacy RNG state")
    tensors["rng/numpy_key"] = torch.from_numpy(rng["state"]["key"].astype(np.int64))
    tensors["curve"] = torch.tensor(curve.rows, dtype=torch.float64).reshape(-1, len(CURVE_COLUMNS))
    meta = {
        "format": TRAIN_FORMAT,
        "settings": json.dumps(dict(settings)),
        "counters": json.dumps(
            {"num_timesteps": int(model.num_timesteps), "n_updates": int(model._n_updates)}
        ),
        "curve": json.dumps(
            {
                "rows": len(curve.rows),
                "episodes": curve.episodes,
                "window": [[r, e] for r, e in curve.window],
                "wall_time_s": wall,
            }
        ),
        "param_groups": json.dumps(osd["param_groups"]),
        "rng_numpy": json.dumps(
            {
                "bit_generator": rng["bit_generator"],
                "pos": int(rng["state"]["pos"]),
                "has_gauss": int(rng["has_gauss"]),
                "gauss": float(rng["gauss"]),
            }
        ),
        "sb3": stable_baselines3.__version__,
        "torch": torch.__version__,
    }
    with atomic_path(path) as tmp:  # bytes, not save_file: that makes the file mode 0600
        tmp.write_bytes(save(tensors, metadata=meta))


_FIX = "use a new --out (the checkpoint is corrupt or of another kind)"


def _read_state(path: Path, tensors: bool) -> tuple[dict[str, str], dict[str, Any]]:
    """The metadata (and with ``tensors`` the tensors) of the checkpoint at ``path``; one that
    cannot be read or is of another format raises one :class:`DataError`."""
    from pioneer.nn.checkpoint import read_training_state

    meta, arrays = read_training_state(path, TRAIN_FORMAT, _FIX, tensors)
    try:
        if not isinstance(json.loads(meta["settings"]), dict):
            raise ValueError("not an object")
    except (KeyError, ValueError) as exc:  # JSONDecodeError is a ValueError
        raise DataError(
            expect(f"{path}: metadata", "JSON 'settings'", "missing/invalid", _FIX)
        ) from exc
    return meta, arrays


def _restore(path: Path, model: Any) -> _CurveState:
    """Load the training state at ``path`` into ``model`` (built with the checkpoint's settings)
    and the global RNGs; returns the curve's state. A file that does not fit raises one
    :class:`DataError`."""
    import torch

    from pioneer.nn.checkpoint import optimizer_state

    meta, t = _read_state(path, tensors=True)
    try:
        model.policy.load_state_dict(
            {k.removeprefix("policy/"): v for k, v in t.items() if k.startswith("policy/")},
            strict=True,
        )
        groups = json.loads(meta["param_groups"])
        model.policy.optimizer.load_state_dict(optimizer_state(t, "optim", groups))
        torch.set_rng_state(t["rng/torch"])
        rng = json.loads(meta["rng_numpy"])
        np.random.set_state(  # noqa: NPY002 (SB3's generator: restored, not drawn)
            {
                "bit_generator": rng["bit_generator"],
                "state": {"key": t["rng/numpy_key"].numpy().astype(np.uint32), "pos": rng["pos"]},
                "has_gauss": rng["has_gauss"],
                "gauss": rng["gauss"],
            }
        )
        counters = json.loads(meta["counters"])
        model.num_timesteps = int(counters["num_timesteps"])
        model._n_updates = int(counters["n_updates"])
        c = json.loads(meta["curve"])
        curve = _CurveState(
            rows=t["curve"].tolist(),
            episodes=int(c["episodes"]),
            window=[(float(r), str(e)) for r, e in c["window"]],
            wall=float(c["wall_time_s"]),
        )
    except (KeyError, ValueError, TypeError, RuntimeError) as exc:  # JSON errors: ValueError
        raise DataError(
            expect(f"{path}: training state", "SB3 PPO's (MlpPolicy, Adam)", f"{exc}", _FIX)
        ) from exc
    return curve


# ------------------------------------------------------------------------------ training
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
        curve = _restore(ckpt, model)
        remove_partial_writes(out)  # the temporary file of a write that was killed
        model.env.seed(_env_seed(seed, model.num_timesteps))  # episodes restart (docstring)
    else:
        curve = _CurveState()
        _save_state(ckpt, model, curve, 0.0, settings)  # from now on, the folder is a run
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
        _save_state(ckpt, model, curve, wall, settings)
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
        _save_policy(model.policy, out / "policy.safetensors", info)
        exc.kept = f"update {saved_rows} of {updates} kept in {ckpt}"
        raise
    finally:
        bar.close()
    return summary


def _summary(
    model: Any,
    settings: Mapping[str, Any],
    curve: _CurveState,
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


def _write_outputs(model: Any, out: Path, summary: dict[str, Any], curve: _CurveState) -> None:
    from pioneer.viz.plots import plot_learning_curve

    _save_policy(model.policy, out / "policy.safetensors", summary)
    arr = np.asarray(curve.rows, dtype=np.float64).reshape(-1, len(CURVE_COLUMNS))
    plot_learning_curve(
        {c: arr[:, i] for i, c in enumerate(CURVE_COLUMNS)},
        out / "curve.png",
        title=f"Stable-Baselines3 PPO · {summary['scenario']}",
    )
    write_text_atomic(out / "train.json", to_json(summary, indent=2) + "\n")


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
    """A PPO policy trained by :func:`train_sb3_ppo`, acting on the 29-D observation alone.

    It acts as SB3's ``predict(obs, deterministic=True)`` does — the Gaussian's mean from the
    actor's network, clipped to the action space — by calling the same modules directly: the
    same operators on the same values (the tests compare both), without ``predict``'s
    per-call mode switch and input checks, which cost more than the 29 → 64 → 64 → 2 network.
    """

    def __init__(self, policy: Any, name: str = "sb3-ppo") -> None:
        import torch

        self.policy = policy
        self.name = name
        self._torch = torch
        self._low = policy.action_space.low
        self._high = policy.action_space.high

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Nothing to reset (a feed-forward policy)."""

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """The mean action, clipped to the action space (as SB3's ``predict``)."""
        p = self.policy
        x = self._torch.from_numpy(np.asarray(obs, dtype=np.float32).reshape(1, -1))
        with self._torch.inference_mode():
            features = p.extract_features(x, p.pi_features_extractor)
            mean = p.action_net(p.mlp_extractor.forward_actor(features))
        action = np.clip(mean.numpy().reshape(-1), self._low, self._high)
        return action.astype(np.float64)


def _obs_dim(scenario: str | None) -> int:
    """The width of the observation the policy is given (its scenario's LiDAR's)."""
    from pioneer.sim.lidar import OBS_DIM
    from pioneer.sim.scenarios import get_scenario

    return get_scenario(scenario).sim.lidar.obs_dim if scenario is not None else OBS_DIM


def make_sb3_policy(
    weights: str | None = None, scenario: str | None = None, name: str = "sb3-ppo"
) -> Sb3Policy:
    """Policy factory: the SB3 policy in ``weights`` (a ``policy.safetensors`` written by
    ``pioneer train sb3-ppo``; ``{scenario}`` is filled in), or the scenario's shipped one."""
    import gymnasium as gym
    import torch
    from stable_baselines3.common.policies import ActorCriticPolicy

    from pioneer.nn.checkpoint import load_checked, read_checkpoint

    if weights is None:
        if scenario is None:
            raise ConfigError(
                expect("sb3-ppo", "weights=FILE or a scenario", None, "pass scenario='hr-rl'")
            )
        from pioneer.data import shipped_sb3_weights

        p = shipped_sb3_weights(scenario)
    else:
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
