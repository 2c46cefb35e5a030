"""The settings of a DAgger run (:class:`DaggerConfig`, paper §V-B.2 and beyond), and how the
settings of runs stored in an older layout are read in today's (a resume compares them)."""

from __future__ import annotations

import dataclasses
import typing
from typing import Any, Literal, Self

from pioneer.bounds import Count, NonNegative, NonNegativeInt, Positive
from pioneer.config import Config
from pioneer.control.teacher import Assumptions, Patience, SoftMargins
from pioneer.learn.models import (
    StudentConfig,
)
from pioneer.learn.training import TRAIN_BATCH, TRAIN_LR
from pioneer.sim.scenarios import DEFAULT_SCENARIO

__all__ = ["LABEL_PREV", "DaggerConfig", "LabelPrev", "Target"]

LabelPrev = Literal["applied", "teacher"]
# What the student learns from each frame: the teacher's command ("label", the paper) or its
# scores of its best candidates ("scores", beyond the paper: docs/student.md)
Target = Literal["label", "scores"]
LABEL_PREV: tuple[str, ...] = typing.get_args(LabelPrev)


@dataclasses.dataclass(frozen=True)
class DaggerConfig(Config):
    """A DAgger run (defaults = paper §V-B.2: 50 teacher episodes + 10 rounds × 50)."""

    # hr-rl, hl-rr, … or a pattern such as general-* (one student for many worlds)
    scenario: str = DEFAULT_SCENARIO
    student: StudentConfig = StudentConfig()  # the student network
    # u_{t−1} in the teacher's label ½u* + ½u_{t−1} on student-driven steps: "applied" (the
    # command the robot actually ran) or "teacher" (the teacher's own previous label along the
    # trajectory, as if its smoothing had been running; keeps the student's jitter out of the
    # labels). Equal on teacher-driven steps.
    label_prev: LabelPrev = "applied"
    margins: SoftMargins = SoftMargins()  # the teacher's soft margins while it labels
    # Beyond the paper: what the labelling teacher's predictions assume of every person in
    # place of what the student cannot see (docs/notes/2026-11-24-general-student-recipes.md, "Which
    # variation costs the student")
    assume: Assumptions = Assumptions()
    # Beyond the paper: how long the labelling teacher holds to its margins and learned term
    # without progress (docs/teacher.md, "Patience")
    patience: Patience = Patience()
    teacher_episodes: Count = 50  # round 0, driven by the teacher
    rounds: NonNegativeInt = 10  # student-driven rounds after round 0
    episodes_per_round: Count = 50  # episodes of every later round
    epochs_initial: Count = 40  # training epochs after round 0 (fresh network)
    epochs_per_round: NonNegativeInt = 10  # epochs over the aggregate after each later round
    batch: Count = TRAIN_BATCH  # frames per Adam step
    lr: Positive = TRAIN_LR  # Adam learning rate
    seed: NonNegativeInt = 0  # seeds the networks and the DAgger episodes
    # Beyond the paper: frames whose gap to the nearest person (surface to surface, at
    # decision time) is below near_gap count near_repeat times in training — the rare frames
    # where the teacher's correction decides between a pass and a collision.
    near_gap: NonNegative = 0.0  # [m] frames nearer a person than this count more (0: none)
    near_repeat: Count = 1  # how many times such a frame counts in training
    # Beyond the paper: validation episodes every round's student drives, the best becoming
    # the run's student (0: the last round's, as in the paper)
    select_episodes: NonNegativeInt = 0
    # Beyond the paper: every frame also trains as its mirror image (the world mirrored x → −x:
    # the observations by pioneer.laser.mirror_observation, ω of the label and of u_{t−1}
    # negated), for a student that drives on both sides of the door
    mirror: bool = False
    # Beyond the paper: "scores" trains on the teacher's judgement, not only its choice — the
    # commands it would send for its best candidates, weighted softmax(score / τ) — so the
    # student learns which commands are nearly as good and which it must not give
    target: Target = "label"
    score_temperature: Positive = 0.05  # τ of target="scores" (score units; → 0: the label)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Self:
        """Build from a plain dict, also in the layout of runs and checkpoints written before
        the student's settings were nested (``student`` its kind, ``action_mode`` and
        ``nll_beta`` beside it)."""
        return super().from_dict(
            _no_patience_before_patience(_one_tier_before_tiers(_nest_student(data)))
        )

    def episodes_in(self, rnd: int) -> int:
        """Episodes collected in round ``rnd``."""
        return self.teacher_episodes if rnd == 0 else self.episodes_per_round

    @property
    def total_episodes(self) -> int:
        """Episodes of the whole run."""
        return self.teacher_episodes + self.rounds * self.episodes_per_round


def _nest_student(data: Any) -> Any:
    """``data`` (a DaggerConfig as a dict) in the current layout: the flat ``student`` (its
    kind), ``action_mode`` and ``nll_beta`` of older runs moved into ``student``."""
    if not isinstance(data, dict) or isinstance(data.get("student"), dict):
        return data
    flat = {"student": "kind", "action_mode": "action_mode", "nll_beta": "nll_beta"}
    student = {new: data[old] for old, new in flat.items() if old in data}
    rest = {k: v for k, v in data.items() if k not in flat}
    return {**rest, "student": student} if student else rest


def _one_tier_before_tiers(data: Any) -> Any:
    """``data`` with ``margins.tiers = 1`` where its margins have no ``tiers``: runs stored
    before the tiers were labelled by a teacher with one tier, and resume as such (or are
    refused for another setting), not with today's default."""
    margins = data.get("margins") if isinstance(data, dict) else None
    if not isinstance(margins, dict) or "tiers" in margins:
        return data
    return {**data, "margins": {**margins, "tiers": 1}}


def _no_patience_before_patience(data: Any) -> Any:
    """``data`` with ``patience.after = 0`` where it has no ``patience``: runs stored before
    the teacher had patience were labelled by a teacher without it, and resume as such."""
    if not isinstance(data, dict) or "patience" in data or "scenario" not in data:
        return data
    return {**data, "patience": {"after": 0.0}}
