"""The LiDAR's beam layout, the 29-D observation of one scan and the adapter from real laser
scans (paper §III-A) — numpy only.

This module imports neither numba nor the simulator, so the robot-side runtime
(:mod:`pioneer.deploy`) loads it alone: no JIT compiler in memory and nothing to compile on the
robot's first scan. The simulator's batched ray caster and observation kernel live in
:mod:`pioneer.sim.lidar`, which re-exports everything here; a test checks that both compute the
same observation, bit for bit.

Beam b (b = 0 … G−1) points at angle 2π b / G relative to the robot heading, counter-
clockwise; ranges are measured from the robot centre and capped at ``max_range``.

Observation (paper eq. 2), exactly in this order, float32:

    o = [r_1 … r_K, d_1, d_2, φ_1, φ_2, φ_g]

- r_k = min of the g consecutive beams of sector k (K = G / g = 24); with the default
  ``sector_layout="centred"`` sector 0 is centred on the heading (beams G−1, 0, 1) and sector
  k on beam g·k, so mirroring the world (x → −x) maps sector k to (K − k) mod K, φ to −φ and
  ω to −ω: the observation is mirror-true. ``"heading_first"`` (beams 0, 1, 2 first) is the
  earlier layout, kept for the compact world's reproducible results;
- d_1 ≤ d_2 the two smallest raw beam ranges (ties: the lower beam index first), φ_1, φ_2
  their beam angles in (−π, π],
- φ_g the goal bearing relative to the heading in (−π, π].

A real scan rarely covers every one of the G directions: a 270° scanner has a blind rear
sector, and beams that return NaN or less than ``range_min`` say nothing. A direction with no
valid source beam within half a beam spacing is *unseen*, and its range is filled by one of
:data:`UNSEEN_RULES` (``unseen=``):

- ``"obstacle"`` (the default, :data:`DEFAULT_UNSEEN`): range 0, an obstacle at the robot —
  never free space that was not observed. Chosen by measurement: the shipped students keep
  their success rate with a 270° scanner under it (docs/deployment.md, "A scanner that does
  not see all around");
- ``"nearest"``: the range of the angularly nearest seen direction (on a tie the shorter);
- ``"max_range"``: ``max_range``, i.e. free space — the optimistic rule of earlier versions.

With no seen direction at all, ``"nearest"`` falls back to ``"obstacle"``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import typing
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from pioneer.config import Config, check_nonnegative, check_positive, default
from pioneer.errors import ConfigError, DataError, expect

__all__ = [
    "DEFAULT_UNSEEN",
    "OBS_DIM",
    "SECTOR_LAYOUTS",
    "UNSEEN_RULES",
    "LidarConfig",
    "ScanReading",
    "UnseenRule",
    "apply_mirror",
    "beam_angles",
    "mirror_map",
    "mirror_observation",
    "observation_from_beams",
    "observation_from_scan",
    "observation_names",
    "read_scan",
    "resample_scan",
    "wrap_angles",
]

OBS_DIM = 29
SectorLayout = Literal["centred", "heading_first"]
SECTOR_LAYOUTS: tuple[str, ...] = typing.get_args(SectorLayout)
UnseenRule = Literal["obstacle", "nearest", "max_range"]  # fills of unseen directions (module doc)
UNSEEN_RULES: tuple[UnseenRule, ...] = typing.get_args(UnseenRule)
DEFAULT_UNSEEN: UnseenRule = "obstacle"


@dataclasses.dataclass(frozen=True)
class LidarConfig(Config):
    """Beam layout and range limits of the simulated 2-D LiDAR."""

    n_beams: int = 72  # G, over 360°; beam 0 along the heading, counter-clockwise
    group_size: int = 3  # g, beams per sector minimum
    n_nearest: int = 2  # b, nearest-obstacle descriptors
    max_range: float = 5.0  # [m]
    noise_std: float = 0.0  # [m] Gaussian range noise (0 = off)
    sector_layout: SectorLayout = "centred"  # sector 0 centred on the heading (module doc)

    def __post_init__(self) -> None:
        # sector_layout is a Literal, checked by Config; the bounds are written by hand, not
        # declared, as the light robot install (this module, no annotated-types) must load it.
        check_positive("LidarConfig", "max_range", self.max_range)
        check_nonnegative("LidarConfig", "noise_std", self.noise_std)
        if self.n_beams <= 0 or self.group_size <= 0 or self.n_beams % self.group_size:
            raise ConfigError(
                expect(
                    "LidarConfig.n_beams/group_size",
                    "positive integers with group_size dividing n_beams",
                    (self.n_beams, self.group_size),
                    f"use e.g. {default(LidarConfig, 'n_beams')} beams in groups of "
                    f"{default(LidarConfig, 'group_size')}",
                )
            )
        if not 1 <= self.n_nearest <= self.n_beams:
            raise ConfigError(
                expect(
                    "LidarConfig.n_nearest",
                    "1 <= b <= n_beams",
                    self.n_nearest,
                    f"use b = {default(LidarConfig, 'n_nearest')}",
                )
            )

    @property
    def n_sectors(self) -> int:
        """K = G / g."""
        return self.n_beams // self.group_size

    @property
    def sector_shift(self) -> int:
        """Beams by which sector 0 starts before the heading: (g − 1) // 2 when centred (1 for
        g = 3: beams G−1, 0, 1), 0 for the earlier heading-first layout."""
        return (self.group_size - 1) // 2 if self.sector_layout == "centred" else 0

    @property
    def obs_dim(self) -> int:
        """K + 2 b + 1 (29 with the paper's values)."""
        return self.n_sectors + 2 * self.n_nearest + 1


def beam_angles(n_beams: int) -> NDArray[np.float64]:
    """Beam angles relative to the heading, wrapped to (−π, π], shape ``(G,)``."""
    return wrap_angles(2.0 * np.pi * np.arange(n_beams) / n_beams)


def observation_names(cfg: LidarConfig | None = None) -> list[str]:
    """Feature names of the observation vector, in order."""
    cfg = cfg or LidarConfig()
    names = [f"r_{k + 1}" for k in range(cfg.n_sectors)]
    names += [f"d_{i + 1}" for i in range(cfg.n_nearest)]
    names += [f"phi_{i + 1}" for i in range(cfg.n_nearest)]
    return [*names, "phi_goal"]


def wrap_angles(a: NDArray[np.float64] | float) -> NDArray[np.float64]:
    """Angles [rad] wrapped to (−π, π]; the same arithmetic, bit for bit, as the simulator's
    scalar :func:`pioneer.sim.robot.wrap_angle`.

    A second copy on purpose: the robot runtime's light install has no numba (the binding
    test: ``tests/test_laser.py::test_wrap_angles_equals_scalar_kernel``)."""
    r = np.pi - np.mod(np.pi - np.asarray(a, dtype=np.float64), 2.0 * np.pi)
    return np.where(r > -np.pi, r, np.pi)


def _observation_one(
    beams: NDArray[np.float64], goal_bearing: float, cfg: LidarConfig
) -> NDArray[np.float32]:
    """The observation of one scan on the simulator's ``G`` beams, ``(obs_dim,)`` float32."""
    g, b = cfg.group_size, cfg.n_nearest
    shifted = np.roll(beams, cfg.sector_shift) if cfg.sector_shift else beams
    sectors = shifted[0::g]  # sector k: beams g·k − shift … g·k − shift + g − 1 (mod G)
    for j in range(1, g):  # g strided minima beat a reshape + min(axis=1) on 72 beams
        sectors = np.minimum(sectors, shifted[j::g])
    nearest = np.argsort(beams, kind="stable")[:b]  # ties: the lower beam index first
    wrapped = math.pi - ((math.pi - goal_bearing) % (2.0 * math.pi))  # as wrap_angles
    return np.concatenate(
        (
            sectors,
            beams[nearest],
            _beam_angle_table(cfg.n_beams)[nearest],
            (wrapped if wrapped > -math.pi else math.pi,),
        ),
        dtype=np.float32,
        casting="same_kind",
    )


@functools.lru_cache(maxsize=8)
def _beam_angle_table(n_beams: int) -> NDArray[np.float64]:
    table = beam_angles(n_beams)
    table.flags.writeable = False  # shared by every call (cached)
    return table


@dataclasses.dataclass(frozen=True)
class ScanReading:
    """A real scan on the simulator's ``G`` beams, with what it says about its own health."""

    beams: NDArray[np.float64]  # (G,) [m] ranges, unseen directions filled by the rule
    seen: NDArray[np.bool_]  # (G,) a valid source beam lay within half a beam spacing
    valid_share: float  # share of the scan's beams that are valid (a return or "no return")
    returns: int  # beams with a return in [range_min, range_max] (not "no return")

    @property
    def coverage_rad(self) -> float:
        """[rad] the angle around the robot the scan saw: seen beams × 2π / G."""
        return float(np.count_nonzero(self.seen)) * 2.0 * math.pi / self.seen.size


def read_scan(
    ranges: NDArray[np.floating] | list[float],
    angle_min: float,
    angle_increment: float,
    range_max: float,
    cfg: LidarConfig,
    range_min: float = 0.0,
    unseen: str = DEFAULT_UNSEEN,
) -> ScanReading:
    """Resample a real 2-D laser scan onto the simulator's ``G`` beams (see
    :func:`resample_scan`) and report which directions it saw and how many of its beams were
    valid."""
    if unseen not in UNSEEN_RULES:
        raise ConfigError(
            expect("unseen", f"one of {UNSEEN_RULES}", unseen, f"use {DEFAULT_UNSEEN!r}")
        )
    r = np.asarray(ranges, dtype=np.float64).ravel()
    if r.size == 0:
        raise DataError(expect("scan.ranges", "at least one beam", 0, "pass the scan's ranges"))
    if not (math.isfinite(angle_increment) and angle_increment != 0.0):
        raise DataError(
            expect("scan.angle_increment", "finite and non-zero", angle_increment, "fix the scan")
        )
    if not (math.isfinite(angle_min) and math.isfinite(range_max) and range_max > 0):
        raise DataError(
            expect(
                "scan.angle_min/range_max",
                "finite, range_max > 0",
                (angle_min, range_max),
                "fix the scan header",
            )
        )
    if angle_increment < 0:  # reversed scan: flip it into counter-clockwise order
        r = r[::-1]
        angle_min = angle_min + angle_increment * (r.size - 1)
        angle_increment = -angle_increment
    n, cap = r.size, cfg.max_range
    # Source validity and values, with a last entry n that stands for "no valid source" (the
    # table lists it after every real candidate of a target beam).
    # NaN compares false both ways (invalid); +inf and finite values above range_max are
    # "no return" (valid, max_range); -inf and values below range_min are invalid.
    beyond = r > range_max
    valid = np.empty(n + 1, dtype=np.bool_)
    np.greater_equal(r, range_min, out=valid[:n])
    valid[:n] |= beyond
    valid[n] = True
    vals = np.empty(n + 1)
    np.minimum(r, cap, out=vals[:n])
    vals[:n][beyond] = cap
    vals[n] = cap if unseen == "max_range" else 0.0
    source, row_start = _resample_table(float(angle_min), float(angle_increment), n, cfg.n_beams)
    first = valid[source].argmax(axis=1)  # candidates are nearest first: the nearest valid one
    chosen = source.ravel()[row_start + first]
    beams = vals[chosen]
    seen = chosen != n
    if unseen == "nearest" and seen.any() and not seen.all():
        beams[~seen] = _nearest_seen(beams, seen)
    n_valid = int(np.count_nonzero(valid[:n]))
    return ScanReading(
        beams=beams,
        seen=seen,
        valid_share=n_valid / n,
        returns=n_valid - int(np.count_nonzero(beyond)),
    )


def _nearest_seen(beams: NDArray[np.float64], seen: NDArray[np.bool_]) -> NDArray[np.float64]:
    """For each unseen beam, the range of the circularly nearest seen beam (a tie: the
    shorter range)."""
    g = beams.size
    hit, miss = np.flatnonzero(seen), np.flatnonzero(~seen)
    d = np.abs(miss[:, None] - hit[None, :])
    d = np.minimum(d, g - d)
    near = d == d.min(axis=1, keepdims=True)
    out: NDArray[np.float64] = np.where(near, beams[hit][None, :], np.inf).min(axis=1)
    return out


def resample_scan(
    ranges: NDArray[np.floating] | list[float],
    angle_min: float,
    angle_increment: float,
    range_max: float,
    cfg: LidarConfig,
    range_min: float = 0.0,
    unseen: str = DEFAULT_UNSEEN,
) -> NDArray[np.float64]:
    """Resample a real 2-D laser scan onto the simulator's ``G`` beams, shape ``(G,)``.

    ROS ``sensor_msgs/LaserScan`` conventions: beam i is at ``angle_min + i·angle_increment``
    in the sensor frame (x forward, counter-clockwise positive); ``+inf`` (or any value above
    ``range_max``) means no return and becomes ``max_range``; ``NaN``, ``-inf`` and values below
    ``range_min`` are invalid and ignored. Each target beam takes the nearest valid source beam
    within half a target spacing; a target beam with none is unseen and filled by the
    ``unseen`` rule (module docstring).
    """
    return read_scan(ranges, angle_min, angle_increment, range_max, cfg, range_min, unseen).beams


@functools.lru_cache(maxsize=16)
def _resample_table(
    amin: float, inc: float, n: int, n_target: int
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """For each target beam, the source beams within half a target spacing, nearest first
    (on an exact tie the one met first in the search order below: the window around the
    target's position in this turn, one turn earlier, then later turns; each by increasing
    index), then ``n`` ("none"): ``(n_target, C)``; and the flat index of each row's first
    entry.

    It depends on the scan's geometry only, which a sensor keeps from scan to scan, so a scan
    costs a few array lookups."""
    tol = max(np.pi / n_target, 0.5 * inc) + 1e-9
    a = 2.0 * np.pi * np.arange(n_target) / n_target  # target beam angles
    u = np.mod(a - amin, 2.0 * np.pi) / inc  # fractional source index in the first turn
    w = math.ceil(tol / inc) + 1
    steps = np.arange(-w, w + 2)
    period = 2.0 * np.pi / inc  # source beams per turn
    # Search windows: this turn, one turn earlier (a target just before angle_min), then
    # every later turn the scan reaches (a scan of more than 360° sees a direction twice).
    turns = [0, -1, *range(1, math.ceil(n / period) + 1)]
    cand = np.concatenate(
        [np.floor(u if k == 0 else u + k * period)[:, None] + steps for k in turns], axis=1
    ).astype(np.int64)
    inside = (cand >= 0) & (cand < n)
    d = np.abs(wrap_angles(a[:, None] - (amin + cand * inc)))
    ok = inside & (d <= tol)
    d = np.where(ok, d, np.inf)
    order = np.lexsort((np.broadcast_to(np.arange(cand.shape[1]), cand.shape), d), axis=1)
    source = np.where(ok, cand, n)[np.arange(n_target)[:, None], order]
    source = np.concatenate([source, np.full((n_target, 1), n)], axis=1)  # always a "none"
    row_start = np.arange(n_target) * source.shape[1]  # flat index of each row's first entry
    source.flags.writeable = row_start.flags.writeable = False  # shared by every call (cached)
    return source, row_start


def observation_from_beams(
    beams: NDArray[np.float64],
    goal_xy_robot: tuple[float, float] | NDArray[np.float64],
    cfg: LidarConfig | None = None,
) -> NDArray[np.float32]:
    """The 29-D observation from ranges on the simulator's ``G`` beams ``(G,)`` [m] (e.g.
    :attr:`ScanReading.beams`) and the goal ``(x, y)`` [m] in the robot frame."""
    cfg = cfg or LidarConfig()
    g = np.asarray(goal_xy_robot, dtype=np.float64)
    if g.shape != (2,) or not np.all(np.isfinite(g)):
        raise DataError(expect("goal_xy_robot", "finite (x, y) [m]", g.tolist(), "fix the goal"))
    b = np.asarray(beams, dtype=np.float64)
    if b.shape != (cfg.n_beams,):
        raise DataError(
            expect("beams", f"shape ({cfg.n_beams},)", b.shape, "resample with read_scan")
        )
    return _observation_one(b, math.atan2(g[1], g[0]), cfg)


def mirror_map(cfg: LidarConfig | None = None) -> tuple[NDArray[np.intp], NDArray[np.float32]]:
    """The mirror image (the world mirrored x → −x) of an observation as a gather and a sign:
    ``index (D,)`` and ``sign (D,)`` with mirror(o) = o[..., index] · sign, then every angle
    equal to −π read as π (:func:`mirror_observation`). Sector k comes from sector
    (K − k) mod K, the distances keep their sign and every angle φ becomes −φ. Exact for the
    centred layout with an odd group size (refused otherwise)."""
    cfg = cfg or LidarConfig()
    if cfg.sector_layout != "centred" or cfg.group_size % 2 == 0:
        raise ConfigError(
            expect(
                "a mirror-true observation",
                'sector_layout "centred" with an odd group_size',
                (cfg.sector_layout, cfg.group_size),
                "mirror only observations of the centred layout (the default)",
            )
        )
    k_count, b = cfg.n_sectors, cfg.n_nearest
    index = np.arange(cfg.obs_dim, dtype=np.intp)
    index[:k_count] = (-np.arange(k_count)) % k_count
    sign = np.ones(cfg.obs_dim, dtype=np.float32)
    sign[k_count + b :] = -1.0
    return index, sign


def mirror_observation(
    obs: NDArray[np.floating], cfg: LidarConfig | None = None
) -> NDArray[np.float32]:
    """The observation of the mirror-image state (the world mirrored x → −x), ``(..., D)``:
    sector k becomes sector (K − k) mod K, the distances stay and every angle φ becomes −φ
    (wrapped to (−π, π]) — :func:`mirror_map`. Exact for the centred layout with an odd group
    size, where observation(mirror(state)) = mirror_observation(observation(state)) up to the
    order of two equally near beams."""
    cfg = cfg or LidarConfig()
    index, sign = mirror_map(cfg)
    o = np.asarray(obs, dtype=np.float32)
    if o.shape[-1] != cfg.obs_dim:
        raise DataError(expect("observations", f"shape (..., {cfg.obs_dim})", o.shape, "fix it"))
    return apply_mirror(o, index, sign)


def apply_mirror(
    x: NDArray[np.floating], index: NDArray[np.intp], sign: NDArray[np.float32]
) -> NDArray[np.float32]:
    """``x (..., D)`` gathered by ``index`` and multiplied by ``sign`` (a :func:`mirror_map`),
    every value at or below −π read as π: float32 negation is exact, and (−π, π] maps onto
    itself with π ↦ π. (No distance or speed of an observation is ever that negative.)"""
    out: NDArray[np.float32] = np.asarray(x, dtype=np.float32)[..., index] * sign
    return np.where(out <= -np.float32(math.pi), -out, out)


def observation_from_scan(
    ranges: NDArray[np.floating] | list[float],
    angle_min: float,
    angle_increment: float,
    range_max: float,
    goal_xy_robot: tuple[float, float] | NDArray[np.float64],
    cfg: LidarConfig | None = None,
    range_min: float = 0.0,
    unseen: str = DEFAULT_UNSEEN,
) -> NDArray[np.float32]:
    """The 29-D observation from a real laser scan and the goal in the robot frame [m]
    (unseen directions filled by the ``unseen`` rule, module docstring)."""
    cfg = cfg or LidarConfig()
    beams = resample_scan(ranges, angle_min, angle_increment, range_max, cfg, range_min, unseen)
    return observation_from_beams(beams, goal_xy_robot, cfg)
