"""Safetensors checkpoints of torch modules with a typed config: one writer and one reader for
the students and CrowdNav++ (weights as tensors; format tag, config and free-form ``info`` as
JSON in the file's metadata — loading cannot execute code)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from torch import nn

from pioneer.errors import DataError, expect
from pioneer.io import atomic_path

__all__ = ["read_checkpoint", "write_checkpoint"]


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
        "info": json.dumps(dict(info or {})),
        "torch": torch.__version__,
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
