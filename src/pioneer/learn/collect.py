"""DAgger's worker side: one labelled episode, driven by the teacher or the student, with the
teacher labelling every step (:func:`collect_episode`), and one episode a round's student
drives alone, for the choice among the rounds (:func:`drive_task`); the teacher and the
round's student are cached per worker process (:mod:`pioneer.imitation.worker`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from pioneer.imitation.store import save_episode
from pioneer.imitation.worker import LabelledDriver, WorkerCache

if TYPE_CHECKING:  # the teacher is imported in the worker, when it is first needed
    from pioneer.control.teacher import Assumptions, Patience, SoftMargins

__all__ = [
    "CollectTask",
    "DriveTask",
    "clear_cache",
    "collect_episode",
    "collect_task",
    "drive_task",
]

_CACHE = WorkerCache()
# Candidates kept per frame for distilling the teacher's scores (beyond the paper): its best
# TARGET_CANDIDATES by score, as the commands it would send for them and their scores.
TARGET_CANDIDATES = 16
# One episode's work: scenario, reward file, student checkpoint (None: the teacher drives),
# env seed, output path, label_prev, the teacher's soft margins, assumptions and patience.
CollectTask = tuple[str, str, str | None, int, str, str, "SoftMargins", "Assumptions", "Patience"]
# One episode a student drives alone: index, scenario, student checkpoint, env seed.
DriveTask = tuple[int, str, str, int]


def clear_cache() -> None:
    """Forget the cached teachers and student (a new run in this process)."""
    _CACHE.clear()


def _teacher(
    scenario: str, reward: str, margins: SoftMargins, assume: Assumptions, patience: Patience
) -> Any:
    # One teacher per reward file: it plans from the privileged state and world of each step,
    # so the variants of a layout distribution that share a reward share the teacher.
    def make() -> Any:
        from pioneer.control.teacher import make_teacher

        teacher = make_teacher(
            scenario,
            reward=reward,
            human_margin=margins.human,
            wall_margin=margins.wall,
            margin_tiers=margins.tiers,
            assume_radius=assume.human_radius,
            assume_a_robot=assume.a_robot,
            assume_start_now=assume.start_now,
        )
        # the whole Patience (its progress step too), which make_teacher takes only as `after`
        teacher.config = dataclasses.replace(teacher.config, patience=patience)
        return teacher

    return _CACHE.get(("teacher", reward, margins, assume, patience), make)


def _student(checkpoint: str) -> Any:
    from pioneer.learn.policy import make_student_policy

    return _CACHE.latest("student", checkpoint, make_student_policy)


class _Labelled(LabelledDriver):
    """The teacher labelling every step, driving itself or letting the student drive."""

    name = "dagger"

    def __init__(self, teacher: Any, student: Any | None, label_prev: str) -> None:
        super().__init__(teacher, label_prev)
        self.teacher, self.student = teacher, student

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        self.teacher.reset(info, rng)
        if self.student is not None:
            self.student.reset(info, rng)

    def drive(self, obs: NDArray[np.float32], info: Mapping[str, Any], decision: Any) -> Any:
        if self.student is None:
            return np.asarray(decision.command, dtype=np.float64)
        return np.asarray(self.student.act(obs, info), dtype=np.float64)


def collect_episode(
    scenario: str,
    reward: str,
    checkpoint: str | None,
    env_seed: int,
    label_prev: str,
    margins: SoftMargins,
    assume: Assumptions,
    patience: Patience,
) -> dict[str, Any]:
    """Run one episode driven by the teacher (``checkpoint is None``) or the student, with the
    teacher labelling every step. Returns arrays ``obs (T, 29)``, ``action (T, 2)`` (teacher
    labels), ``applied (T, 2)``, ``gap (T,)`` (surface to surface, at decision time), ``aleatoric``,
    ``epistemic`` (student's, NaN when the teacher drives), the episode outcome, and the
    teacher's best candidates of every step, ``target_commands (T, k, 2)`` and
    ``target_scores (T, k)`` (:func:`_score_targets`).
    ``margins``: the teacher's soft margins (:class:`pioneer.control.teacher.SoftMargins`),
    ``assume`` what its predictions assume of people
    (:class:`~pioneer.control.teacher.Assumptions`), ``patience`` how long it holds to its
    preferences without progress (:class:`~pioneer.control.teacher.Patience`)."""
    from pioneer.envs.env import NavEnv
    from pioneer.envs.episode import Episode, Step

    teacher = _teacher(scenario, reward, margins, assume, patience)
    student = _student(checkpoint) if checkpoint is not None else None
    driver = _Labelled(teacher, student, label_prev)
    rows_obs, rows_lab, rows_app, rows_clear = [], [], [], []

    rows_tcmd, rows_tscore = [], []

    def keep(step: Step) -> None:
        rows_obs.append(np.asarray(step.obs, dtype=np.float32))
        rows_lab.append(driver.decision.command)
        rows_app.append(step.command)
        rows_clear.append(step.info["min_gap"])
        commands, scores = _score_targets(teacher, driver.decision)
        rows_tcmd.append(commands)
        rows_tscore.append(scores)

    episode = Episode(NavEnv(scenario), driver, env_seed)
    info = episode.run(keep)
    n = len(rows_obs)
    unc = (
        np.asarray(student.uncertainty, dtype=np.float64).reshape(n, 2)
        if student is not None
        else np.full((n, 2), np.nan)
    )
    return {
        "obs": np.stack(rows_obs),
        "action": np.stack(rows_lab).astype(np.float32),
        "applied": np.stack(rows_app).astype(np.float32),
        "gap": np.asarray(rows_clear, dtype=np.float64),
        "aleatoric": unc[:, 0],
        "epistemic": unc[:, 1],
        "event": np.array(episode.event),
        "time_s": np.array(float(info["time"])),
        "env_seed": np.array(env_seed, dtype=np.int64),
        "scenario": np.array(scenario),
        "target_commands": np.stack(rows_tcmd).astype(np.float32),
        "target_scores": np.stack(rows_tscore).astype(np.float32),
    }


def _score_targets(teacher: Any, decision: Any) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The teacher's best :data:`TARGET_CANDIDATES` candidates of one decision as the commands
    it would send for them ``(k, 2)`` and their scores ``(k,)`` (−∞ for a candidate it could
    not choose); when none was feasible, its fallback command alone (score 0)."""
    k = TARGET_CANDIDATES
    commands, scores = np.zeros((k, 2)), np.full(k, -np.inf)
    if decision.scores.size == 0:
        commands[0], scores[0] = decision.command, 0.0
        return commands, scores
    order = np.argsort(-decision.scores, kind="stable")[:k]
    commands[: order.size] = decision.smoothed(teacher.candidates[order], teacher.config.smoothing)
    scores[: order.size] = decision.scores[order]
    return commands, scores


def collect_task(args: CollectTask) -> str:
    """Collect one episode (:func:`collect_episode`) and write it to its path: the
    :class:`pioneer.imitation.rounds.Collector` function of DAgger's students."""
    scenario, reward, checkpoint, env_seed, path, label_prev, margins, assume, patience = args
    ep = collect_episode(
        scenario, reward, checkpoint, env_seed, label_prev, margins, assume, patience
    )
    return save_episode(path, ep)


def drive_task(args: DriveTask) -> tuple[int, str, float]:
    """Drive one episode with a round's student alone, no teacher (DAgger's choice among its
    rounds' students on validation episodes): ``(index, event, time [s])``."""
    index, scenario, checkpoint, env_seed = args
    from pioneer.envs.env import NavEnv
    from pioneer.envs.episode import Episode

    episode = Episode(NavEnv(scenario), _student(checkpoint), env_seed)
    info = episode.run()
    return index, str(episode.event), float(info["time"])
