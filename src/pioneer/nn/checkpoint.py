"""Safetensors checkpoints of torch modules with a typed config: one writer and one reader for
the students and CrowdNav++ (weights as tensors; format tag, config and free-form ``info`` as
JSON in the file's metadata — loading cannot execute code). For the resumable trainers
(CrowdNav++'s PPO, the students' fine-tuning, SB3's PPO): the one training-state writer and
reader, and an optimizer's state as named tensors."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

import torch
from torch import nn

from pioneer.config import Config
from pioneer.errors import DataError, PioneerError, expect
from pioneer.io import atomic_path, to_json

__all__ = [
    "load_checked",
    "optimizer_state",
    "optimizer_tensors",
    "read_checkpoint",
    "read_training_state",
    "restore_optimizer",
    "stored_config",
    "write_checkpoint",
    "write_training_state",
]

M = TypeVar("M", bound=nn.Module)
C = TypeVar("C", bound=Config)


def stored_config(p: Path, meta: Mapping[str, Any], cls: type[C], fix: str) -> C:
    """The ``cls`` config stored in a checkpoint's metadata; an invalid one raises one
    :class:`DataError` naming the file."""
    try:
        return cls.from_dict(meta["config"])
    except PioneerError as exc:
        raise DataError(expect(f"{p}: config", f"a valid {cls.__name__}", str(exc), fix)) from exc


def write_checkpoint(
    model: nn.Module,
    config: Mapping[str, Any],
    path: str | Path,
    fmt: str,
    info: Mapping[str, Any] | None = None,
) -> Path:
    """Write ``model``'s state dict to ``path`` (atomically) with ``fmt``, ``config`` and
    ``info`` in the metadata; returns the path."""
    from safetensors.torch import save

    tensors = {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}
    meta = {
        "format": fmt,
        "config": json.dumps(dict(config)),
        "info": to_json(dict(info or {})),
        "torch": torch.__version__,
        # The kernels torch picked on this CPU: float results, hence trained weights and the
        # rollouts that follow them, match bit for bit only between machines where it agrees.
        "torch_cpu_capability": torch.backends.cpu.get_cpu_capability(),
    }
    target = Path(path)
    with atomic_path(target) as tmp:
        tmp.write_bytes(save(tensors, metadata=meta))
    return target


def read_checkpoint(
    p: Path, fmt: str, what: str, fix: str, missing_fix: str, tensors: bool
) -> tuple[dict[str, Any], dict[str, torch.Tensor]]:
    """``({"format", "config", "info"}, tensors)`` of the checkpoint at ``p`` (no tensors when
    ``tensors`` is false). A missing, unreadable or foreign file, or bad metadata, raises one
    :class:`DataError` naming ``what`` and the ``fix`` (``missing_fix`` for a missing file)."""
    from safetensors import SafetensorError, safe_open

    if not p.is_file():
        raise DataError(expect(what, "an existing file", str(p), missing_fix))
    try:
        with safe_open(str(p), framework="pt") as fh:
            raw = dict(fh.metadata() or {})
            arrays = {k: fh.get_tensor(k) for k in fh.keys()} if tensors else {}  # noqa: SIM118
    except (SafetensorError, OSError, ValueError, RuntimeError) as exc:
        raise DataError(
            expect(f"{what} {p}", "a readable .safetensors file", f"{exc}", fix)
        ) from exc
    if raw.get("format") != fmt:
        raise DataError(expect(f"{p}: format", fmt, raw.get("format"), fix))
    try:
        meta = {
            "format": raw["format"],
            "config": json.loads(raw["config"]),
            "info": json.loads(raw.get("info", "{}")),
        }
    except (KeyError, json.JSONDecodeError) as exc:
        raise DataError(expect(f"{p}: metadata", "JSON 'config'", "missing/invalid", fix)) from exc
    return meta, arrays


def load_checked(
    model: M, arrays: Mapping[str, torch.Tensor], p: Path, built_from: str, fix: str
) -> M:
    """Load ``arrays`` into ``model`` (built from the checkpoint's config, described by
    ``built_from``) and return it in eval mode, after checking that the tensors are exactly the
    model's (names and shapes) and finite float32; otherwise one :class:`DataError` listing the
    missing, unexpected and mis-shaped tensors, or the first bad one."""
    expected = {k: tuple(v.shape) for k, v in model.state_dict().items()}
    received = {k: tuple(v.shape) for k, v in arrays.items()}
    if expected != received:
        diff = {
            "missing": sorted(set(expected) - set(received)),
            "unexpected": sorted(set(received) - set(expected)),
            "shape": sorted(k for k in set(expected) & set(received) if expected[k] != received[k]),
        }
        raise DataError(
            expect(
                f"{p}: tensors",
                f"those of {built_from}",
                diff,
                f"the weights do not match the stored config; {fix}",
            )
        )
    for k, v in arrays.items():
        if v.dtype != torch.float32 or not bool(torch.isfinite(v).all()):
            raise DataError(expect(f"{p}: {k}", "finite float32", str(v.dtype), fix))
    model.load_state_dict(dict(arrays), strict=True)
    return model.eval()


def optimizer_tensors(state: Mapping[str, Any], prefix: str) -> dict[str, torch.Tensor]:
    """An optimizer's ``state_dict()`` per-parameter state as tensors named
    ``PREFIX/INDEX/NAME`` (its ``param_groups`` are plain JSON: store them beside)."""
    return {
        f"{prefix}/{i}/{k}": torch.as_tensor(v).detach().cpu().clone().contiguous()
        for i, st in state["state"].items()
        for k, v in st.items()
    }


def optimizer_state(
    tensors: Mapping[str, torch.Tensor], prefix: str, param_groups: Any
) -> dict[str, Any]:
    """The ``state_dict`` that :func:`optimizer_tensors` stored under ``prefix``, with its
    ``param_groups``, for the optimizer's ``load_state_dict``."""
    out: dict[str, Any] = {"state": {}, "param_groups": param_groups}
    for k, v in tensors.items():
        if k.startswith(f"{prefix}/"):
            _, i, name = k.split("/")
            out["state"].setdefault(int(i), {})[name] = v
    return out


