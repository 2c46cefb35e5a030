"""``pioneer demos generate|show`` and ``pioneer teleop``: demonstration datasets."""

from __future__ import annotations

import dataclasses
from typing import Annotated

import tyro

from pioneer.cli._files import OutFile
from pioneer.cli._options import Flag, Seed, metavar, optional
from pioneer.cli._parse import config_flags
from pioneer.cli._text import command_line
from pioneer.config import default
from pioneer.demos.generate import Demonstrator, Selection, generate
from pioneer.demos.teleop import TeleopSession
from pioneer.io import to_json
from pioneer.sim.scenarios import DEFAULT_SCENARIO

__all__ = ["DemosGenerate", "DemosShow", "Teleop"]

config_flags(
    Selection,
    max_time_s=tyro.conf.arg(name="max_time", metavar="S"),
    max_path_m=tyro.conf.arg(name="max_path", metavar="M"),
    min_gap_m=tyro.conf.arg(name="min_gap", metavar="M"),
)


@dataclasses.dataclass(frozen=True)
class DemosGenerate:
    """Demonstrations (γ = +1 and −1) of one scenario, saved as a dataset (.npz): efficient
    successes of a demonstrator (+1), a careless driver's collisions (−1)."""

    scenario: str
    """hr-rl, hl-rr or static"""
    out: OutFile
    """output .npz"""
    positive: Annotated[int | None, optional("N", "the paper's count")] = None
    """positive samples"""
    negative: Annotated[int | None, optional("N", "the paper's count")] = None
    """negative samples"""
    seed: Seed = default(generate, "seed")
    """seed of the first episode"""
    demonstrator: Demonstrator = default(generate, "demonstrator")
    """positives from the rules-only teacher or the scripted courteous driver"""
    selection: tyro.conf.OmitArgPrefixes[Selection] = Selection()
    """which successful episodes make positive demonstrations"""
    overwrite: Flag = False
    """replace an existing --out (otherwise refused: a file you made is never replaced)"""

    def run(self) -> int:
        """Generate and save; print the dataset's summary (JSON)."""
        d = generate(
            self.scenario,
            self.positive,
            self.negative,
            seed=self.seed,
            command=command_line(),
            demonstrator=self.demonstrator,
            selection=self.selection,
        )
        d.save(self.out)
        print(to_json({"out": self.out, **d.summary()}))
        return 0


@dataclasses.dataclass(frozen=True)
class DemosShow:
    """The summary of a dataset file (JSON)."""

    demos: Annotated[str, tyro.conf.Positional, metavar("FILE")]
    """the dataset (.npz)"""

    def run(self) -> int:
        """Load and summarise (without the per-feature names and units)."""
        from pioneer.reward.dataset import Dataset

        d = Dataset.load(self.demos)
        meta = {k: v for k, v in d.meta.items() if k not in ("feature_names", "units")}
        print(to_json({**d.summary(), "meta": meta}, indent=2))
        return 0


@dataclasses.dataclass(frozen=True)
class Teleop:
    """Drive with the keyboard and record labelled demos (needs pygame-ce)."""

    out: OutFile
    """dataset .npz (appended to after every episode)"""
    scenario: str = DEFAULT_SCENARIO
    """hr-rl, hl-rr, static, …"""
    seed: Seed = default(TeleopSession, "seed")
    """episode k is seeded seed + k"""
    max_episodes: Annotated[int | None, optional("N", "until you quit")] = None
    """stop after this many saved episodes"""

    def run(self) -> int:
        """Run the session; print its summary (JSON)."""
        session = TeleopSession(
            self.scenario,
            self.out,
            seed=self.seed,
            max_episodes=self.max_episodes,
            command=command_line(),
        )
        print(to_json(session.run()))
        return 0
