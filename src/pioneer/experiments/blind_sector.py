"""Which fill rule for directions a scanner does not see: the shipped students driven by the
robot runtime in simulation, with a scanner of a narrower field of view (docs/deployment.md,
"A scanner that does not see all around").

Each step, :class:`ScannerPolicy` casts the simulator's 72 beams, keeps those within ±fov/2 of
the heading as a ``LaserScan`` (beam 0 at −fov/2, counter-clockwise, no return = ``+inf``) and
hands it to :meth:`StudentRuntime.step <pioneer.deploy.runtime.StudentRuntime.step>` with the
rule under test — the resampling, the fill, the scan health and the clipping are exactly the
robot's. The student is the shipped MDN of the scenario, exported to ONNX. Episodes use
validation seeds (:func:`pioneer.seeds.validation_seed`, purpose ``"blind-sector"``): this
study chooses a default. Each record of ``episodes.jsonl`` names what drove it in ``made_by``,
as the evaluation's records do (:func:`pioneer.eval.harness.made_by_record`): the scanner's
field of view, the runtime's settings, and the hashes of the student and its ONNX export.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pioneer.config import MAX_EPISODES, check_count, default
from pioneer.data import shipped_student
from pioneer.deploy.config import RuntimeConfig
from pioneer.deploy.runtime import StudentRuntime
from pioneer.errors import ConfigError, expect
from pioneer.eval.episode import run_episode
from pioneer.eval.harness import made_by_record
from pioneer.io import atomic_path, file_record, inside, output_dir, to_json
from pioneer.laser import UNSEEN_RULES, UnseenRule
from pioneer.learn.export import export_onnx
from pioneer.learn.models import load_student
from pioneer.seeds import validation_seed
from pioneer.sim.world import scan
from pioneer.stats import wilson_interval

__all__ = [
    "SCENARIOS",
    "SEED_PURPOSE",
    "ScannerPolicy",
    "run_blind_sector_study",
    "scanner_message",
]

SEED_PURPOSE = "blind-sector"
SCENARIOS = ("hr-rl-compact", "hl-rr-compact")  # where the shipped students were trained


def scanner_message(
    beams: NDArray[np.float64], fov_rad: float, max_range: float
) -> tuple[NDArray[np.float64], float, float]:
    """The part of the simulator's ``G`` beams ``(G,)`` [m] (beam 0 along the heading) that a
    scanner of field of view ``fov_rad`` centred on the heading sees, as a ``LaserScan``:
    ``(ranges, angle_min, angle_increment)``; a beam at ``max_range`` becomes ``+inf``."""
    g = beams.size
    inc = 2.0 * math.pi / g
    if not 0.0 < fov_rad <= 2.0 * math.pi:
        fix = f"use e.g. {default(run_blind_sector_study, 'fov_deg'):g}"
        raise ConfigError(expect("fov", "in (0°, 360°]", math.degrees(fov_rad), fix))
    if fov_rad >= 2.0 * math.pi - 1e-9:
        idx = np.arange(g)
        k = 0
    else:
        k = math.floor(0.5 * fov_rad / inc + 1e-9)
        idx = np.arange(-k, k + 1) % g
    r = beams[idx].astype(np.float64)
    r[r >= max_range] = np.inf
    return r, -k * inc, inc


class ScannerPolicy:
    """The robot runtime as a policy in the simulator, seeing through a scanner of field of
    view ``fov_rad`` (module docstring); ``stops`` counts its stop decisions by reason in the
    current episode."""

    def __init__(self, runtime: StudentRuntime, fov_rad: float, name: str) -> None:
        self.runtime = runtime
        self.fov_rad = fov_rad
        self.name = name
        self.stops: dict[str, int] = {}

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Start an episode (deterministic; ``rng`` is unused)."""
        self.stops = {}
        self.runtime.reset()

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """The runtime's command ``(v [m/s], ω [rad/s])`` on this step's scan, shape ``(2,)``."""
        world, state = info["world"], info["state"]
        beams = scan(world, state)[0]
        ranges, amin, inc = scanner_message(beams, self.fov_rad, world.sim.lidar.max_range)
        x, y, th = state.robot[0]
        dx, dy = state.goal[0] - (x, y)
        goal = (math.cos(th) * dx + math.sin(th) * dy, -math.sin(th) * dx + math.cos(th) * dy)
        d = self.runtime.step(ranges, amin, inc, world.sim.lidar.max_range, goal, age_s=0.0)
        if d.stop_reason is not None:
            self.stops[d.stop_reason] = self.stops.get(d.stop_reason, 0) + 1
        return np.array([d.v, d.omega])


