"""Density reward learned from positive and negative demonstrations (paper §IV-A.1).

With inducing points U = {(u_i, γ̃_i)} and demonstrations D = {(z_j, γ_j)}, N_D = |D|:

    α = (λ K_UU + β I)⁻¹ (1/N_D) K_UD 1                                          (eq. 8)
    r(z) = Σ_i α_i k_SL((z, +1), (u_i, γ̃_i))        (the query has leverage +1)    (eq. 6)

K is the smooth leveraged kernel (eq. 9). The solve uses a Cholesky factorisation with a
growing diagonal jitter as fallback, never an explicit inverse. r grows like 1/β, so the
reward is divided by ``scale`` = max |r| over the training demonstrations and the scale is
stored with the model: the reward then lies in about [−1, 1] and combines with the rule terms.

Choices beyond the paper (docs/reward.md): features are standardised with the training
statistics; the default length scale is the median pairwise distance of the standardised
demos (docs/reward.md); above ``max_inducing`` demos the
inducing set is chosen by k-means (the demo nearest to each centroid, keeping its own γ) or
farthest-point sampling.
"""

from __future__ import annotations

import dataclasses
import json
import typing
from pathlib import Path
from typing import Annotated, Any, Literal, Self

import numpy as np
import scipy.linalg
from annotated_types import Ge
from numpy.typing import ArrayLike, NDArray

from pioneer.bounds import Positive
from pioneer.config import Config
from pioneer.errors import ConfigError, DataError, expect
from pioneer.io import atomic_path, load_npz
from pioneer.reward.fastexp import exp_shifted_inplace
from pioneer.reward.kernels import leverage_factor, sq_dists

__all__ = [
    "INDUCING",
    "DensityConfig",
    "DensityReward",
    "farthest_point_indices",
    "kmeans_medoid_indices",
]

F64 = NDArray[np.float64]
FORMAT = "pioneer.density_reward/1"
_CHUNK = 4096
Inducing = Literal["kmeans", "fps"]  # how a subset of inducing points is chosen
INDUCING: tuple[str, ...] = typing.get_args(Inducing)


@dataclasses.dataclass(frozen=True)
class DensityConfig(Config):
    """Hyperparameters of the density reward (defaults: docs/reward.md)."""

    gain2: Positive = 1.0  # g², kernel output scale
    # l in standardised units; None: the median heuristic (median pairwise distance)
    length_scale: Positive | None = None
    length_scale_factor: Positive = 1.0  # multiplies the median-heuristic length scale
    lam: Positive = 1e-2  # λ, weight of the RKHS-norm regulariser
    beta: Positive = 1e-3  # β, weight of the coefficient-norm regulariser
    max_inducing: Annotated[int, Ge(1)] = 2000  # above this many demos, choose inducing points
    # how the inducing points are chosen: "kmeans" (medoids) or "fps" (farthest-point sampling)
    inducing: Inducing = "kmeans"
    jitter: Positive = 1e-8  # first diagonal jitter tried if the Cholesky factorisation fails
    standardize: bool = True  # z-score features with the training statistics
    seed: int = 0  # for k-means / FPS / the length-scale subsample


def farthest_point_indices(z: F64, k: int, rng: np.random.Generator) -> NDArray[np.int64]:
    """Indices of up to ``k`` distinct points by farthest-point sampling (first one random)."""
    n = z.shape[0]
    idx = np.empty(k, dtype=np.int64)
    idx[0] = rng.integers(n)
    d = np.einsum("ij,ij->i", z - z[idx[0]], z - z[idx[0]])
    for i in range(1, k):
        nxt = int(np.argmax(d))
        if d[nxt] <= 0.0:  # every distinct point is taken (duplicated data): stop early
            return idx[:i]
        idx[i] = nxt
        diff = z - z[nxt]
        np.minimum(d, np.einsum("ij,ij->i", diff, diff), out=d)
    return idx


