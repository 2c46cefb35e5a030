"""ONNX export of a student, for the torch-free robot runtime (:mod:`pioneer.deploy`).

The graph has one input ``obs`` (batch, input_dim) float32 — the 29-D observation, raw (the
standardisation is inside the graph), followed for a student that reads them by the previous
observation o_{t−1} and u_{t−1} (v, ω), the command sent at the previous step
(:class:`pioneer.deploy.runtime.StudentInputs`) — and a dynamic batch axis. Outputs:

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

:func:`export_checkpoint` is ``pioneer export``: a checkpoint (or a DAgger output folder) in,
an ONNX file out, written only if :func:`parity_check` finds ONNX Runtime and PyTorch agree.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from pioneer.config import default
from pioneer.deploy.mixture import ACTION_MODES
from pioneer.deploy.runtime import ONNX_FORMAT
from pioneer.errors import ConfigError, DataError, expect
from pioneer.io import atomic_path
from pioneer.learn.models import (
    MDN,
    Student,
    StudentConfig,
    load_student,
    select_action,
    uncertainty,
)

__all__ = [
    "CHECKPOINT_FILE",
    "MDN_OUTPUTS",
    "MLP_OUTPUTS",
    "ONNX_FORMAT",
    "PARITY_TOL",
    "export_checkpoint",
    "export_onnx",
    "parity_check",
]

MDN_OUTPUTS: tuple[str, ...] = ("action", "aleatoric", "epistemic", "logits", "mu", "sigma")
MLP_OUTPUTS: tuple[str, ...] = ("action",)
CHECKPOINT_FILE = "student.safetensors"  # the final student in a DAgger output folder
PARITY_TOL = 1e-4  # max |ONNX Runtime − PyTorch| accepted by export_checkpoint (float32 graph)
PARITY_OBS = 64  # random observations in export_checkpoint's parity check


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
        fix = f"use {default(StudentConfig, 'action_mode')!r}"
        raise ConfigError(expect("action_mode", f"one of {ACTION_MODES}", mode, fix))
    graph: nn.Module
    if isinstance(model, MDN):
        graph, outputs = _MDNGraph(model, mode), MDN_OUTPUTS
    else:
        graph, outputs = model, MLP_OUTPUTS
    was_training = model.training
    model.eval()
    dummy = torch.zeros(2, model.config.input_dim, dtype=torch.float32)
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


def parity_check(
    model: Student, onnx_path: str | Path, n: int = 64, seed: int = 0
) -> dict[str, float]:
    """Max ``|ONNX Runtime − PyTorch|`` of each output of the graph at ``onnx_path`` against
    ``model`` (eval mode), on ``n`` observations drawn around the model's input statistics
    (mean ± 2 std, from a generator seeded by ``seed``)."""
    import onnxruntime as ort

    rng = np.random.default_rng(seed)
    mean = model.obs_mean.detach().cpu().numpy().astype(np.float64)
    std = model.obs_std.detach().cpu().numpy().astype(np.float64)
    obs = (mean + 2.0 * std * rng.standard_normal((n, mean.size))).astype(np.float32)
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    opts.log_severity_level = 3
    sess = ort.InferenceSession(str(onnx_path), opts, providers=["CPUExecutionProvider"])
    names = [o.name for o in sess.get_outputs()]
    got = sess.run(names, {"obs": obs})
    mode = sess.get_modelmeta().custom_metadata_map.get("action_mode", "mode")
    graph: nn.Module = _MDNGraph(model, mode) if isinstance(model, MDN) else model
    was_training = model.training
    model.eval()
    try:
        with torch.no_grad():
            out = graph(torch.from_numpy(obs))
    finally:
        model.train(was_training)
    want = out if isinstance(out, tuple) else (out,)
    return {
        name: float(np.max(np.abs(g - w.numpy())))
        for name, g, w in zip(names, got, want, strict=True)
    }


def export_checkpoint(
    model_path: str | Path, out: str | Path, action_mode: str | None = None, opset: int = 17
) -> dict[str, Any]:
    """``pioneer export``: load the student at ``model_path`` (a ``.safetensors`` checkpoint
    from :func:`~pioneer.learn.models.save_student`, or a folder holding
    :data:`CHECKPOINT_FILE`, as ``pioneer distill`` writes), export it to ``out`` and check
    parity on random observations. ``out`` is written only if every output agrees within
    :data:`PARITY_TOL`; otherwise :class:`DataError`. Returns a JSON-able summary.
    """
    p = Path(model_path)
    if p.is_dir():
        p = p / CHECKPOINT_FILE
    if not p.is_file():
        raise DataError(
            expect(
                "--model",
                f"a student .safetensors checkpoint or a folder holding {CHECKPOINT_FILE}",
                str(model_path),
                "check the path (pioneer distill writes OUT/student.safetensors)",
            )
        )
    model = load_student(p)
    if action_mode is not None and not isinstance(model, MDN):
        raise ConfigError(
            expect(
                "--action-mode",
                "an MDN student (it picks the mixture's action)",
                f"{p}: an {model.config.kind} student",
                "drop --action-mode",
            )
        )
    target = Path(out)
    with atomic_path(target) as tmp:
        export_onnx(model, tmp, opset=opset, action_mode=action_mode)
        diffs = parity_check(model, tmp, n=PARITY_OBS)
        worst = max(diffs.values())
        if not worst <= PARITY_TOL:
            raise DataError(
                expect(
                    f"ONNX parity of {p}",
                    f"max |ONNX Runtime − PyTorch| <= {PARITY_TOL}",
                    diffs,
                    "check the torch and onnxruntime versions; nothing was written",
                )
            )
    mode = (action_mode or model.config.action_mode) if isinstance(model, MDN) else "regression"
    return {
        "out": str(target),
        "model": str(p),
        "kind": model.config.kind,
        "action_mode": mode,
        "opset": opset,
        "parity": {"observations": PARITY_OBS, "max_abs_diff": worst, "outputs": diffs, "ok": True},
    }
