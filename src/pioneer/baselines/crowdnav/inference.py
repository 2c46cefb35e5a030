"""CrowdNav++'s acting step in NumPy: the network of :class:`CrowdNavNet` for one decision.

A second copy of the module's forward on purpose — at a batch of one it is 3× faster — bound to
the module step by step by ``tests/baselines/crowdnav/test_crowdnav_inference.py``.

An evaluation episode asks the network for one action per 0.1 s step of one world — a batch
of one. There PyTorch spends its time dispatching ≈ 60 operators on 64-wide arrays (most of
a 0.5 ms decision), not computing; the same arithmetic as NumPy calls on float32 arrays takes
a fraction of it (a decision 0.17 ms, docs/baselines.md). The weights are copied once from
the module (transposed for row-vector products).

The values equal the module's to float32 rounding, not bit for bit: the products, e^x and
tanh come from other libraries (OpenBLAS and NumPy's SIMD loops instead of PyTorch's), so
their last bits differ. ``make_crowdnav_policy(forward="torch")`` keeps the module's own
forward as the reference; the tests compare both step by step, and docs/baselines.md records
the two side by side on validation episodes. Training (:mod:`~pioneer.baselines.crowdnav.ppo`)
acts through this forward too, with the critic's value (:meth:`CrowdNavInference.act`), and
updates the module.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from pioneer.baselines.crowdnav.network import CrowdNavNet
from pioneer.baselines.crowdnav.observation import CrowdNavObs
from pioneer.nn.attention import masked_softmax

__all__ = ["CrowdNavInference"]

F32 = NDArray[np.float32]


def _sigmoid(x: F32) -> F32:
    return np.float32(1.0) / (np.float32(1.0) + np.exp(-x))


class CrowdNavInference:
    """The forward pass of a :class:`CrowdNavNet` for acting: graph encoding, one GRU step, the
    actor's mean and, for training's rollouts, the critic's value. The weights are those of
    the module when this object is made (a trainer makes a new one after every update)."""

    def __init__(self, model: CrowdNavNet) -> None:
        cfg = model.config
        self.config = cfg
        self._scale = np.float32(1.0 / math.sqrt(cfg.embed))
        p = {k: v.detach().numpy().astype(np.float32) for k, v in model.state_dict().items()}

        def linear(name: str) -> tuple[F32, F32]:
            return np.ascontiguousarray(p[f"{name}.weight"].T), p[f"{name}.bias"].copy()

        self._robot = linear("robot_embed")
        self._spatial = linear("spatial_embed")
        self._qkv = linear("hh_qkv")
        self._rh_q = linear("rh_q")
        self._rh_k = linear("rh_k")
        self._merge = linear("merge")
        self._actor = (linear("actor.0"), linear("actor.2"))
        self._mean = linear("mean_head")
        self._critic = (linear("critic.0"), linear("critic.2"))
        self._value = linear("value_head")
        self._w_ih = np.ascontiguousarray(p["gru.weight_ih"].T)  # (E, 3H): r, z, n
        self._w_hh = np.ascontiguousarray(p["gru.weight_hh"].T)  # (H, 3H)
        self._b_ih = p["gru.bias_ih"].copy()
        self._b_hh = p["gru.bias_hh"].copy()

    def initial_state(self, batch: int) -> F32:
        """The GRU state at the start of an episode, zeros (batch, H)."""
        return np.zeros((batch, self.config.hidden), dtype=np.float32)

    def step(self, obs: CrowdNavObs, h: F32) -> tuple[F32, F32, F32]:
        """``(mean (B, 2), robot–human weights (B, N), new GRU state (B, H))`` of one step of
        ``B`` worlds from their observations and GRU states ``h (B, H)``."""
        x, a_rh = self._encode(obs)
        h_new = self._gru(x, h)
        return self._head(self._actor, self._mean, h_new), a_rh, h_new

    def act(self, obs: CrowdNavObs, h: F32) -> tuple[F32, F32, F32]:
        """``(mean (B, 2), value (B,), new GRU state (B, H))``: a training rollout's step (as
        the module's ``encode``, ``gru`` and ``heads``)."""
        x, _ = self._encode(obs)
        h_new = self._gru(x, h)
        mean = self._head(self._actor, self._mean, h_new)
        return mean, self._head(self._critic, self._value, h_new)[:, 0], h_new

    def _encode(self, obs: CrowdNavObs) -> tuple[F32, F32]:
        """The graph features ``x (B, E)`` and the robot–human weights ``(B, N)``."""
        e = self.config.embed
        mask = obs.mask
        w, b = self._robot
        r = np.maximum(np.concatenate([obs.robot, obs.temporal], axis=-1) @ w + b, 0.0)
        w, b = self._spatial
        s = np.maximum(obs.spatial @ w + b, 0.0)  # (B, N, E)
        w, b = self._qkv
        qkv = s @ w + b
        q, k, v = qkv[..., :e], qkv[..., e : 2 * e], qkv[..., 2 * e :]
        a_hh = masked_softmax((q @ k.transpose(0, 2, 1)) * self._scale, mask[:, None, :])
        hum = np.maximum(s + a_hh @ v, 0.0) * mask[:, :, None]
        w, b = self._rh_k
        keys = hum @ w + b
        w, b = self._rh_q
        query = r @ w + b
        a_rh = masked_softmax((keys @ query[:, :, None])[..., 0] * self._scale, mask)
        c = (a_rh[:, :, None] * hum).sum(axis=1)
        w, b = self._merge
        return np.maximum(np.concatenate([r, c], axis=-1) @ w + b, 0.0), a_rh

    @staticmethod
    def _head(trunk: tuple[tuple[F32, F32], tuple[F32, F32]], out: tuple[F32, F32], h: F32) -> F32:
        """``out(tanh(tanh(h W1 + b1) W2 + b2))``: the actor's or the critic's head."""
        (w1, b1), (w2, b2) = trunk
        w, b = out
        return np.tanh(np.tanh(h @ w1 + b1) @ w2 + b2) @ w + b

    def _gru(self, x: F32, h: F32) -> F32:
        """One step of PyTorch's GRUCell (equations in :mod:`pioneer.nn.recurrent`)."""
        n_h = h.shape[-1]
        gi = x @ self._w_ih + self._b_ih
        gh = h @ self._w_hh + self._b_hh
        rz = _sigmoid(gi[:, : 2 * n_h] + gh[:, : 2 * n_h])
        r, z = rz[:, :n_h], rz[:, n_h:]
        n = np.tanh(gi[:, 2 * n_h :] + r * gh[:, 2 * n_h :])
        return (1.0 - z) * n + z * h
