"""A student's forward pass in NumPy, for acting: one observation at a time.

An episode asks the student for one command per 0.1 s step — a batch of one. PyTorch spends
that step dispatching ≈ 35 small operators (≈ 0.16 ms for the MDN), not computing; the same
float32 arithmetic as NumPy calls takes a fraction of it. The weights are copied once from
the module (transposed for row-vector products); the mixture's action and its uncertainty
come from :mod:`pioneer.deploy.mixture`, as in the ONNX runtime.

The values equal the module's to float32 rounding, not bit for bit (the products and e^x
come from other libraries, and the mixture read-outs are computed in float64).
``make_student_policy(forward="torch")`` keeps the module's forward as the reference; the
tests compare both step by step, and docs/student.md records the two side by side on
validation episodes. Training always uses the module.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from torch import nn

from pioneer.deploy.mixture import MIRROR_ACTION, symmetric_mixture
from pioneer.laser import apply_mirror
from pioneer.learn.models import ACTION_DIM, MDN, Student

__all__ = ["StudentInference"]

F32 = NDArray[np.float32]
SOFTPLUS_THRESHOLD = 20.0  # torch's softplus is the identity above this (beta = 1)


def _softplus(x: F32) -> F32:
    """log(1 + eˣ), as :func:`torch.nn.functional.softplus` (identity above its threshold)."""
    soft: F32 = np.log1p(np.exp(np.minimum(x, np.float32(SOFTPLUS_THRESHOLD))))
    return np.where(x > SOFTPLUS_THRESHOLD, x, soft)


class StudentInference:
    """The forward pass of a :class:`~pioneer.learn.models.Student` (eval mode: no dropout):
    :meth:`mixture` for an MDN — ``(logits (N, K), mu (N, K, 2), sigma (N, K, 2))`` as
    ``MDN.forward`` — and :meth:`regress` for an MLP — the command ``(N, 2)``."""

    def __init__(self, model: Student) -> None:
        state = {k: v.detach().numpy().astype(np.float32) for k, v in model.state_dict().items()}
        self.kind = model.kind
        self.config = model.config
        self._in_mean, self._in_std = state["obs_mean"], state["obs_std"]
        self._act_mean, self._act_std = state["act_mean"], state["act_std"]
        self._trunk = [
            (np.ascontiguousarray(m.weight.detach().numpy().T), m.bias.detach().numpy().copy())
            for m in model.trunk
            if isinstance(m, nn.Linear)
        ]

        def linear(name: str) -> tuple[F32, F32]:
            return np.ascontiguousarray(state[f"{name}.weight"].T), state[f"{name}.bias"].copy()

        self._mirror = (
            model.config.inputs.mirror_map(model.config.obs_dim) if model.config.symmetric else None
        )
        if isinstance(model, MDN):
            self._heads = [linear("logits_head"), linear("mu_head"), linear("sigma_head")]
        else:
            self._heads = [linear("head")]

    def _features(self, x: F32) -> F32:
        h = (np.asarray(x, dtype=np.float32) - self._in_mean) / self._in_std
        for w, b in self._trunk:
            h = np.maximum(h @ w + b, np.float32(0.0))
        return h

    def mixture(self, x: F32) -> tuple[F32, F32, F32]:
        """An MDN's mixture of inputs ``x (N, input_dim)``, in physical units (a symmetric
        student's 2K components: :func:`pioneer.deploy.mixture.symmetric_mixture`)."""
        if self._mirror is None:
            return self._mixture(x)
        return symmetric_mixture(self._mixture(x), self._mixture(apply_mirror(x, *self._mirror)))

    def _mixture(self, x: F32) -> tuple[F32, F32, F32]:
        h = self._features(x)
        (wl, bl), (wm, bm), (ws, bs) = self._heads
        shape = (-1, self.config.n_components, ACTION_DIM)
        logits = h @ wl + bl
        mu = (h @ wm + bm).reshape(shape) * self._act_std + self._act_mean
        sigma = _softplus(h @ ws + bs).reshape(shape) * self._act_std
        return logits, mu, sigma + np.float32(self.config.sigma_floor)

    def regress(self, x: F32) -> F32:
        """An MLP student's command ``(N, 2)`` of inputs ``x (N, input_dim)`` (a symmetric
        student's: the mean of f(x) and the mirrored f(M x))."""
        if self._mirror is None:
            return self._regress(x)
        mirrored = self._regress(apply_mirror(x, *self._mirror)) * MIRROR_ACTION
        out: F32 = np.float32(0.5) * (self._regress(x) + mirrored)
        return out

    def _regress(self, x: F32) -> F32:
        (w, b) = self._heads[0]
        out: F32 = (self._features(x) @ w + b) * self._act_std + self._act_mean
        return out