def kmeans_medoid_indices(
    z: F64, k: int, rng: np.random.Generator, iters: int = 10
) -> NDArray[np.int64]:
    """Indices of the demos nearest to ``k`` k-means centroids (deduplicated, sorted).

    Lloyd's algorithm from a random subset, with the assignment step as one matrix product
    per chunk (scipy's k-means++ initialisation is quadratic in k: minutes for k = 2000).
    """
    n = z.shape[0]
    centroids = z[rng.choice(n, size=k, replace=False)].copy()
    labels = np.empty(n, dtype=np.int64)
    for _ in range(iters):
        for s in range(0, n, _CHUNK):
            labels[s : s + _CHUNK] = np.argmin(sq_dists(z[s : s + _CHUNK], centroids), axis=1)
        counts = np.bincount(labels, minlength=k).astype(np.float64)
        sums = np.zeros_like(centroids)
        np.add.at(sums, labels, z)
        filled = counts > 0
        centroids[filled] = sums[filled] / counts[filled, None]
    nearest = np.empty(k, dtype=np.int64)
    for s in range(0, k, _CHUNK):
        nearest[s : s + _CHUNK] = np.argmin(sq_dists(centroids[s : s + _CHUNK], z), axis=1)
    return np.unique(nearest)


def _median_distance(z: F64, rng: np.random.Generator, max_points: int = 400) -> float:
    """Median pairwise Euclidean distance of (a subsample of) the standardised demos
    (docs/reward.md).

    This is deliberately broad. In 31-D a kernel this wide gives every rollout state a graded
    reward, so the teacher's candidates are told apart (spread of R_den across candidates
    ≈ 0.2, teacher time 12.5 s vs 7.1 s without it). The per-dimension median difference of
    the authors' earlier code (≈ 0.9 here) ranks held-out demos better (AUROC 0.99 vs 0.79)
    but is ~0 everywhere away from the demos, so it leaves the teacher unchanged.
    ``--select-length`` picks by AUROC instead (docs/reward.md).
    """
    if z.shape[0] < 2:
        return 1.0
    sub = z if z.shape[0] <= max_points else z[rng.choice(z.shape[0], max_points, replace=False)]
    d = np.sqrt(sq_dists(sub, sub)[np.triu_indices(sub.shape[0], k=1)])
    d = d[d > 0]
    return float(np.median(d)) if d.size else 1.0


def _validate_training(features: ArrayLike, gamma: ArrayLike) -> tuple[F64, F64]:
    z = np.asarray(features, dtype=np.float64)
    g = np.asarray(gamma, dtype=np.float64)
    if z.ndim == 1:
        z = z[:, None]
    if z.ndim != 2 or z.shape[0] == 0:
        raise DataError(expect("features", "a non-empty array (N, D)", z.shape, "pass demos"))
    if g.shape != (z.shape[0],):
        raise DataError(expect("gamma", f"shape ({z.shape[0]},)", g.shape, "one γ per sample"))
    bad = np.flatnonzero(~np.all(np.isfinite(z), axis=1))
    if bad.size:
        raise DataError(
            expect(f"features[{bad[0]}]", "finite values", z[bad[0]].tolist(), "drop NaN/inf rows")
        )
    bad = np.flatnonzero(~np.isfinite(g) | (g < -1) | (g > 1))
    if bad.size:
        raise DataError(
            expect(f"gamma[{bad[0]}]", "a fidelity in [-1, 1]", float(g[bad[0]]), "clip or fix γ")
        )
    return z, g


