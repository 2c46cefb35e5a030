"""``pioneer scenarios`` (list and draw the worlds) and ``pioneer calibrate`` (their
statistics beside the paper's evidence)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import tyro

from pioneer.cli._files import OutDir, OutFile, Output
from pioneer.cli._options import Flag, Seed, Workers, metavar, optional, require_some
from pioneer.cli._parse import config_flags
from pioneer.cli._text import number
from pioneer.config import default
from pioneer.experiments.calibration import calibrate
from pioneer.experiments.reproduce_plan import SCENARIOS
from pioneer.io import inside, output_dir
from pioneer.sim.scenarios.distribution import (
    MIN_PLACEMENT_RATE,
    LayoutDistribution,
    draw_variants,
    sample_variants,
)
from pioneer.sim.scenarios.registry import PLACEMENT_CHECK_SEEDS, check_placement

if TYPE_CHECKING:
    from pioneer.sim.scenarios import ScenarioConfig

__all__ = ["Calibrate", "SampleLayouts", "Scenarios"]

config_flags(LayoutDistribution)  # its ranges are sample-layouts' flags (--human-radius LO HI …)


@dataclasses.dataclass(frozen=True)
class Scenarios:
    """List the scenarios (built-in and from --scenarios files); optionally draw each."""

    png_dir: Annotated[str | None, optional("DIR", "draw none"), Output("folder")] = None
    """write one PNG per scenario (its layout and a start state)"""
    seed: Seed = 0
    """seed of the drawn start state"""

    def run(self) -> int:
        """Print one row per scenario; draw them if asked. "placed [%]" is the share of
        start-state draws that placed every body for the seeds a scenario file is checked with:
        how tight the start regions are (``sample-layouts`` keeps layouts of at least
        ``MIN_PLACEMENT_RATE``; a start state gives up after ``spec.MAX_TRIES`` draws)."""
        from pioneer.data import base_scenario
        from pioneer.sim.scenarios import get_scenario, scenario_names

        def placement_rate(cfg: ScenarioConfig) -> float:
            return 100.0 * PLACEMENT_CHECK_SEEDS / check_placement(cfg.name, cfg)

        configs = {name: get_scenario(name) for name in scenario_names()}
        head = f"{'scenario':<24} {'learned parts of':<16} {'humans':>6} {'map [m]':>11}"
        print(f"{head} {'placed [%]':>10} {'limit [s]':>9}")
        for name, cfg in configs.items():
            xmin, xmax, ymin, ymax = cfg.bounds
            size = f"{xmax - xmin:.1f} × {ymax - ymin:.1f}"
            print(
                f"{name:<24} {base_scenario(name):<16} {len(cfg.humans):>6} {size:>11} "
                f"{placement_rate(cfg):>10.3g} {cfg.sim.time_limit:>9.1f}"
            )
        if self.png_dir:
            self._draw(configs, Path(self.png_dir))
        return 0

    def _draw(self, configs: dict[str, ScenarioConfig], out: Path) -> None:
        import numpy as np

        from pioneer.progress import progress_bar
        from pioneer.sim.scenarios import sample_state
        from pioneer.viz import plot_trajectory

        output_dir(out)
        for name, cfg in progress_bar(configs.items(), desc="layouts", unit="png"):
            state = sample_state(cfg, np.random.default_rng(self.seed))
            title = f"{name} · initial state, seed {self.seed}"
            plot_trajectory(cfg.world(), [state], inside(out, f"{name}.png"), title=title)
        print(f"wrote {len(configs)} layouts to {out}")


@dataclasses.dataclass(frozen=True)
class Calibrate:
    """World statistics beside the paper's evidence, on validation seeds (writes
    OUT/calibration.json)."""

    out: OutDir
    """folder for calibration.json"""
    scenario: Annotated[tuple[str, ...], metavar("NAME")] = SCENARIOS
    """hr-rl hl-rr …"""
    episodes: int = default(calibrate, "episodes")
    """validation episodes per scenario"""
    workers: Workers = None
    """processes"""
    driver: str = default(calibrate, "driver")
    """policy behind the teacher_* statistics"""

    def run(self) -> int:
        """Calibrate; print one line of statistics per scenario (OUT: outside the band)."""
        from pioneer.experiments.calibration import BANDS

        require_some("--scenario", self.scenario)
        res = calibrate(self.scenario, self.episodes, self.out, self.workers, driver=self.driver)
        for name, st in res["scenarios"].items():
            cells = []
            for key in (*BANDS, "teacher_risky_frame_share_gap", "risky_at_start_share"):
                lo_hi = BANDS.get(key)
                mark = "" if lo_hi is None else (" ok" if st["within_band"][key] else " OUT")
                cells.append(f"{key} {number(st[key], '.3g')}{mark}")
            print(f"{name}: " + "; ".join(cells))
        print(f"wrote {Path(self.out) / 'calibration.json'} ({res['elapsed_s']:.0f} s)")
        return 0


def _counts_drawn(variants: dict[str, dict[str, Any]]) -> str:
    """How many layouts have each number of boarders and of exiting passengers: a redrawn
    draw is more often a crowded one, so without ``--keep-counts`` these can fall short of the
    ranges asked for."""
    from collections import Counter

    from pioneer.sim.scenarios.layouts import ElevatorLayout

    paper = ElevatorLayout()
    parts = []
    for key, what in (("n_boarding", "boarders"), ("n_exiting", "exiting passengers")):
        n = Counter(int(v["elevator"].get(key, getattr(paper, key))) for v in variants.values())
        parts.append(f"{what} " + ", ".join(f"{k}: {n[k]}" for k in sorted(n)))
    return "layouts with " + "; ".join(parts)


@dataclasses.dataclass(frozen=True)
class SampleLayouts:
    """Draw valid elevator layouts from the randomised distribution (LayoutDistribution) into
    a scenario file, for `pioneer --scenarios FILE …` (e.g. the general student)."""

    out: OutFile
    """scenario file to write (JSON, format pioneer.scenarios/1)"""
    n: int = 200
    """layouts to draw"""
    seed: Seed = 0
    """seed of the draws"""
    prefix: str = default(sample_variants, "prefix")
    """variant names: PREFIX-0000, PREFIX-0001, …"""
    dist: tyro.conf.OmitArgPrefixes[LayoutDistribution] = LayoutDistribution()
    overwrite: Flag = False
    """replace an existing --out (otherwise refused: a file you made is never replaced)"""

    def run(self) -> int:
        """Draw (with a progress bar), write the file, print a summary line. Stopped by
        Ctrl-C or SIGTERM, it writes the layouts drawn so far: a scenario file of its own."""
        from pioneer.interrupt import Interrupted, kept
        from pioneer.io import check_name
        from pioneer.progress import progress_bar

        check_name("--prefix", self.prefix)  # the variants' names become file names
        variants: dict[str, dict[str, object]] = {}
        rejected = 0
        draws = draw_variants(self.dist, self.n, self.seed, self.prefix)
        try:
            with kept(lambda: self._kept(len(variants)), resumes=False):
                for name, entry, so_far in progress_bar(
                    draws, total=self.n, desc="layouts", unit="layout"
                ):
                    variants[name], rejected = entry, so_far
        except Interrupted:
            if variants:
                self._write(variants, rejected)
            raise
        self._write(variants, rejected)
        print(
            f"{len(variants)} layouts ({rejected} draws redrawn: their bodies not placed, or "
            f"placed in under {MIN_PLACEMENT_RATE:.0%} of the start-state draws): ",
            end="",
        )
        print(self.out)
        print(_counts_drawn(variants))
        return 0

    def _kept(self, done: int) -> str:
        """What a stopped run keeps (:func:`pioneer.interrupt.kept`)."""
        if not done:
            return f"0 of {self.n} layouts drawn, nothing written"
        return (
            f"{done} of {self.n} layouts kept in {self.out} (a scenario file of those; "
            f"to draw all {self.n}, run the command again with --overwrite)"
        )

    def _write(self, variants: dict[str, dict[str, object]], rejected: int) -> None:
        """The scenario file of ``variants`` (written whole or not at all)."""
        from pioneer.io import to_json, write_text_atomic
        from pioneer.sim.scenarios import SCENARIO_FILE_FORMAT

        doc = {
            "format": SCENARIO_FILE_FORMAT,
            "distribution": {
                **self.dist.to_dict(),
                "seed": self.seed,
                "rejected_draws": rejected,
                "min_placement_rate": MIN_PLACEMENT_RATE,
            },
            "scenarios": variants,
        }
        write_text_atomic(self.out, to_json(doc, indent=1) + "\n")