def _made_by(
    scenario: str, student: Path, onnx: Path, fov_rad: float, config: RuntimeConfig
) -> dict[str, Any]:
    """A record's ``made_by`` for the :class:`ScannerPolicy` of one variant."""
    made = {
        "policy": f"{__name__}:{ScannerPolicy.__name__}",
        "params": {"fov_rad": fov_rad, "runtime": config.to_dict()},
        "files": {"checkpoint": file_record(student), "model": file_record(onnx)},
    }
    return made_by_record(made, scenario)


def _variants(fov_deg: float, rules: Sequence[UnseenRule]) -> list[tuple[str, float, UnseenRule]]:
    """``(label, fov [rad], rule)``: the full scanner (reference), then each rule at fov."""
    out = [("360°", 2.0 * math.pi, rules[0])]
    out += [(f"{fov_deg:g}° {rule}", math.radians(fov_deg), rule) for rule in rules]
    return out


def run_blind_sector_study(
    out_dir: str | Path,
    scenarios: Sequence[str] = SCENARIOS,
    episodes: int = 100,
    fov_deg: float = 270.0,
    rules: Sequence[UnseenRule] = UNSEEN_RULES,
) -> dict[str, Any]:
    """Run ``episodes`` validation episodes per scenario for the full scanner and for a
    ``fov_deg`` scanner under each rule; write ``episodes.jsonl`` and ``summary.json`` into
    ``out_dir`` and return the summary: per scenario and variant, n, successes, collisions,
    timeouts, the success rate with its 95 % Wilson interval and the stop counts."""
    bad = sorted(set(rules) - set(UNSEEN_RULES))
    if bad or not rules:
        raise ConfigError(expect("rules", f"some of {UNSEEN_RULES}", list(rules), "fix them"))
    if not 0.0 < fov_deg <= 360.0:
        fix = f"use e.g. {default(run_blind_sector_study, 'fov_deg'):g}"
        raise ConfigError(expect("--fov", "in (0°, 360°]", fov_deg, fix))
    if episodes < 1:
        fix = f"use e.g. {default(run_blind_sector_study, 'episodes')}"
        raise ConfigError(expect("--episodes", "an integer >= 1", episodes, fix))
    check_count(
        "episodes (scenarios × scanners × --episodes)",
        len(set(scenarios)) * (1 + len(rules)) * episodes,
        MAX_EPISODES,
        "ask for fewer --episodes",
    )
    from pioneer.sim.scenarios import get_scenario

    students = {sc: shipped_student(get_scenario(sc).name) for sc in scenarios}
    out = output_dir(out_dir)  # every input checked: only now is anything written
    summary: dict[str, Any] = {"fov_deg": fov_deg, "episodes": episodes, "seeds": SEED_PURPOSE}
    lines: list[str] = []
    for scenario in scenarios:
        onnx = export_onnx(load_student(students[scenario]), inside(out, f"{scenario}.onnx"))
        summary[scenario] = {}
        for label, fov, rule in _variants(fov_deg, rules):
            config = RuntimeConfig(unseen=rule)
            rt = StudentRuntime(onnx, config=config)
            policy = ScannerPolicy(rt, fov, f"student-onnx {label}")
            made = _made_by(scenario, students[scenario], onnx, fov, config)
            events = {"success": 0, "collision": 0, "timeout": 0}
            stops: dict[str, int] = {}
            for k in range(episodes):
                seed = validation_seed(SEED_PURPOSE, scenario, k)
                rec, _ = run_episode(scenario, policy, seed)
                events[rec.event] += 1
                for reason, c in policy.stops.items():
                    stops[reason] = stops.get(reason, 0) + c
                row = {"variant": label, **rec.to_dict(), "stops": policy.stops, "made_by": made}
                lines.append(to_json(row))
            lo, hi = wilson_interval(events["success"], episodes)
            summary[scenario][label] = {
                "n": episodes,
                **events,
                "success_rate": events["success"] / episodes,
                "success_ci95": [lo, hi],
                "stops": stops,
            }
            print(to_json({"scenario": scenario, "variant": label, **events}), flush=True)
    with atomic_path(out / "episodes.jsonl") as tmp:
        tmp.write_text("".join(line + "\n" for line in lines))
    with atomic_path(out / "summary.json") as tmp:
        tmp.write_text(to_json(summary, indent=2) + "\n")
    return summary
