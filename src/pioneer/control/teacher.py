"""The sampling-based lookahead teacher (paper §IV-A.2).

Every 0.1 s: roll 8 × 15 candidate commands 3 s ahead (Δt = 0.3 s, L = 10) through the
batched world with privileged human motion, observe every rollout state, and score

    R = α_den R_den + α_goal R_goal + α_obs R_obs                                   (eq. 13)
    R_den = (1/L) Σ_ℓ r_den(o_ℓ, u)                                                  (eq. 14)

with the rule terms and adaptive weights of :mod:`pioneer.reward.rules`. The best command u*
is smoothed: u_t = α_EMA u* + (1 − α_EMA) u_{t−1}, α_EMA = 0.5.

Additions to the paper (docs/teacher.md): a candidate predicted to collide (or to come closer
than ``safety_margin``) is infeasible; among the feasible ones, those that keep the soft
margins (``margins``: a gap to people and to walls) are preferred when any exists, else the
teacher chooses among all feasible ones. If none is feasible the teacher stops at once
(v = ω = 0, no smoothing) — unless standing still is predicted to be run into as well
(``fallback="evade"``, the default): then it drives the candidate whose predicted collision
comes latest. An optional ``extra_score`` hook adds a scenario-specific term (the courteous
demonstrator uses it to yield to people leaving the elevator).

Beyond the paper, for a teacher whose student must drive many worlds (the research log
docs/notes/2026-11-24-general-student-recipes.md, "Which variation costs the student"):
``assume`` replaces, in the teacher's own predictions only, what a student cannot read from
a scan by one value for every world — every person at least ``human_radius`` large, every
person reacting to the robot with ``a_robot``, every person who has not started walking
starting now (``start_now``: they may at any moment). The world the robot drives in is
unchanged; where its people already are so, the decisions are the same.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from typing import Annotated, Any, Literal, NamedTuple

import numpy as np
from annotated_types import Interval
from numpy.typing import NDArray

from pioneer.bounds import Count, NonNegative, Positive
from pioneer.config import Config
from pioneer.control.rollout import (
    HORIZON,
    HUMAN_MODEL,
    ROLLOUT_PRECISION,
    STEP,
    HumanModel,
    Rollout,
    RolloutPrecision,
    rollout,
)
from pioneer.envs.policy import Decision
from pioneer.limits import OMEGA_MAX
from pioneer.reward.density import DensityReward
from pioneer.reward.features import feature_map
from pioneer.reward.recipe import default_features, default_reward
from pioneer.reward.rules import RuleWeights, combine, goal_term, obstacle_term
from pioneer.sim.scenarios import DEFAULT_SCENARIO
from pioneer.sim.world import State, World

__all__ = [
    "PATIENT",
    "Assumptions",
    "LookaheadTeacher",
    "Patience",
    "SoftMargins",
    "TeacherConfig",
    "TeacherDecision",
    "make_teacher",
]

F64 = NDArray[np.float64]
ExtraScore = Callable[[Rollout, State, World], F64]
Fallback = Literal["stop", "evade"]  # what the teacher does when no candidate is feasible


@dataclasses.dataclass(frozen=True)
class SoftMargins(Config):
    """Gaps the teacher prefers to keep: among the feasible (collision-free) candidates, it
    chooses from those predicted to keep both gaps when any does, else from those keeping the
    largest fraction of them that some candidate keeps (:meth:`factors`), else from all
    feasible ones. Unlike ``TeacherConfig.safety_margin`` they never leave the teacher without
    a command."""

    # Beyond the paper (docs/teacher.md, "Soft margins"): chosen on validation episodes so
    # that the DAgger students, who imitate the teacher to within centimetres, have room.
    human: NonNegative = 0.1  # [m] predicted gap (surface to surface) to every person
    wall: NonNegative = 0.05  # [m] predicted gap to every wall
    # where no candidate keeps both margins, try them scaled by (T − k) / T, k = 1 … T − 1,
    # before all feasible candidates: as much room as the situation leaves (1 = no steps).
    # Beyond the paper (docs/teacher.md, "Soft margins"): 4 took the per-episode minimum gap's
    # lowest decile from 4 to 76 mm and the students from 80 to 94 % (validation episodes).
    tiers: Count = 4

    def factors(self) -> tuple[float, ...]:
        """The scales of the margins, tried in order: 1, (T − 1)/T, …, 1/T."""
        return tuple((self.tiers - k) / self.tiers for k in range(self.tiers))


@dataclasses.dataclass(frozen=True)
class Assumptions(Config):
    """What the teacher assumes of the people in its predictions, in place of what they are
    (the defaults: nothing, they are predicted as they are). For the teacher of a student of
    many worlds: the student cannot see how large a person is behind its near surface or
    whether it will give way, and labels that depend on either are labels it cannot learn
    (docs/student.md)."""

    human_radius: NonNegative = 0.0  # [m] every person predicted at least this large (0: as is)
    # [m/s²] every person predicted to react to the robot with this A_r (paper eq. 4's robot
    # term), also those that ignore it (None: as they are)
    a_robot: NonNegative | None = None
    # every person who has not started walking yet predicted to start now: people waiting in
    # the cabin may walk out at any moment, and when is not in a scan (the imitable teacher)
    start_now: bool = False

    def apply(self, world: World, state: State, cache: dict[str, Any]) -> tuple[World, State]:
        """``world`` and ``state`` as the teacher predicts them (the same objects when nothing
        is assumed); ``cache`` keeps the last world built (one per world, not per step)."""
        if self.human_radius > 0.0:
            state = dataclasses.replace(
                state, h_radius=np.maximum(state.h_radius, self.human_radius)
            )
        if self.a_robot is not None:
            if cache.get("source") is not world:
                sim = world.sim
                force = dataclasses.replace(sim.social_force, a_robot=self.a_robot)
                cache["source"] = world
                cache["assumed"] = World(
                    world.walls, world.bounds, dataclasses.replace(sim, social_force=force)
                )
            world = cache["assumed"]
            state = dataclasses.replace(state, h_reacts=np.ones_like(state.h_reacts))
        if self.start_now:
            state = dataclasses.replace(state, h_delay=np.minimum(state.h_delay, state.t[:, None]))
        return world, state

    @property
    def active(self) -> bool:
        """Whether anything is assumed."""
        return self.human_radius > 0.0 or self.a_robot is not None or self.start_now


@dataclasses.dataclass(frozen=True)
class Patience(Config):
    """How long the teacher holds to what it prefers beyond the rule terms while it makes no
    progress: after ``after`` seconds in which its distance to the goal has not shrunk by
    ``progress`` (a crawl towards the door is no progress), it gives up the learned term —
    and, unless ``keep_margins``, the soft margins — and chooses by the rule terms alone, for
    ``hold`` seconds at least, then until it has made progress again. The learned term was
    fitted where people walk 0.5–0.7 m/s; where people are faster or do not queue it makes
    the teacher hang back until boarders have settled in the doorway. Off by default (the
    paper's teacher and ours); :data:`PATIENT` is the setting chosen on validation episodes,
    the policy ``teacher-patient`` (docs/teacher.md, "Patience")."""

    after: NonNegative = 0.0  # [s] without progress before it gives up its preferences (0: never)
    progress: Positive = 0.05  # [m] a shorter distance to the goal by this much is progress
    hold: NonNegative = 0.0  # [s] once impatient, it stays so this long whatever its progress
    keep_margins: bool = False  # impatient, it still prefers the candidates that keep the margins
    # with ``keep_margins``: while it has made no progress for ``after`` seconds (not merely
    # within its hold), it gives up the margin to people — never the wall's: hugging a wall
    # traps a robot that only drives forward — until it makes progress again
    stuck_drops_human_margin: bool = False
    # impatient, α_goal for eq. 18's 2 (1 − r), 0 beyond the start's distance (None: eq. 18's)
    goal_weight: NonNegative | None = None

    @property
    def active(self) -> bool:
        """Whether the teacher is ever impatient (``after`` > 0)."""
        return self.after > 0.0


# Chosen on validation episodes of the examples/ variants and the paper worlds (docs/teacher.md):
# no 0.4 m of progress in 2 s (a crawl below 0.2 m/s) and the learned term is dropped for the rest
# of the episode (100 s: longer than any episode here); the margins stay; α_goal = 2 (eq. 18's
# α_den + α_goal at r = 1/2): the goal takes the dropped term's share.
PATIENT = Patience(after=2.0, progress=0.4, hold=100.0, keep_margins=True, goal_weight=2.0)


@dataclasses.dataclass(frozen=True)
class TeacherConfig(Config):
    """Candidate set, horizon and smoothing of the lookahead teacher."""

    v_values: tuple[float, ...] = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8)  # [m/s]
    n_omega: Count = 15  # ω values evenly spaced in [−ω_max, ω_max]
    omega_max: Positive = OMEGA_MAX  # [rad/s]
    horizon: Positive = HORIZON  # [s] T
    dt: Positive = STEP  # [s] rollout step Δt
    human_model: HumanModel = HUMAN_MODEL  # how rollouts move the people
    # The rollouts' arithmetic: "fast" (float32 rays, vectorised e^x), "float32" (float32
    # rays) or "float64" (the reference); each checked against the reference by
    # pioneer.control.precision_check.
    precision: RolloutPrecision = ROLLOUT_PRECISION
    smoothing: Annotated[float, Interval(gt=0.0, le=1.0)] = 0.5  # α_EMA
    safety_margin: NonNegative = 0.0  # [m] predicted human gap below this is infeasible
    margins: SoftMargins = SoftMargins()  # gaps preferred among the feasible candidates
    assume: Assumptions = Assumptions()  # what the predictions assume of people (beyond the paper)
    # No feasible candidate: "stop" at once, or "evade" — stop unless standing still is
    # predicted to collide too, then drive the candidate that collides latest.
    fallback: Fallback = "evade"
    weights: RuleWeights = RuleWeights()
    # Beyond the paper, off by default: the margins and the learned term given up after a
    # while without progress (Patience; docs/teacher.md)
    patience: Patience = Patience()

    def candidates(self) -> F64:
        """The candidate commands: every v × ``n_omega`` ω evenly in [−ω_max, ω_max] → (C, 2),
        v-major (the paper's 8 × 15 = 120)."""
        w = np.linspace(-self.omega_max, self.omega_max, self.n_omega)
        vv, ww = np.meshgrid(np.asarray(self.v_values, dtype=np.float64), w, indexing="ij")
        return np.stack([vv.ravel(), ww.ravel()], axis=1)


@dataclasses.dataclass(frozen=True)
class TeacherDecision(Decision):
    """One teacher decision: the command (the smoothed command actually sent) and the per-term
    scores behind it."""

    best: F64  # (2,) u*, the best feasible candidate (zeros if none)
    index: int  # index of u* among the candidates (−1 if none feasible)
    n_feasible: int
    terms: dict[str, float]  # weighted density / goal / obstacle / extra / total of u*
    raw_terms: dict[str, float]  # unweighted R_den, R_goal, R_obs of u*
    # (C,) every candidate's score, −∞ where it could not be chosen (infeasible, or outside the
    # kept soft margins); empty when none was feasible (the fallback's command)
    scores: F64 = dataclasses.field(default_factory=lambda: np.zeros(0))
    previous: F64 = dataclasses.field(default_factory=lambda: np.zeros(2))  # u_{t−1} smoothed with

    def smoothed(self, candidates: F64, smoothing: float) -> F64:
        """The command the teacher would send for each of ``candidates (C, 2)``:
        α_EMA u + (1 − α_EMA) u_{t−1}, as it sends u* (``command``)."""
        out: F64 = smoothing * candidates + (1.0 - smoothing) * self.previous
        return out


class LookaheadTeacher:
    """The PioneeR teacher as a :class:`~pioneer.envs.policy.Policy` (privileged)."""

    def __init__(
        self,
        density: DensityReward | None = None,
        features: str | None = None,
        config: TeacherConfig | None = None,
        extra_score: ExtraScore | None = None,
        name: str = "teacher",
    ) -> None:
        self.density = density
        # The model knows the feature map it was fitted on; without one, the elevator's.
        info = getattr(density, "info_", {}) if density is not None else {}
        self.features = features or str(info.get("features", "obs_action"))
        self._feature_map = feature_map(self.features)
        self.config = config or TeacherConfig()
        self.extra_score = extra_score
        self.name = name
        self.candidates = self.config.candidates()
        self._prev = np.zeros(2)
        self.last: TeacherDecision | None = None
        self._assumed: dict[str, Any] = {}  # the world with the assumed reaction (Assumptions)
        self._progress = (math.inf, 0.0)  # (best distance to the goal [m], when it was made [s])
        self._impatient_until = -math.inf  # [s] (Patience.hold)
        self._stuck = False  # no progress for Patience.after seconds, as of the last decision

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Forget the previous command and the progress made."""
        self._prev = np.zeros(2)
        self.last = None
        self._progress = (math.inf, 0.0)
        self._impatient_until = -math.inf
        self._stuck = False

    def impatient(self, state: State) -> bool:
        """Note the progress to ``state`` (B = 1) and say whether the teacher has made none for
        ``patience.after`` seconds (:class:`Patience`). A state earlier than the last progress
        starts a new episode."""
        p = self.config.patience
        d = float(np.linalg.norm(state.robot[0, :2] - state.goal[0]))
        t = float(state.t[0])
        best, since = self._progress
        if t < since:  # a new episode
            self._impatient_until = -math.inf
        if d < best - p.progress or t < since:
            self._progress = best, since = d, t
        self._stuck = p.active and t - since >= p.after - 1e-9
        if not p.active:
            return False
        if self._stuck:
            self._impatient_until = max(self._impatient_until, t + p.hold)
            return True
        return t < self._impatient_until - 1e-9

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> F64:
        """Decide from the privileged ``info["state"]`` and ``info["world"]``."""
        self.last = self.decide(info["world"], info["state"])
        return self.last.command

    def decide(self, world: World, state: State, prev: F64 | None = None) -> TeacherDecision:
        """Score all candidates from ``state`` (B = 1) and return the smoothed command.

        ``prev`` replaces the teacher's own previous command u_{t−1} in the smoothing; a
        labeller (DAgger) or a shield passes the command actually applied (``state.command``),
        so the label is what the teacher would send had it been driving.
        """
        cfg = self.config
        if prev is not None:
            self._prev = np.asarray(prev, dtype=np.float64).reshape(2).copy()
        impatient = self.impatient(state)
        world, state = cfg.assume.apply(world, state, self._assumed)
        sc = self._score(world, state, impatient)
        if sc.n_feasible == 0:
            self._prev = self._fallback(world, state, sc)
            return TeacherDecision(self._prev.copy(), self._prev.copy(), -1, 0, {}, {})
        i = int(np.argmax(sc.scored))
        best = self.candidates[i]
        previous = self._prev.copy()
        cmd = cfg.smoothing * best + (1.0 - cfg.smoothing) * previous
        self._prev = cmd
        return TeacherDecision(
            command=cmd.copy(),
            best=best.copy(),
            index=i,
            n_feasible=sc.n_feasible,
            terms={
                **{k: float(v[i]) for k, v in sc.terms.items()},
                "extra": float(sc.extra[i]),
                "total": float(sc.scored[i]),
            },
            raw_terms={
                "density": float(sc.r_den[i]),
                "goal": float(sc.r_goal[i]),
                "obstacle": float(sc.r_obs[i]),
            },
            scores=sc.scored,
            previous=previous,
        )

    def _fallback(self, world: World, state: State, sc: _Scores) -> F64:
        """The command when no candidate is feasible (sent unsmoothed): stop; with
        ``fallback="evade"``, if standing still is predicted to collide too (a person walks into
        the robot), the candidate whose predicted collision comes latest (ties: the best score
        of the rule terms), or still the stop when none collides later than standing."""
        cfg = self.config
        stop = np.zeros(2)
        if cfg.fallback == "stop":
            return stop
        still = rollout(
            world, state, stop[None], cfg.horizon, cfg.dt, cfg.human_model, cfg.precision
        )
        if not still.collided[0]:
            return stop
        latest = sc.collision_step.max()
        if latest <= still.collision_step[0]:
            return stop
        among = np.where(sc.collision_step == latest, sc.total, -np.inf)
        return self.candidates[int(np.argmax(among))].copy()

    def scores(self, world: World, state: State) -> F64:
        """Every candidate's total score from ``state`` (B = 1), −∞ where infeasible (or, when
        some candidate keeps the soft margins, where it does not); the decision of a patient
        teacher (:class:`Patience`) is its argmax (ties: the lowest candidate index). A state
        alone holds no progress history, so the scores are always the patient ones: an
        impatient :meth:`decide` scores by the rule terms alone."""
        world, state = self.config.assume.apply(world, state, self._assumed)
        return self._score(world, state).scored

    def _score(self, world: World, state: State, impatient: bool = False) -> _Scores:
        """Every candidate's scores; ``impatient``: by the rule terms alone, among all feasible
        candidates (:class:`Patience`)."""
        cfg = self.config
        w, g = cfg.weights, cfg.patience.goal_weight
        g = w.goal_weight if g is None else g
        w = dataclasses.replace(w, use_density=False, goal_weight=g) if impatient else w
        ro = rollout(
            world, state, self.candidates, cfg.horizon, cfg.dt, cfg.human_model, cfg.precision
        )
        c, n_l = ro.robot.shape[:2]
        d_total = float(np.linalg.norm(state.goal[0] - state.start[0]))
        d_goal = ro.final_goal_distance
        r_goal = goal_term(d_goal, d_total)
        feasible = ~ro.collided & (ro.min_gap >= cfg.safety_margin)
        n_feasible = int(feasible.sum())
        p = cfg.patience
        drop_margins = impatient and not p.keep_margins
        people = not (impatient and p.stuck_drops_human_margin and self._stuck)
        chosen = feasible if drop_margins else self._preferred(feasible, ro, people)
        # Only candidates that can be chosen are observed and scored by the density: about half
        # collide in the paper world, and the rays and the density are most of a decision's
        # arithmetic. (The others keep 0 for both terms; they score −∞.)
        r_obs = np.zeros(c)
        r_den = np.zeros(c)
        n_chosen = int(chosen.sum())
        if n_chosen:
            obs = ro.observations(chosen)
            r_obs[chosen] = obstacle_term(obs)
            if self.density is not None and w.use_density:
                feats = self._feature_map.from_rollout(ro.robot[chosen], obs, ro.commands[chosen])
                r_den[chosen] = self.density(feats).reshape(n_chosen, n_l).mean(axis=1)
        total, terms = combine(r_den, r_goal, r_obs, d_goal, d_total, w)
        extra = self.extra_score(ro, state, world) if self.extra_score is not None else np.zeros(c)
        scored = np.where(chosen, total + extra, -np.inf)
        return _Scores(
            scored, n_feasible, terms, extra, r_den, r_goal, r_obs, total + extra,
            ro.collision_step,
        )  # fmt: skip

    def _preferred(
        self, feasible: NDArray[np.bool_], ro: Rollout, people: bool = True
    ) -> NDArray[np.bool_]:
        """The candidates the teacher chooses among: those that keep the soft margins, else
        those that keep the largest fraction of them some candidate keeps
        (:meth:`SoftMargins.factors`), else all feasible ones; without ``people``, the wall's
        margin alone."""
        m = self.config.margins
        human = m.human if people else 0.0
        for f in m.factors():
            keep = feasible & (ro.min_gap >= f * human) & (ro.min_wall_gap >= f * m.wall)
            if keep.any():
                return keep
        return feasible


class _Scores(NamedTuple):
    """Per-candidate quantities of one scoring pass (all ``(C,)``)."""

    scored: F64  # total + extra, −∞ where infeasible or outside the kept soft margins
    n_feasible: int
    terms: dict[str, F64]  # weighted terms from ``combine``
    extra: F64
    r_den: F64
    r_goal: F64
    r_obs: F64
    total: F64  # total + extra, also where infeasible
    collision_step: NDArray[np.int64]  # predicted first collision step (L + 1: none)


def make_teacher(
    scenario: str = DEFAULT_SCENARIO,
    reward: str | None = None,
    density: bool = True,
    goal: bool = True,
    obstacle: bool = True,
    human_model: HumanModel = TeacherConfig.human_model,
    fallback: Fallback = TeacherConfig.fallback,
    human_margin: float = SoftMargins.human,
    wall_margin: float = SoftMargins.wall,
    margin_tiers: int = SoftMargins.tiers,
    precision: RolloutPrecision = TeacherConfig.precision,
    assume_radius: float = Assumptions.human_radius,
    assume_a_robot: float | None = Assumptions.a_robot,
    assume_start_now: bool = Assumptions.start_now,
    patience: float = Patience.after,
    patience_progress: float = Patience.progress,
    patience_hold: float = Patience.hold,
    patience_keep_margins: bool = Patience.keep_margins,
    patience_stuck_drops_human_margin: bool = Patience.stuck_drops_human_margin,
    patience_goal_weight: float | None = Patience.goal_weight,
    patient: bool = False,
    name: str = "teacher",
) -> LookaheadTeacher:
    """The PioneeR teacher for ``scenario``: reward from ``reward`` (a model file) or fitted on
    the shipped demos; each term can be switched off (paper Table II); ``human_margin`` and
    ``wall_margin`` are its soft margins [m] and ``margin_tiers`` their steps
    (:class:`SoftMargins`); ``precision`` the rollouts' arithmetic (fast, the default; float32
    rays; or float64, the reference: :mod:`pioneer.control.precision_check`); ``assume_radius``
    [m], ``assume_a_robot`` [m/s²] and ``assume_start_now`` what its predictions assume of
    every person (:class:`Assumptions`; beyond the paper); ``patience`` [s] how long it holds
    to its margins and learned term without progress (:class:`Patience`; 0: always, as the
    paper's teacher), ``patience_progress`` [m], ``patience_hold`` [s],
    ``patience_keep_margins``, ``patience_stuck_drops_human_margin`` and
    ``patience_goal_weight`` the rest of :class:`Patience`; ``patient``: :data:`PATIENT`
    instead of those six (the policy ``teacher-patient``)."""
    model = None
    if density:
        # ``reward`` may contain "{scenario}" so one policy spec serves every scenario.
        model = (
            DensityReward.load(reward.format(scenario=scenario))
            if reward
            else default_reward(scenario)
        )
    features = str(model.info_.get("features", default_features(scenario))) if model else "xy"
    cfg = TeacherConfig(
        human_model=human_model,
        precision=precision,
        fallback=fallback,
        margins=SoftMargins(human=human_margin, wall=wall_margin, tiers=margin_tiers),
        assume=Assumptions(
            human_radius=assume_radius, a_robot=assume_a_robot, start_now=assume_start_now
        ),
        weights=RuleWeights(use_density=density, use_goal=goal, use_obstacle=obstacle),
        patience=PATIENT
        if patient
        else Patience(
            after=patience,
            progress=patience_progress,
            hold=patience_hold,
            keep_margins=patience_keep_margins,
            stuck_drops_human_margin=patience_stuck_drops_human_margin,
            goal_weight=patience_goal_weight,
        ),
    )
    return LookaheadTeacher(model, features=features, config=cfg, name=name)
