"""The files of an SB3 run (:mod:`pioneer.baselines.sb3`): ``policy.safetensors`` (the policy's
tensors, its architecture and spaces as JSON) and ``checkpoint.safetensors``, the training
state written after every update and restored on resume: the policy's tensors, Adam's state,
torch's and numpy's global RNGs (SB3 draws from them), SB3's counters and the learning curve's
running state. Safetensors and JSON only: loading runs no code."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from pioneer.baselines.crowdnav.trainer import CURVE_COLUMNS as PPO_CURVE_COLUMNS
from pioneer.errors import DataError, expect

__all__ = [
    "CHECKPOINT",
    "CURVE_COLUMNS",
    "SB3_FORMAT",
    "TRAIN_FORMAT",
    "CurveState",
    "read_state",
    "restore",
    "save_policy",
    "save_state",
]

SB3_FORMAT = "pioneer.sb3-ppo/1"  # policy.safetensors
TRAIN_FORMAT = "pioneer.sb3-ppo-train/1"  # checkpoint.safetensors
CHECKPOINT = "checkpoint.safetensors"
# the CrowdNav++ trainer's learning-curve columns, counted in SB3 rollouts instead of updates
CURVE_COLUMNS = ("rollout", *PPO_CURVE_COLUMNS[1:])


@dataclasses.dataclass
class CurveState:
    """The learning curve's running state (kept in the checkpoint)."""

    rows: list[list[float]] = dataclasses.field(default_factory=list)
    episodes: int = 0
    window: list[tuple[float, str]] = dataclasses.field(default_factory=list)
    wall: float = 0.0  # [s] of training before this process


def save_state(
    path: Path, model: Any, curve: CurveState, wall: float, settings: Mapping[str, Any]
) -> None:
    """The training state of ``model`` and the curve (at ``wall`` seconds of training) to
    ``path``: safetensors + JSON metadata, atomically (see the module docstring)."""
    import stable_baselines3
    import torch

    from pioneer.nn.checkpoint import write_training_state

    rng = np.random.get_state(legacy=False)  # noqa: NPY002 (SB3's generator: saved, not drawn)
    if not isinstance(rng, dict):
        raise TypeError("numpy returned its legacy RNG state")
    tensors = {
        "rng/torch": torch.get_rng_state(),
        "rng/numpy_key": torch.from_numpy(rng["state"]["key"].astype(np.int64)),
        "curve": torch.tensor(curve.rows, dtype=torch.float64).reshape(-1, len(CURVE_COLUMNS)),
    }
    write_training_state(
        path,
        TRAIN_FORMAT,
        modules={"policy": model.policy},
        optimizers={"optim": model.policy.optimizer},
        tensors=tensors,
        meta={
            "settings": dict(settings),
            "counters": {
                "num_timesteps": int(model.num_timesteps),
                "n_updates": int(model._n_updates),
            },
            "curve": {
                "rows": len(curve.rows),
                "episodes": curve.episodes,
                "window": [[r, e] for r, e in curve.window],
                "wall_time_s": wall,
            },
            "rng_numpy": {
                "bit_generator": rng["bit_generator"],
                "pos": int(rng["state"]["pos"]),
                "has_gauss": int(rng["has_gauss"]),
                "gauss": float(rng["gauss"]),
            },
            "sb3": stable_baselines3.__version__,
        },
    )


_FIX = "use a new --out (the checkpoint is corrupt or of another kind)"


def read_state(path: Path, tensors: bool) -> tuple[dict[str, str], dict[str, Any]]:
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


def restore(path: Path, model: Any) -> CurveState:
    """Load the training state at ``path`` into ``model`` (built with the checkpoint's settings)
    and the global RNGs; returns the curve's state. A file that does not fit raises one
    :class:`DataError`."""
    import torch

    from pioneer.nn.checkpoint import restore_optimizer

    meta, t = read_state(path, tensors=True)
    try:
        model.policy.load_state_dict(
            {k.removeprefix("policy/"): v for k, v in t.items() if k.startswith("policy/")},
            strict=True,
        )
        restore_optimizer(model.policy.optimizer, t, meta, "optim")
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
        curve = CurveState(
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


def _box(space: Any) -> dict[str, list[float]]:
    return {"low": space.low.tolist(), "high": space.high.tolist()}


def save_policy(policy: Any, path: Path, info: Mapping[str, Any]) -> None:
    from pioneer.nn.checkpoint import write_checkpoint

    config = {
        "net_arch": policy.net_arch,
        "activation_fn": policy.activation_fn.__name__,
        "observation_space": _box(policy.observation_space),
        "action_space": _box(policy.action_space),
    }
    write_checkpoint(policy, config, path, SB3_FORMAT, info)