class DensityReward:
    """The learned density reward r(z); call it on a batch of feature vectors ``(M, D)``."""

    def __init__(self, config: DensityConfig | None = None) -> None:
        self.config = config or DensityConfig()
        self.feature_names: list[str] = []
        self.mean_: F64 | None = None
        self.std_: F64 | None = None
        self.inducing_: F64 | None = None  # (N_U, D) standardised inducing points
        self.leverage_: F64 | None = None  # (N_U,) γ̃
        self.alpha_: F64 | None = None  # (N_U,)
        self.length_: float = float("nan")
        self.scale_: float = 1.0
        self.n_train_: int = 0
        self.info_: dict[str, Any] = {}
        self._w: F64 | None = None  # α_i · g² · cos(π/2 (1 − γ̃_i)), for evaluation
        self._u32: NDArray[np.float32] | None = None  # (D, N_U) −2c uᵀ
        self._cu2: NDArray[np.float32] | None = None  # (N_U,) c ‖u‖²
        self._w32: NDArray[np.float32] | None = None

    # ---------------------------------------------------------------------------- fitting
    def fit(
        self, features: ArrayLike, gamma: ArrayLike, feature_names: list[str] | None = None
    ) -> Self:
        """Fit α in closed form (eq. 8) on demos ``features (N, D)`` with fidelities ``γ (N,)``."""
        cfg = self.config
        z, g = _validate_training(features, gamma)
        rng = np.random.default_rng(cfg.seed)
        d = z.shape[1]
        self.feature_names = list(feature_names) if feature_names else [f"z{i}" for i in range(d)]
        if len(self.feature_names) != d:
            raise DataError(
                expect("feature_names", f"{d} names", len(self.feature_names), "name every feature")
            )
        if cfg.standardize:
            self.mean_ = z.mean(axis=0)
            std = z.std(axis=0)
            self.std_ = np.where(std > 1e-12, std, 1.0)
        else:
            self.mean_ = np.zeros(d)
            self.std_ = np.ones(d)
        zs = (z - self.mean_) / self.std_
        self.length_ = cfg.length_scale or cfg.length_scale_factor * _median_distance(zs, rng)
        n = zs.shape[0]
        if n <= cfg.max_inducing:
            idx = np.arange(n)
        elif cfg.inducing == "fps":
            idx = np.sort(farthest_point_indices(zs, cfg.max_inducing, rng))
        else:
            idx = kmeans_medoid_indices(zs, cfg.max_inducing, rng)
        u, gu = zs[idx], g[idx]
        c = -0.5 / (self.length_**2)
        k_uu = cfg.gain2 * np.exp(sq_dists(u, u) * c) * leverage_factor(gu, gu)
        b = np.zeros(u.shape[0])
        for s in range(0, n, _CHUNK):
            blk = cfg.gain2 * np.exp(sq_dists(u, zs[s : s + _CHUNK]) * c)
            b += (blk * leverage_factor(gu, g[s : s + _CHUNK])).sum(axis=1)
        b /= n
        a_mat = cfg.lam * k_uu + cfg.beta * np.eye(u.shape[0])
        self.alpha_, jitter = _cholesky_solve(a_mat, b, cfg.jitter)
        self.inducing_, self.leverage_ = u, gu
        self._w = self.alpha_ * cfg.gain2 * np.cos(0.5 * np.pi * (1.0 - gu))
        self._u32 = self._cu2 = self._w32 = None
        self.n_train_ = n
        self.scale_ = 1.0
        raw = self.raw(z)
        self.scale_ = float(np.max(np.abs(raw))) or 1.0
        self.info_ = {"jitter": jitter, "n_inducing": int(u.shape[0])}
        return self

    # ------------------------------------------------------------------------- evaluation
    def _check_fitted(self) -> None:
        if self._w is None:
            raise ConfigError(
                expect("DensityReward", "a fitted model", "unfitted", "call fit() or load()")
            )

    def raw(self, features: ArrayLike) -> F64:
        """Unscaled reward Σ_i α_i k_SL((z, +1), (u_i, γ̃_i)) for ``(M, D)`` features."""
        self._check_fitted()
        assert self.mean_ is not None and self.std_ is not None and self.inducing_ is not None
        assert self._w is not None
        z = np.asarray(features, dtype=np.float64)
        if z.ndim == 1:
            z = z[None, :] if z.shape[0] == self.mean_.shape[0] else z[:, None]
        if z.shape[-1] != self.mean_.shape[0]:
            raise DataError(
                expect(
                    "features",
                    f"(M, {self.mean_.shape[0]})",
                    z.shape,
                    "use the training feature map",
                )
            )
        # float32 evaluation (relative error ~1e-6), with the kernel's −1/(2l²) folded into
        # cached inducing terms: c‖z−u‖² = c‖z‖² + c‖u‖² − 2c z·u. The exponential is the
        # SIMD kernel of pioneer.reward.fastexp (≤ 1e−7 relative error, 2× numpy's on AVX2).
        zs = ((z - self.mean_) / self.std_).astype(np.float32)
        u_scaled, cu2, w32 = self._eval_cache()
        c = np.float32(-0.5 / (self.length_**2))
        out = np.empty(zs.shape[0])
        for s in range(0, zs.shape[0], _CHUNK):
            q = zs[s : s + _CHUNK]
            k = q @ u_scaled  # (M, N_U): −2c z·u
            # k ← exp(k + c‖z‖² + c‖u‖²) = exp(c‖z−u‖²); the argument is ≤ 0 up to round-off
            exp_shifted_inplace(k, c * np.einsum("ij,ij->i", q, q), cu2)
            out[s : s + _CHUNK] = k @ w32
        return out

    def _eval_cache(self) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]:
        assert self.inducing_ is not None and self._w is not None
        if self._u32 is None or self._cu2 is None or self._w32 is None:
            u = self.inducing_.astype(np.float32)
            c = np.float32(-0.5 / (self.length_**2))
            self._u32 = np.ascontiguousarray((-2.0 * c) * u.T)
            self._cu2 = c * np.einsum("ij,ij->i", u, u)
            self._w32 = self._w.astype(np.float32)
        return self._u32, self._cu2, self._w32

    def __call__(self, features: ArrayLike) -> F64:
        """Scaled reward r(z) / scale for ``(M, D)`` features → ``(M,)``."""
        return self.raw(features) / self.scale_

    # --------------------------------------------------------------------------- save/load
    def save(self, path: str | Path) -> None:
        """Write an ``.npz`` (arrays + a JSON metadata string; no pickle), atomically."""
        self._check_fitted()
        assert self.inducing_ is not None and self.leverage_ is not None and self.alpha_ is not None
        assert self.mean_ is not None and self.std_ is not None
        meta = {
            "format": FORMAT,
            "config": self.config.to_dict(),
            "feature_names": self.feature_names,
            "length_scale": self.length_,
            "scale": self.scale_,
            "n_train": self.n_train_,
            "info": self.info_,
        }
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.savez(
                fh,
                mean=self.mean_,
                std=self.std_,
                inducing=self.inducing_,
                leverage=self.leverage_,
                alpha=self.alpha_,
                metadata=np.array(json.dumps(meta)),
            )

    @classmethod
    def load(cls, path: str | Path) -> DensityReward:
        """Read a model written by :meth:`save`; every field is validated."""
        p = Path(path)
        arrays = load_npz(
            p, "reward model", "re-fit the model; the file is truncated or not an npz"
        )
        meta = _checked_meta(p, arrays)
        model = cls(DensityConfig.from_dict(meta["config"]))
        model.feature_names = list(meta["feature_names"])
        model.mean_ = arrays["mean"].astype(np.float64)
        model.std_ = arrays["std"].astype(np.float64)
        model.inducing_ = arrays["inducing"].astype(np.float64)
        model.leverage_ = arrays["leverage"].astype(np.float64)
        model.alpha_ = arrays["alpha"].astype(np.float64)
        model.length_ = float(meta["length_scale"])
        model.scale_ = float(meta["scale"])
        model.n_train_ = int(meta["n_train"])
        model.info_ = dict(meta.get("info", {}))
        _check_layout(p, model.info_.get("features"), model.feature_names)
        model._w = model.alpha_ * model.config.gain2 * np.cos(0.5 * np.pi * (1.0 - model.leverage_))
        return model