def read_training_state(
    path: Path, fmt: str, fix: str, tensors: bool = True
) -> tuple[dict[str, str], dict[str, torch.Tensor]]:
    """The raw metadata (and with ``tensors`` the tensors) of a trainer's checkpoint; a file
    that cannot be read or is of another format than ``fmt`` raises one :class:`DataError`."""
    from safetensors import SafetensorError, safe_open

    try:
        with safe_open(str(path), framework="pt") as fh:
            meta = dict(fh.metadata() or {})
            arrays = {k: fh.get_tensor(k) for k in fh.keys()} if tensors else {}  # noqa: SIM118
    except (SafetensorError, OSError, ValueError, RuntimeError) as exc:
        raise DataError(expect(f"checkpoint {path}", "a readable file", str(exc), fix)) from exc
    if meta.get("format") != fmt:
        raise DataError(expect(f"{path}: format", fmt, meta.get("format"), fix))
    return meta, arrays


def _groups_key(prefix: str) -> str:
    """The metadata key of the ``param_groups`` of the optimizer stored under ``prefix``:
    ``optim`` → ``param_groups``, ``critic_optim`` → ``critic_param_groups``."""
    return prefix.removesuffix("optim") + "param_groups"


def write_training_state(
    path: Path,
    fmt: str,
    *,
    modules: Mapping[str, nn.Module],
    optimizers: Mapping[str, torch.optim.Optimizer],
    tensors: Mapping[str, torch.Tensor],
    meta: Mapping[str, Any],
) -> None:
    """A trainer's whole state to ``path``, atomically: safetensors + metadata, read back by
    :func:`read_training_state`. Each module's parameters and buffers as ``PREFIX/NAME``, each
    optimizer's state as ``PREFIX/INDEX/NAME`` (:func:`optimizer_tensors`) with its
    ``param_groups`` as JSON under :func:`_groups_key` (restored by
    :func:`restore_optimizer`), the trainer's own ``tensors``, and ``meta``: a string as it
    is, anything else as JSON; ``format`` (``fmt``) and the ``torch`` version are added."""
    from safetensors.torch import save

    out: dict[str, torch.Tensor] = {
        f"{prefix}/{k}": v.detach().cpu().clone().contiguous()
        for prefix, module in modules.items()
        for k, v in module.state_dict().items()
    }
    info: dict[str, str] = {"format": fmt}
    for prefix, opt in optimizers.items():
        osd = opt.state_dict()
        out.update(optimizer_tensors(osd, prefix))
        info[_groups_key(prefix)] = json.dumps(osd["param_groups"])
    out.update(tensors)
    info.update({k: v if isinstance(v, str) else json.dumps(v) for k, v in meta.items()})
    info["torch"] = torch.__version__
    with atomic_path(path) as tmp:  # bytes, not save_file: that makes the file mode 0600
        tmp.write_bytes(save(out, metadata=info))


def restore_optimizer(
    opt: torch.optim.Optimizer,
    tensors: Mapping[str, torch.Tensor],
    meta: Mapping[str, str],
    prefix: str,
) -> None:
    """Load into ``opt`` the state :func:`write_training_state` stored under ``prefix``."""
    groups = json.loads(meta[_groups_key(prefix)])
    opt.load_state_dict(optimizer_state(tensors, prefix, groups))
