"""A randomised distribution of elevator layouts and human behaviour, for one student that
drives in many worlds (beyond the paper; docs/general-student.md).

:class:`LayoutDistribution` holds the ranges (door and lobby size, cabin, number, speed and size
of the humans, their reaction to the robot, LiDAR noise, which side they board); the start
regions follow the geometry by the proportions of the paper world (a 4 × 4 m lobby gives
exactly its regions). :func:`sample_variants` draws ``n`` valid layouts from a seed and
returns them as scenario-file entries (``pioneer.scenarios/1``, each with the built-in ``base``
of its side, whose demonstrations give the teacher's reward); a draw that cannot place its
bodies for the start seeds a scenario file is checked with, or places them in fewer than
:data:`MIN_PLACEMENT_RATE` of its start-state draws (too tight to be sure of every other
seed), is redrawn, and counted. Crowded draws are the ones redrawn most, so the numbers of
boarders and passengers come out below their ranges; ``keep_counts`` draws them first and
redraws only the rest.

    pioneer sample-layouts --n 200 --seed 0 --out runs/general/layouts.json
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from typing import Annotated, Any, cast

import numpy as np
from annotated_types import MinLen

from pioneer.bounds import NonNegative, NonNegativeInt, UnitInterval
from pioneer.config import Config, Ordered, check_count
from pioneer.errors import ConfigError, PioneerError, ScenarioError, expect
from pioneer.io import check_name
from pioneer.sim.scenarios.layouts import ElevatorLayout, HumanSide, elevator_scenario
from pioneer.sim.scenarios.registry import PLACEMENT_CHECK_SEEDS, check_placement
from pioneer.sim.world import SimConfig

__all__ = [
    "MAX_LAYOUTS",
    "MIN_PLACEMENT_RATE",
    "LayoutDistribution",
    "draw_counts",
    "draw_variants",
    "sample_layout",
    "sample_variants",
]

Range = Annotated[tuple[NonNegative, NonNegative], Ordered()]  # 0 <= low <= high
Counts = Annotated[tuple[NonNegativeInt, NonNegativeInt], Ordered()]  # 0 <= low <= high, inclusive
PAPER = ElevatorLayout()  # the paper world: the reference of the proportions
MAX_DRAWS = 50  # draws per accepted layout before giving up
MAX_LAYOUTS = 100_000  # layouts one call may draw (a scenario file of ≈ 20 MB)
# A kept layout must place its bodies in at least this share of start-state draws (estimated
# on the start seeds a scenario file is checked with). A start state gives up after
# spec.MAX_TRIES = 2000 draws; at a true rate of 1 % that happens once in e^20 episodes,
# while layouts of 0.2–0.3 % passed the 50 seeds and then stopped a DAgger run in the middle.
MIN_PLACEMENT_RATE = 0.02
QUEUE_FRONT_Y = -2.7  # [m] the front of the boarders' start rows when three or more queue
QUEUE_BEYOND = 0.4  # [m] keep_counts: how far beyond the lobby's open far side they may queue


@dataclasses.dataclass(frozen=True)
class LayoutDistribution(Config):
    """Uniform ranges of the randomised elevator world (the paper world is inside every one)."""

    error_type = ScenarioError

    lobby_width: Range = (3.5, 5.0)  # [m]
    lobby_depth: Range = (3.5, 5.0)  # [m]
    cabin_width: Range = (2.2, 2.8)  # [m]
    cabin_depth: Range = (2.3, 3.0)  # [m]
    door_width: Range = (1.4, 2.2)  # [m] (capped by the cabin width)
    n_boarding: Counts = (1, 3)  # humans boarding from the lobby
    n_exiting: Counts = (0, 2)  # humans leaving the cabin
    human_radius: Range = (0.3, 0.6)  # [m]
    v_pref_scale: Range = (0.8, 1.3)  # × the paper's (0.5, 0.6, 0.7) m/s
    a_robot: Range = (0.0, 2.0)  # [m/s²] the humans' reaction to the robot (0: invisible)
    reacts_share: UnitInterval = 0.8  # probability that a group (boarders, exiting) reacts at all
    lidar_noise: Range = (0.0, 0.03)  # [m] Gaussian range noise σ
    queue_share: UnitInterval = 1.0  # probability that the boarders let the exiting out first
    # probability that the exiting passengers may start anywhere in the cabin's depth (else in
    # its front part, ElevatorLayout's default r_h + 0.3 … r_h + 0.9 m)
    deep_exit_share: UnitInterval = 0.0
    # the humans' sides to draw from: "right" → HR-RL, "left" → HL-RR
    sides: Annotated[tuple[HumanSide, ...], MinLen(1)] = ("right", "left")
    # draw the numbers of boarders and exiting passengers once per layout and redraw only
    # the rest until its bodies are placed, so the numbers follow their ranges (two or more
    # exiting passengers then start anywhere in the cabin's depth, and three or more boarders
    # queue from QUEUE_BEYOND beyond the lobby's open far side); off, the whole draw is
    # redrawn, and crowded numbers, placed less often, come out rarer than their ranges say
    # (two passengers hardly ever)
    keep_counts: bool = False


def sample_layout(
    dist: LayoutDistribution,
    rng: np.random.Generator,
    counts: tuple[int, int] | None = None,
) -> tuple[ElevatorLayout, SimConfig]:
    """One draw of the distribution (not yet checked for placement); ``counts``: the numbers
    of boarders and exiting passengers, already drawn (:func:`draw_counts`)."""

    def u(r: Range) -> float:
        return round(float(rng.uniform(*r)), 3)

    def k(r: tuple[int, int]) -> int:
        return _integer(rng, r)

    def p(share: float) -> bool:  # no draw at 0 or 1: the draws of other layouts stay the same
        return share >= 1.0 or (share > 0.0 and bool(rng.random() < share))

    w, d = u(dist.lobby_width), u(dist.lobby_depth)
    cabin_w = min(u(dist.cabin_width), w)
    sw, sd = w / PAPER.lobby_width, d / PAPER.lobby_depth  # the paper world's proportions
    n_boarding = k(dist.n_boarding) if counts is None else counts[0]
    scale = u(dist.v_pref_scale)
    boarder_y = _scaled(PAPER.boarder_y, sd)
    if n_boarding >= 3:  # they queue in depth: give them the whole back of the lobby
        # keep_counts: from QUEUE_BEYOND beyond its open far side, as the compact rule and
        # the three-boarders example do (else three 0.45 m bodies fit only in deep lobbies)
        back = -(d + QUEUE_BEYOND) if counts is not None else boarder_y[0]
        boarder_y = (round(back, 3), round(QUEUE_FRONT_Y * sd, 3))
    exit_turn = _scaled(PAPER.exit_waypoints[0] if PAPER.exit_waypoints else None, sw, sd)
    layout = ElevatorLayout(
        human_side=cast(HumanSide, str(rng.choice(list(dist.sides)))),
        cabin_width=cabin_w,
        cabin_depth=u(dist.cabin_depth),
        door_width=min(u(dist.door_width), cabin_w),
        lobby_width=w,
        lobby_depth=d,
        n_boarding=n_boarding,
        n_exiting=k(dist.n_exiting) if counts is None else counts[1],
        human_radius=u(dist.human_radius),
        v_pref_choices=tuple(round(v * scale, 3) for v in PAPER.v_pref_choices),
        robot_start_y=_scaled(PAPER.robot_start_y, sd),
        boarder_x=_scaled(PAPER.boarder_x, sw),
        boarder_y=boarder_y,
        exit_waypoints=(exit_turn,),
        boarders_react_to_robot=bool(rng.random() < dist.reacts_share),
        exiting_react_to_robot=bool(rng.random() < dist.reacts_share),
    )
    base = SimConfig()
    sim = dataclasses.replace(
        base,
        social_force=dataclasses.replace(base.social_force, a_robot=u(dist.a_robot)),
        lidar=dataclasses.replace(base.lidar, noise_std=u(dist.lidar_noise)),
    )
    if not p(dist.queue_share):
        layout = dataclasses.replace(layout, boarders_queue=False)
    deep_crowd = counts is not None and counts[1] >= 2  # keep_counts: room for two or more
    if p(dist.deep_exit_share) or deep_crowd:  # from just inside the door to the back wall
        r_h = layout.human_radius
        deep = (round(r_h + 0.1, 3), round(layout.cabin_depth - r_h - layout.margin, 3))
        layout = dataclasses.replace(layout, exit_start_y=deep)
    return layout, sim


def draw_counts(dist: LayoutDistribution, rng: np.random.Generator) -> tuple[int, int]:
    """The numbers of boarders and exiting passengers of one layout, each uniform over its
    range (``keep_counts``: drawn once, before the rest is redrawn until placed)."""
    n_boarding = _integer(rng, dist.n_boarding)
    return n_boarding, _integer(rng, dist.n_exiting)


def _integer(rng: np.random.Generator, r: tuple[int, int]) -> int:
    """An integer uniform over the inclusive range ``r``."""
    return int(rng.integers(r[0], r[1] + 1))


def _scaled(
    pair: tuple[float, float] | None, s0: float, s1: float | None = None
) -> tuple[float, float]:
    """A pair of the paper world (a range or a point) scaled by ``s0`` (the second item by
    ``s1``, default ``s0``), rounded to the millimetre."""
    if pair is None:
        raise ValueError("the paper world sets every range it scales")  # pragma: no cover
    return round(pair[0] * s0, 3), round(pair[1] * (s0 if s1 is None else s1), 3)


def _changed(cfg: Config, default: Config) -> dict[str, Any]:
    """The fields of ``cfg`` that differ from ``default`` (nested configs as dicts)."""
    out: dict[str, Any] = {}
    mine, ref = cfg.to_dict(), default.to_dict()
    for key, value in mine.items():
        if value != ref[key]:
            out[key] = (
                {k: v for k, v in value.items() if v != ref[key][k]}
                if isinstance(value, dict)
                else value
            )
    return out


def sample_variants(
    dist: LayoutDistribution, n: int, seed: int, prefix: str = "general"
) -> tuple[dict[str, dict[str, Any]], int]:
    """``n`` valid layouts drawn from ``seed`` as scenario-file entries ``{name: entry}``, and
    the number of draws rejected because their bodies could not be placed."""
    variants: dict[str, dict[str, Any]] = {}
    rejected = 0
    for name, entry, so_far in draw_variants(dist, n, seed, prefix):
        variants[name], rejected = entry, so_far
    return variants, rejected


def draw_variants(
    dist: LayoutDistribution, n: int, seed: int, prefix: str = "general"
) -> Iterator[tuple[str, dict[str, Any], int]]:
    """The ``n`` valid layouts of :func:`sample_variants` one at a time, as they are drawn:
    ``(name, scenario-file entry, draws rejected so far)``. ``n`` is checked against
    :data:`MAX_LAYOUTS` and the prefix at once, before the first draw."""
    if n < 1:
        raise ScenarioError(expect("layouts to draw", "n >= 1", n, "ask for at least one"))
    check_count("layouts to draw (--n)", n, MAX_LAYOUTS, "ask for fewer, in several files")
    try:  # the variants' names are PREFIX-0000, …: file names in the runs that use them
        check_name("layout name prefix (--prefix)", prefix)
    except ConfigError as exc:
        raise ScenarioError(str(exc)) from None
    return _draws(dist, n, seed, prefix)


def _draws(
    dist: LayoutDistribution, n: int, seed: int, prefix: str
) -> Iterator[tuple[str, dict[str, Any], int]]:
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x6E0E]))
    rejected = 0
    budget = PLACEMENT_CHECK_SEEDS / MIN_PLACEMENT_RATE  # [draws] beyond it the rate is too low
    unplaceable: set[tuple[int, int]] = set()  # keep_counts: numbers no geometry held
    for index in range(n):
        name = f"{prefix}-{index:04d}"
        counts = _placeable_counts(dist, rng, unplaceable)
        while True:
            found = None
            for _ in range(MAX_DRAWS):
                layout, sim = sample_layout(dist, rng, counts)
                try:
                    scenario = elevator_scenario(layout, sim=sim, name=name)
                    draws = check_placement(name, scenario, budget)
                except PioneerError:
                    rejected += 1
                    continue
                if draws > budget:
                    rejected += 1  # placeable for these seeds, but too tight to be sure for all
                    continue
                found = layout, sim
                break
            if found is not None or counts is None:
                break
            unplaceable.add(counts)  # these numbers do not fit: others, from now on
            counts = _placeable_counts(dist, rng, unplaceable)
        if found is None:
            raise ScenarioError(
                expect(
                    "layout distribution",
                    f"a placeable layout within {MAX_DRAWS} draws",
                    "none",
                    "widen the lobby ranges or shrink the humans",
                )
            )
        layout, sim = found
        entry = {
            "elevator": _changed(layout, ElevatorLayout()) | {"human_side": layout.human_side},
            "sim": _changed(sim, SimConfig()),
            "base": "hr-rl" if layout.human_side == "right" else "hl-rr",
        }
        yield name, entry, rejected


def _placeable_counts(
    dist: LayoutDistribution, rng: np.random.Generator, unplaceable: set[tuple[int, int]]
) -> tuple[int, int] | None:
    """``keep_counts``: numbers of boarders and passengers drawn uniformly among those not yet
    found unplaceable (``None`` without ``keep_counts``)."""
    if not dist.keep_counts:
        return None
    (b0, b1), (e0, e1) = dist.n_boarding, dist.n_exiting
    every = [(b, e) for b in range(b0, b1 + 1) for e in range(e0, e1 + 1)]
    if all(c in unplaceable for c in every):
        raise ScenarioError(
            expect(
                "layout distribution",
                "numbers of boarders and exiting passengers whose bodies can be placed",
                f"none of {sorted(unplaceable)} within {MAX_DRAWS} draws each",
                "widen the lobby ranges or shrink the humans",
            )
        )
    while True:
        counts = draw_counts(dist, rng)
        if counts not in unplaceable:
            return counts