def _check_layout(p: Path, features: object, names: list[str]) -> None:
    """A model that names one of PioneeR's feature maps must have that map's features, in its
    order (a model fitted through the API without names, ``z0, z1, …``, is checked for its
    width only; a feature map of the caller's own is the caller's to check)."""
    from pioneer.reward.features import FEATURE_MAPS, feature_map

    if features not in FEATURE_MAPS:
        return
    wanted = list(feature_map(str(features)).names)
    generic = names == [f"z{i}" for i in range(len(names))]
    if len(names) != len(wanted) or (not generic and names != wanted):
        got = f"{len(names)} features" + ("" if generic else f" {names[:3]}…")
        raise DataError(
            expect(f"{p}: features", f"the {len(wanted)} of {features!r} in order", got, "re-fit")
        )


def _checked_meta(p: Path, arrays: dict[str, Any]) -> dict[str, Any]:
    """Validate a saved model's arrays and metadata (:meth:`DensityReward.load`); returns the
    metadata."""
    need = {"mean", "std", "inducing", "leverage", "alpha", "metadata"}
    if need - set(arrays):
        raise DataError(
            expect(f"reward model {p}", f"arrays {sorted(need)}", sorted(arrays), "re-fit")
        )
    try:
        meta = json.loads(str(arrays["metadata"]))
    except json.JSONDecodeError as exc:
        raise DataError(expect(f"{p}: metadata", "JSON", "invalid JSON", "re-fit")) from exc
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        got = meta.get("format") if isinstance(meta, dict) else type(meta).__name__
        raise DataError(expect(f"{p}: format", FORMAT, got, "re-fit with this version"))
    d = arrays["mean"].shape[0] if arrays["mean"].ndim == 1 else -1
    _check_arrays(p, arrays, d)
    _check_meta_fields(p, meta, d)
    return meta


