"""Does the teacher choose the same with faster arithmetic? The equivalence check of its precision.

The teacher's rollouts have three precisions (``TeacherConfig.precision``,
:data:`pioneer.control.rollout.RolloutPrecision`; docs/performance.md): ``"float64"``, the
reference; ``"float32"``, float32 ray casting of the rollout states ("Float32 rays for the
teacher"); ``"fast"``, the default, float32 rays and the social forces' exponentials by a
vectorised e^x within 2 ulp of libm's ("The rollout in SIMD lanes"). The ranges, and with
``"fast"`` the predicted people too, then differ from the reference in their last bits, the
scores in about the seventh digit — except where a beam grazes an obstacle so closely that
it hits in one precision and misses in the other — and the chosen candidate only where two
candidates' scores nearly tie. :func:`compare_precision` measures that on recorded decision
inputs (:func:`record_decision_inputs`): the share of states where both paths choose the
same candidate, and where they do not, how much worse the other path's choice is under the
reference scores. A precision is acceptable when the share is at least ``MIN_SAME_SHARE``
and every such loss is below the tolerance.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Sequence

import numpy as np
from numpy.typing import NDArray

from pioneer.control.rollout import RolloutPrecision
from pioneer.control.teacher import LookaheadTeacher, make_teacher
from pioneer.envs.env import NavEnv
from pioneer.envs.episode import Episode, Step
from pioneer.sim.world import State, World

__all__ = [
    "MIN_SAME_SHARE",
    "SCORE_TOLERANCE",
    "DecisionInput",
    "PrecisionReport",
    "chosen_index",
    "compare_precision",
    "record_decision_inputs",
    "with_precision",
]

F64 = NDArray[np.float64]

# What "the same teacher" means (what a switch of precision must keep): the same candidate
# in at least 99 % of states, and where not, a choice whose reference score is less than
# SCORE_TOLERANCE below the reference choice's. The scores are sums of terms of order 1
# (pioneer.reward.rules). Float32 rounding alone moves a score by ~1e-7; what moves it more
# is a beam that grazes a person (or a wall's end) so closely that it hits in one precision
# and misses in the other (the discontinuity the reference has too, only narrower), by a few
# hundredths at most in the measured sets (docs/performance.md). A differing choice loses at
# most the two candidates' changes: the tolerance admits one such flip; a systematic error
# would show in the share.
MIN_SAME_SHARE = 0.99
SCORE_TOLERANCE = 0.05


@dataclasses.dataclass(frozen=True, eq=False)
class DecisionInput:
    """What one teacher decision is made from: ``decide(world, state, prev)``."""

    world: World
    state: State  # B = 1
    prev: F64  # (2,) the command applied in the previous control period [m/s, rad/s]


def record_decision_inputs(
    scenario: str, seeds: Iterable[int], every: int = 1
) -> list[DecisionInput]:
    """The inputs of every ``every``-th decision of the reference teacher
    (``make_teacher(scenario, precision="float64")``) in the seeded episodes of ``scenario``,
    in order: states as the teacher meets them (people in the door, candidates colliding),
    not one scene."""
    teacher = make_teacher(scenario, precision="float64")
    out: list[DecisionInput] = []
    for seed in seeds:
        env = NavEnv(scenario)
        prev = np.zeros(2)

        def keep(step: Step) -> None:
            nonlocal prev
            if step.index % every == 0:
                out.append(DecisionInput(step.info["world"], step.info["state"], prev))
            prev = np.asarray(step.command, dtype=np.float64).copy()

        Episode(env, teacher, seed).run(keep)
    return out


@dataclasses.dataclass(frozen=True)
class PrecisionReport:
    """Both paths' choices over a set of decision inputs (:func:`compare_precision`)."""

    precision: RolloutPrecision  # the path compared with the float64 reference
    n_states: int
    n_same: int  # states where both choose the same candidate (or both none)
    differing: tuple[int, ...]  # indices of the other states in the input set
    score_loss: tuple[float, ...]  # per differing state: reference score of the reference
    # choice minus that of the other path's choice (>= 0; inf if only one chose none)
    max_score_change: float  # the largest |score − reference score| of any choosable candidate
    tolerance: float

    @property
    def same_share(self) -> float:
        """Share of states with the same choice (1.0 for an empty set)."""
        return self.n_same / self.n_states if self.n_states else 1.0

    @property
    def max_score_loss(self) -> float:
        """The largest score loss over the differing states (0.0 when none differ)."""
        return max(self.score_loss, default=0.0)

    @property
    def equivalent(self) -> bool:
        """At least ``MIN_SAME_SHARE`` the same, and every other loss below ``tolerance``."""
        return self.same_share >= MIN_SAME_SHARE and self.max_score_loss < self.tolerance

    def summary(self) -> str:
        """One line: the share, the count and the largest loss against the tolerance."""
        return (
            f"{self.precision} vs float64: the same candidate in {self.n_same}/{self.n_states} "
            f"states ({100.0 * self.same_share:.2f} %), largest score loss where not "
            f"{self.max_score_loss:.3g} (tolerance {self.tolerance:g}), largest score change "
            f"{self.max_score_change:.3g}"
        )


def with_precision(teacher: LookaheadTeacher, precision: RolloutPrecision) -> LookaheadTeacher:
    """A new teacher with ``teacher``'s reward, features, settings, extra score and name, whose
    rollouts are observed with ``precision`` rays (``TeacherConfig.precision``)."""
    cfg = dataclasses.replace(teacher.config, precision=precision)
    return LookaheadTeacher(
        teacher.density, teacher.features, cfg, teacher.extra_score, teacher.name
    )


def chosen_index(scores: F64) -> int:
    """The candidate :meth:`LookaheadTeacher.decide` chooses from its ``scores`` (C,): the
    argmax (ties: the lowest index), or −1 when every score is −∞ (no candidate feasible: the
    fallback, which observes nothing and so is the same at any precision)."""
    return int(np.argmax(scores)) if np.isfinite(scores).any() else -1


def compare_precision(
    teacher: LookaheadTeacher,
    inputs: Sequence[DecisionInput],
    precision: RolloutPrecision = "float32",
    tolerance: float = SCORE_TOLERANCE,
) -> PrecisionReport:
    """Score every input with ``teacher``'s reward and settings twice — with float64 rays (the
    reference) and with ``precision`` — and compare the candidates each would choose
    (:func:`chosen_index`). Where they differ, the loss is the reference score of the
    reference choice minus the reference score of the other choice. Deterministic."""
    ref = with_precision(teacher, "float64")
    alt = with_precision(teacher, precision)
    differing: list[int] = []
    loss: list[float] = []
    change = 0.0
    for k, d in enumerate(inputs):
        s_ref = ref.scores(d.world, d.state)
        s_alt = alt.scores(d.world, d.state)
        finite = np.isfinite(s_ref)
        if np.any(finite):
            change = max(change, float(np.abs(s_alt[finite] - s_ref[finite]).max()))
        i_ref, i_alt = chosen_index(s_ref), chosen_index(s_alt)
        if i_ref != i_alt:
            differing.append(k)
            lost = s_ref[i_ref] - s_ref[i_alt] if min(i_ref, i_alt) >= 0 else np.inf
            loss.append(float(lost))
    return PrecisionReport(
        precision, len(inputs), len(inputs) - len(differing), tuple(differing), tuple(loss),
        change, tolerance,
    )  # fmt: skip
