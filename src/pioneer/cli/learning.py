"""``pioneer distill`` (DAgger students) and ``pioneer train crowdnav++`` (the PPO baseline).

Every default is the one of the config the options fill (``DaggerConfig``, ``PPOConfig``,
``WarmStartConfig``) or of the function they are passed to, read with
:func:`~pioneer.cli._common.default`.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Annotated, TypeAlias

from pioneer.baselines.crowdnav.imitation import EXPERTS, WarmStartConfig
from pioneer.baselines.crowdnav.imitation import Expert as WarmStartExpert
from pioneer.baselines.crowdnav.ppo import PPOConfig, train_crowdnav
from pioneer.baselines.sb3 import train_sb3_ppo
from pioneer.cli._common import (
    Flag,
    OutDir,
    Seed,
    Workers,
    command_line,
    default,
    metavar,
    one_of,
    optional,
    require_some,
)
from pioneer.deploy.mixture import ACTION_MODES
from pioneer.deploy.mixture import ActionMode as DaggerActionMode
from pioneer.errors import ConfigError, expect
from pioneer.experiments.blind_sector import run_blind_sector_study
from pioneer.io import to_json
from pioneer.laser import UNSEEN_RULES
from pioneer.laser import UnseenRule as LaserUnseenRule
from pioneer.learn.dagger import LABEL_PREV, DaggerConfig, run_dagger
from pioneer.learn.dagger import LabelPrev as DaggerLabelPrev
from pioneer.learn.models import KINDS, StudentConfig, StudentKind

if TYPE_CHECKING:
    Student: TypeAlias = StudentKind
    ActionMode: TypeAlias = DaggerActionMode
    LabelPrev: TypeAlias = DaggerLabelPrev
    Expert: TypeAlias = WarmStartExpert
    UnseenRule: TypeAlias = LaserUnseenRule
else:
    Student = one_of(KINDS)
    ActionMode = one_of(ACTION_MODES)
    LabelPrev = one_of(LABEL_PREV)
    Expert = one_of(EXPERTS)
    UnseenRule = one_of(UNSEEN_RULES)

__all__ = ["Distill", "StudyBlindSector", "TrainCrowdNav", "TrainSb3"]


@dataclasses.dataclass(frozen=True)
class Distill:
    """DAgger: distil the teacher into a LiDAR-only student (resumes an existing --out)."""

    out: OutDir
    """output folder (resumes if it exists)"""
    scenario: str = default(DaggerConfig, "scenario")
    """hr-rl, hl-rr, … or a pattern such as general-* (one student for many worlds)"""
    student: Student = default(StudentConfig, "kind")
    """the student network"""
    action_mode: ActionMode = default(StudentConfig, "action_mode")
    """MDN's executed action"""
    nll_beta: float = default(StudentConfig, "nll_beta")
    """MDN's β-NLL exponent in [0, 1]"""
    label_prev: LabelPrev = default(DaggerConfig, "label_prev")
    """u_{t-1} in the teacher's smoothed label on student-driven steps"""
    teacher_episodes: int = default(DaggerConfig, "teacher_episodes")
    """round 0 episodes"""
    rounds: int = default(DaggerConfig, "rounds")
    """student-driven rounds"""
    episodes_per_round: int = default(DaggerConfig, "episodes_per_round")
    """episodes of every later round"""
    epochs_initial: int = default(DaggerConfig, "epochs_initial")
    """epochs after round 0"""
    epochs_per_round: int = default(DaggerConfig, "epochs_per_round")
    """epochs after later rounds"""
    seed: Seed = default(DaggerConfig, "seed")
    """seeds the networks and the DAgger episodes"""
    workers: Workers = None
    """processes collecting episodes"""
    reward: Annotated[str | None, optional("FILE", "fit on the shipped demos")] = None
    """teacher reward model .npz"""

    def run(self) -> int:
        """Run (or resume) DAgger; print where the student is."""
        self._check_student_flags()
        cfg = DaggerConfig(
            scenario=self.scenario,
            student=StudentConfig(
                kind=self.student, action_mode=self.action_mode, nll_beta=self.nll_beta
            ),
            label_prev=self.label_prev,
            teacher_episodes=self.teacher_episodes,
            rounds=self.rounds,
            episodes_per_round=self.episodes_per_round,
            epochs_initial=self.epochs_initial,
            epochs_per_round=self.epochs_per_round,
            seed=self.seed,
        )
        res = run_dagger(cfg, self.out, self.workers, reward=self.reward)
        last = res.curves[-1]
        print(
            f"student: {res.student}  ({last['frames_total']} frames, last round SR "
            f"{100 * last['success_rate']:.0f}%); curves: {res.out / 'curves.png'}"
        )
        return 0

    def _check_student_flags(self) -> None:
        """--action-mode and --nll-beta shape the MDN: with --student mlp they are refused,
        not ignored."""
        if self.student == "mdn":
            return
        for flag, name in (("--action-mode", "action_mode"), ("--nll-beta", "nll_beta")):
            if getattr(self, name) != default(StudentConfig, name):
                raise ConfigError(
                    expect(flag, "--student mdn (an MDN setting)", "--student mlp", f"drop {flag}")
                )


