"""Layouts grouped by situation, each situation drawn equally often (the fine-tuning's
``stratify``; :mod:`pioneer.learn.finetune`).

A family of sampled layouts is drawn uniformly by default, so a situation is practised as
often as the sampler happens to produce it: crowded numbers of people and shallow lobbies are
placed less often and come out rare. Here each pattern's layouts are split by *situation* —
the number of people boarding, the number leaving the cabin, and whether the lobby is shallow
(the map reaches less than :data:`SHALLOW_LOBBY` below the door) — and a pattern's draws go
to its situations equally, then to a layout of the situation uniformly. Situations with fewer
than :data:`MIN_LAYOUTS` layouts are pooled into one (or, fewer than that together, join the
largest situation), so no single layout takes a situation's whole share. The patterns keep
their shares (each still drawn equally often), and the mastery curriculum
(:mod:`pioneer.learn.curriculum`) chooses among the situations instead of the families.
"""

from __future__ import annotations

from collections.abc import Sequence

from pioneer.sim.scenarios import get_scenario

__all__ = ["MIN_LAYOUTS", "SHALLOW_LOBBY", "by_situation", "situation"]

SHALLOW_LOBBY = 3.5  # [m] a lobby shallower than this (the layout distribution's lower bound)
MIN_LAYOUTS = 5  # situations with fewer layouts are pooled into one

Situation = tuple[int, int, bool]  # (boarding, exiting, shallow lobby)


def situation(name: str) -> Situation:
    """The situation of scenario ``name``: its people boarding and leaving the cabin (by
    role), and whether its map reaches less than :data:`SHALLOW_LOBBY` below the door."""
    sc = get_scenario(name)
    roles = [h.role for h in sc.humans]
    return roles.count("boarding"), roles.count("exiting"), -sc.bounds[2] < SHALLOW_LOBBY


def by_situation(pools: Sequence[Sequence[str]]) -> tuple[list[list[str]], list[float]]:
    """Split every pool of ``pools`` (drawn equally often) by situation: the new pools, in
    order (a pool's situations sorted, the small ones pooled last or joining the largest),
    and the probability of drawing each (a pool's share divided equally among its
    situations; they sum to 1)."""
    out: list[list[str]] = []
    weights: list[float] = []
    for pool in pools:
        groups: dict[Situation, list[str]] = {}
        for name in pool:
            groups.setdefault(situation(name), []).append(name)
        strata = [groups[k] for k in sorted(groups) if len(groups[k]) >= MIN_LAYOUTS]
        rest = [n for k in sorted(groups) if len(groups[k]) < MIN_LAYOUTS for n in groups[k]]
        if len(rest) >= MIN_LAYOUTS or not strata:
            strata.append(rest)
        elif rest:  # too few to be drawn as one: they join the largest situation
            max(strata, key=len).extend(rest)
        out += strata
        weights += [1.0 / (len(pools) * len(strata))] * len(strata)
    return out, weights
