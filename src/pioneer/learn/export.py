"""ONNX export of a student, for the torch-free robot runtime (SPEC 6, :mod:`pioneer.deploy`).

The graph has one input ``obs`` (batch, obs_dim) float32 — the 29-D observation, raw (the
standardisation is inside the graph) — and a dynamic batch axis. Outputs:

- MDN: ``action`` (batch, 2) the deterministic command (v [m/s], ω [rad/s]) chosen by the
  model's ``action_mode`` (mean of the most probable component by default), ``aleatoric``
  (batch,) and ``epistemic`` (batch,) [(m/s)² + (rad/s)²], then the raw mixture ``logits``
  (batch, K), ``mu`` and ``sigma`` (batch, K, 2) for analysis or a different read-out.
  The decision and the uncertainty are computed in the graph, so the runtime is one
  ``session.run`` with no post-processing.
- MLP: ``action`` (batch, 2) only (a regression has no uncertainty estimate).

The file's metadata (``metadata_props``) carries the format tag, the kind, the action mode
and the :class:`~pioneer.learn.models.StudentConfig` as JSON. Exported with PyTorch's
TorchScript-based exporter (``dynamo=False``): it needs no extra package and the graph is
small and static.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import torch
from torch import nn

from pioneer.deploy.mixture import ACTION_MODES
from pioneer.deploy.runtime import ONNX_FORMAT
from pioneer.errors import ConfigError, expect
from pioneer.io import atomic_path
from pioneer.learn.models import MDN, Student, select_action, uncertainty

__all__ = ["MDN_OUTPUTS", "MLP_OUTPUTS", "ONNX_FORMAT", "export_onnx"]

MDN_OUTPUTS: tuple[str, ...] = ("action", "aleatoric", "epistemic", "logits", "mu", "sigma")
MLP_OUTPUTS: tuple[str, ...] = ("action",)


class _MDNGraph(nn.Module):
    def __init__(self, model: MDN, mode: str) -> None:
        super().__init__()
        self.model = model
        self.mode = mode

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, ...]:
        logits, mu, sigma = self.model(obs)
        aleatoric, epistemic = uncertainty(logits, mu, sigma)
        return select_action(logits, mu, self.mode), aleatoric, epistemic, logits, mu, sigma


def export_onnx(
    model: Student, path: str | Path, opset: int = 17, action_mode: str | None = None
) -> Path:
    """Write ``model`` (eval mode, dropout off) as an ONNX graph to ``path`` (atomically).

    ``action_mode`` overrides the model's ``config.action_mode`` for the ``action`` output
    (MDN only). Returns the path. See the module docstring for inputs and outputs.
    """
    import onnx

    mode = action_mode or model.config.action_mode
    if mode not in ACTION_MODES:
        raise ConfigError(expect("action_mode", f"one of {ACTION_MODES}", mode, "use 'mode'"))
    graph: nn.Module
    if isinstance(model, MDN):
        graph, outputs = _MDNGraph(model, mode), MDN_OUTPUTS
    else:
        graph, outputs = model, MLP_OUTPUTS
    was_training = model.training
    model.eval()
    dummy = torch.zeros(2, model.config.obs_dim, dtype=torch.float32)
    axes = {name: {0: "batch"} for name in ("obs", *outputs)}
    target = Path(path)
    try:
        with atomic_path(target) as tmp, warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the TorchScript exporter's deprecation notice
            torch.onnx.export(
                graph,
                (dummy,),
                str(tmp),
                input_names=["obs"],
                output_names=list(outputs),
                opset_version=opset,
                dynamic_axes=axes,
                dynamo=False,
                do_constant_folding=True,
            )
            proto = onnx.load(str(tmp))
            meta = {
                "format": ONNX_FORMAT,
                "kind": model.config.kind,
                "action_mode": mode if isinstance(model, MDN) else "regression",
                "config": json.dumps(model.config.to_dict()),
                "outputs": json.dumps(list(outputs)),
            }
            onnx.helper.set_model_props(proto, meta)
            proto.producer_name = "pioneer"
            onnx.checker.check_model(proto)
            onnx.save(proto, str(tmp))
    finally:
        model.train(was_training)
    return target