@dataclasses.dataclass(frozen=True)
class TrainCrowdNav:
    """CrowdNav++ with PPO, optionally warm-started by imitation (resumes an existing --out)."""

    out: OutDir
    """output folder (checkpoint, policy, curve)"""
    scenario: str = "hr-rl"
    """hr-rl, hl-rr, …"""
    steps: int = default(PPOConfig, "total_steps")
    """total environment steps"""
    envs: int = default(PPOConfig, "n_envs")
    """environments stepped together"""
    seed: Seed = default(PPOConfig, "seed")
    """seeds the weights, the action noise, the minibatches and the episodes"""
    lr: float = default(PPOConfig, "lr")
    """Adam learning rate"""
    entropy_coef: float = default(PPOConfig, "entropy_coef")
    """PPO entropy bonus"""
    bc_episodes: int = default(WarmStartConfig, "bc_episodes")
    """expert demonstrations to imitate first (0: no imitation)"""
    bc_expert: Expert = default(WarmStartConfig, "expert")
    """the demonstrator (sfm, dwa: independent of PioneeR; teacher: PioneeR's own)"""
    bc_epochs: int = default(WarmStartConfig, "bc_epochs")
    """behaviour-cloning epochs"""
    dagger_rounds: int = default(WarmStartConfig, "dagger_rounds")
    """DAgger rounds after cloning"""
    dagger_episodes: int = default(WarmStartConfig, "dagger_episodes")
    """episodes per DAgger round"""
    critic_warmup: int = default(WarmStartConfig, "critic_warmup")
    """[updates] critic-only updates before PPO"""
    checkpoint_every: int = default(PPOConfig, "checkpoint_every")
    """[updates] between checkpoints"""
    threads: int = default(train_crowdnav, "torch_threads")
    """torch threads"""
    resume: Flag = False
    """require a checkpoint in --out (default: resume if there is one)"""

    def run(self) -> int:
        """Train (or resume); print the outputs and the final statistics (JSON lines)."""
        ppo = PPOConfig(
            total_steps=self.steps,
            n_envs=self.envs,
            lr=self.lr,
            entropy_coef=self.entropy_coef,
            seed=self.seed,
            checkpoint_every=self.checkpoint_every,
        )
        warm = WarmStartConfig(
            expert=self.bc_expert,
            bc_episodes=self.bc_episodes,
            bc_epochs=self.bc_epochs,
            dagger_rounds=self.dagger_rounds,
            dagger_episodes=self.dagger_episodes,
            critic_warmup=self.critic_warmup,
        )
        summary = train_crowdnav(
            self.scenario,
            self.out,
            ppo,
            warm=warm,
            resume=True if self.resume else None,
            command=command_line(),
            torch_threads=self.threads,
        )
        print(to_json({"out": self.out, **{k: summary[k] for k in ("updates", "env_steps")}}))
        print(to_json({"final": summary["final"], "wall_time_s": summary["wall_time_s"]}))
        return 0


@dataclasses.dataclass(frozen=True)
class TrainSb3:
    """Stable-Baselines3 PPO (its defaults, MlpPolicy) on the Gymnasium environment with the
    environment's own reward; writes policy.safetensors (no pickle), curve.csv/png, train.json.
    Needs the sb3 extra."""

    out: OutDir
    """output folder (must not hold an SB3 run)"""
    scenario: str = "hr-rl"
    """hr-rl → pioneer/ElevatorHRRL-v1, hl-rr → pioneer/ElevatorHLRR-v1; others by name"""
    steps: int = 1_000_000
    """total environment steps"""
    envs: int = default(train_sb3_ppo, "n_envs")
    """environments (SB3's make_vec_env)"""
    seed: Seed = default(train_sb3_ppo, "seed")
    """seeds SB3 and the environments"""

    def run(self) -> int:
        """Train; print the outputs and the final statistics (JSON lines)."""
        summary = train_sb3_ppo(
            self.scenario,
            self.out,
            steps=self.steps,
            n_envs=self.envs,
            seed=self.seed,
            command=command_line(),
        )
        print(to_json({"out": self.out, "env_steps": summary["env_steps"]}))
        print(to_json({"final": summary["final"], "wall_time_s": summary["wall_time_s"]}))
        return 0


@dataclasses.dataclass(frozen=True)
class StudyBlindSector:
    """The shipped students through the robot runtime with a scanner of narrower field of view,
    under each fill rule of unseen directions (validation seeds; docs/student.md); writes
    OUT/summary.json and OUT/episodes.jsonl, prints one line per scenario and variant."""

    out: OutDir
    """output folder"""
    scenario: Annotated[tuple[str, ...], metavar("NAME")] = default(
        run_blind_sector_study, "scenarios"
    )
    """scenarios with a shipped student"""
    episodes: int = default(run_blind_sector_study, "episodes")
    """validation episodes per scenario and variant"""
    fov: float = default(run_blind_sector_study, "fov_deg")
    """[°] the scanner's field of view, centred on the heading"""
    rules: tuple[UnseenRule, ...] = default(run_blind_sector_study, "rules")
    """fill rules of unseen directions"""

    def run(self) -> int:
        """Run the study."""
        require_some("--scenario", self.scenario)
        run_blind_sector_study(self.out, self.scenario, self.episodes, self.fov, self.rules)
        return 0