def _check_arrays(p: Path, arrays: dict[str, Any], d: int) -> None:
    n_u = arrays["alpha"].shape[0] if arrays["alpha"].ndim == 1 else -1
    if d < 1:
        raise DataError(
            expect(f"{p}: mean", "a feature vector (D,), D >= 1", arrays["mean"].shape, "re-fit")
        )
    if n_u < 1:
        raise DataError(
            expect(
                f"{p}: alpha",
                "at least one inducing point",
                arrays["alpha"].shape,
                "re-fit the model on some demos",
            )
        )
    shapes = {"mean": (d,), "std": (d,), "inducing": (n_u, d), "leverage": (n_u,), "alpha": (n_u,)}
    for k, shp in shapes.items():
        arr = arrays[k]
        if arr.shape != shp:
            raise DataError(expect(f"{p}: {k}", f"shape {shp}", arr.shape, "re-fit the model"))
        if not np.all(np.isfinite(arr)):
            raise DataError(expect(f"{p}: {k}", "finite values", "NaN/inf", "re-fit the model"))
    if np.any(np.abs(arrays["leverage"]) > 1) or np.any(arrays["std"] <= 0):
        raise DataError(
            expect(f"{p}: leverage/std", "γ̃ in [-1, 1], std > 0", "out of range", "re-fit")
        )


def _check_meta_fields(p: Path, meta: dict[str, Any], d: int) -> None:
    missing = sorted({"config", "feature_names", "length_scale", "scale", "n_train"} - set(meta))
    if missing:
        raise DataError(
            expect(
                f"{p}: metadata",
                "config, feature_names, length_scale, scale, n_train",
                f"missing {missing}",
                "re-fit the model",
            )
        )
    for key in ("length_scale", "scale"):
        val = meta[key]
        if not (isinstance(val, int | float) and np.isfinite(val) and val > 0):
            raise DataError(expect(f"{p}: {key}", "a finite number > 0", val, "re-fit the model"))
    if len(meta["feature_names"]) != d:
        raise DataError(
            expect(f"{p}: feature_names", f"{d} names", len(meta["feature_names"]), "re-fit")
        )


def _cholesky_solve(a: F64, b: F64, jitter: float) -> tuple[F64, float]:
    """Solve a x = b for SPD ``a`` by Cholesky; on failure retry with jitter ×10 up to 1e−2."""
    eps = 0.0
    scale = float(np.mean(np.diag(a)))
    while True:
        try:
            cf = scipy.linalg.cho_factor(
                a + eps * scale * np.eye(a.shape[0]), lower=True, check_finite=False
            )
            return scipy.linalg.cho_solve(cf, b, check_finite=False), eps
        except np.linalg.LinAlgError:
            eps = jitter if eps == 0.0 else eps * 10.0
            if eps > 1e-2:
                raise
