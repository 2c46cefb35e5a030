"""What ``pioneer reproduce`` runs: how much (the profiles), on which scenarios, and the rows
of the paper's tables and ours beside them."""

from __future__ import annotations

import dataclasses

from pioneer.data import STUDENT_SEEDS
from pioneer.eval.episode import RISKY_DISTANCE_M
from pioneer.eval.harness import PolicySpec

__all__ = [
    "ARRIVING",
    "BASELINES",
    "CLASSIC",
    "PAPER_ROWS",
    "PAPER_STUDENT",
    "PAPER_TEACHERS",
    "PROFILES",
    "SCENARIOS",
    "SHIELD",
    "STUDENTS",
    "TEACHERS",
    "UNCERTAINTY_KEY",
    "Profile",
    "seed_row",
    "student_specs",
]


@dataclasses.dataclass(frozen=True)
class Profile:
    """How much to run."""

    seeds: int
    trials: int


PROFILES = {
    "smoke": Profile(seeds=1, trials=1),  # the whole pipeline in a minute (tests, CI)
    "quick": Profile(seeds=2, trials=10),
    "paper": Profile(seeds=5, trials=100),
}
SCENARIOS = ("hr-rl", "hl-rr")
# paper Tables I–II: the paper's teacher (no soft margins, the stop fallback) and its ablations,
# the rows compared with the paper; beside them ours (soft margins in tiers, the evade
# fallback: docs/teacher.md), the teacher the students imitate, and its ablations
PAPER_TEACHERS = (
    "teacher-paper",
    "teacher-paper-no-density",
    "teacher-paper-no-goal",
    "teacher-paper-no-obstacle",
)
TEACHERS = ("teacher", "teacher-no-density", "teacher-no-goal", "teacher-no-obstacle")
STUDENTS = ("student-mdn", "student-mlp")  # paper Table III, the shipped DAgger students
PAPER_STUDENT = "student-mdn-paper"  # the paper's DAgger recipe, as a measured row
SHIELD = "student-shield"  # beyond the paper: the MDN handing over to the teacher when unsure
BASELINES = ("cvar-bf", "crowdnav++")  # paper Table I (CrowdNav++: pure PPO, its own recipe)
# beyond the paper, in Table I: CrowdNav++ as its authors' family would train it here (an
# imitation warm start, then PPO on the CrowdNav++ reward without its intrusion term)
ARRIVING = ("crowdnav++-il-teacher",)
# beyond the paper, in Table I: classic references and Stable-Baselines3's PPO with its
# defaults on the environment's own reward
CLASSIC = ("dwa", "sfm", "goal", "sb3-ppo")
PAPER_ROWS = (*PAPER_TEACHERS, *BASELINES, *STUDENTS)  # the rows of the paper's Tables I–IV
SEED_ROW = "{name}-s{seed}"  # the row of a student's other DAgger seeds (seed 0: its name)
# uncertainty.json: the key of the safe/risky split at the paper's threshold (Table IV)
UNCERTAINTY_KEY = f"threshold_{RISKY_DISTANCE_M:g}m"


def student_specs() -> list[PolicySpec]:
    """Table III's students: each shipped recipe (and the paper's) at every DAgger seed of
    :data:`pioneer.data.STUDENT_SEEDS`; seed 0 is the row of its name."""
    return [
        PolicySpec.make(name, label=seed_row(name, seed), seed=seed)
        for name in (*STUDENTS, PAPER_STUDENT)
        for seed in STUDENT_SEEDS
    ]


def seed_row(name: str, seed: int) -> str:
    """The row label of a student's DAgger ``seed`` (seed 0: its name)."""
    return name if seed == 0 else SEED_ROW.format(name=name, seed=seed)
