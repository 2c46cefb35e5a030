"""Data shipped with the package: default demonstration datasets, trained students and
baselines, and the measured episode times of the reference machine."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pioneer.errors import DataError, expect

__all__ = [
    "CROWDNAV_VARIANTS",
    "DEFAULT_STUDENT_KIND",
    "EPISODE_TIMES",
    "STUDENT_LABEL_PREV",
    "STUDENT_PREVIOUS_COMMAND",
    "STUDENT_SEEDS",
    "STUDENT_SELECT_EPISODES",
    "base_scenario",
    "shipped_crowdnav_weights",
    "shipped_demos",
    "shipped_sb3_weights",
    "shipped_student",
    "shipped_student_for",
]

DEMOS_DIR = Path(__file__).parent / "demos"
STUDENTS_DIR = Path(__file__).parent / "students"
BASELINES_DIR = Path(__file__).parent / "baselines"
# Seconds per episode of every policy on the reference machine, read by `pioneer reproduce`
# for its expected time and written by benchmarks/episode_times.py (docs/performance.md).
EPISODE_TIMES = Path(__file__).parent / "episode_times.json"
# The shipped student a policy loads when not told which kind: the paper's MDN (§V-B.2).
DEFAULT_STUDENT_KIND = "mdn"
STUDENT_SEEDS = (0, 1, 2)  # the DAgger seeds of the shipped students (Table III)
# validation episodes that chose each shipped student among its run's rounds (--select-episodes)
STUDENT_SELECT_EPISODES = 100
# the label's u_{t-1} (--label-prev) of every shipped student, chosen on validation episodes:
# the teacher's own previous label (docs/notes/2026-11-25-why-the-students-crash.md)
STUDENT_LABEL_PREV = "teacher"
# whether each shipped kind also reads its own last command u_{t-1} (--previous-command),
# chosen on validation episodes: it helps the MDN, not the MLP
# (docs/student.md, "The shipped recipe")
STUDENT_PREVIOUS_COMMAND = {"mdn": True, "mlp": False}


def base_scenario(scenario: str) -> str:
    """The scenario whose shipped demos and students serve ``scenario``: the built-in
    ``base`` it was registered with (``hr-rl-r03`` → ``hr-rl``; a scenario file's variant →
    the ``base`` it names), else itself (:func:`pioneer.sim.scenarios.scenario_base`)."""
    from pioneer.sim.scenarios import scenario_base

    return scenario_base(scenario)


def shipped_demos(scenario: str) -> Path:
    """Path of the shipped demonstration file for ``scenario``."""
    p = DEMOS_DIR / f"{base_scenario(scenario)}.npz"
    if not p.is_file():
        names = sorted(q.stem for q in DEMOS_DIR.glob("*.npz"))
        raise DataError(
            expect(
                "shipped demos",
                f"one of {names}",
                scenario,
                "pass your own demos/reward file, or give the variant a built-in 'base'",
            )
        )
    return p


def shipped_student_for(scenario: str, params: Mapping[str, Any]) -> Path:
    """The shipped student a student policy's parameters name (``kind``, ``general``,
    ``seed``, ``recipe``; each defaulting as in :func:`shipped_student`)."""
    return shipped_student(
        scenario,
        str(params.get("kind") or DEFAULT_STUDENT_KIND),
        bool(params.get("general")),
        int(params.get("seed", 0)),
        str(params.get("recipe", "")),
    )


def shipped_student(
    scenario: str,
    kind: str = DEFAULT_STUDENT_KIND,
    general: bool = False,
    seed: int = 0,
    recipe: str = "",
) -> Path:
    """Path of the shipped DAgger-trained student (``kind`` "mdn" | "mlp") for ``scenario``;
    ``general``: the one student for many worlds (``general-KIND``), whatever the scenario.
    ``seed``: its DAgger seed (one of :data:`STUDENT_SEEDS`; seed 0 is the default student);
    ``recipe``: another recipe than the shipped one (``"paper"``: the paper's, §V-B.2)."""
    stem = f"general-{kind}" if general else f"{base_scenario(scenario)}-{kind}"
    stem += f"-{recipe}" if recipe else ""
    stem += f"-s{seed}" if seed else ""
    p = STUDENTS_DIR / f"{stem}.safetensors"
    if not p.is_file():
        names = sorted(q.stem for q in STUDENTS_DIR.glob("*.safetensors"))
        raise DataError(
            expect(
                "shipped student",
                f"one of {names}",
                stem,
                "train one with `pioneer distill` and pass checkpoint=PATH, or give the variant"
                " a built-in 'base'",
            )
        )
    return p


# variant → file-name prefix: pure PPO (the `crowdnav++` row), imitation of sfm + PPO (compact
# world, `crowdnav++-il`), imitation of the teacher + PPO without the intrusion term
# (`crowdnav++-il-teacher`)
CROWDNAV_VARIANTS = {"ppo": "crowdnav", "il": "crowdnav-il", "il-teacher": "crowdnav-il-teacher"}


def shipped_crowdnav_weights(scenario: str, variant: str = "ppo") -> Path:
    """Path of the shipped CrowdNav++ weights for ``scenario``: ``variant`` "ppo" (pure PPO, the
    original's recipe: ``baselines/crowdnav-NAME``), "il" (imitation of sfm + PPO:
    ``baselines/crowdnav-il-NAME``) or "il-teacher" (imitation of the teacher + PPO without the
    intrusion term: ``baselines/crowdnav-il-teacher-NAME``)."""
    if variant not in CROWDNAV_VARIANTS:
        raise DataError(
            expect("CrowdNav++ variant", f"one of {sorted(CROWDNAV_VARIANTS)}", variant, "pick one")
        )
    return _shipped_baseline(CROWDNAV_VARIANTS[variant], scenario, "CrowdNav++", "crowdnav++")


def shipped_sb3_weights(scenario: str) -> Path:
    """Path of the shipped Stable-Baselines3 PPO policy for ``scenario``
    (``baselines/sb3-ppo-NAME``, the ``sb3-ppo`` row)."""
    return _shipped_baseline("sb3-ppo", scenario, "sb3-ppo", "sb3-ppo")


def _shipped_baseline(prefix: str, scenario: str, what: str, command: str) -> Path:
    """``baselines/PREFIX-NAME.safetensors`` for ``scenario``'s base, or one :class:`DataError`
    naming the files there and how to train one."""
    name = base_scenario(scenario)
    p = BASELINES_DIR / f"{prefix}-{name}.safetensors"
    if not p.is_file():
        names = sorted(q.stem for q in BASELINES_DIR.glob("*.safetensors"))
        raise DataError(
            expect(
                f"{what} shipped weights",
                f"one of {names}",
                f"{prefix}-{name}",
                f"train them (pioneer train {command} --scenario {scenario} --out DIR) and "
                "pass weights=DIR/policy.safetensors",
            )
        )
    return p
