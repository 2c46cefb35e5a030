"""``pioneer distill`` (DAgger students) and ``pioneer train crowdnav++`` (the PPO baseline).

Their options are the configs they fill (``DaggerConfig`` with its ``StudentConfig``,
``PPOConfig``, ``WarmStartConfig``), nested as groups of flags: the flags, defaults, bounds and
help come from the configs; other defaults are those of the function the options are passed to,
read with :func:`~pioneer.config.default`.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Annotated, TypeAlias

import tyro
from annotated_types import Ge

from pioneer.baselines.crowdnav.imitation import WarmStartConfig
from pioneer.baselines.crowdnav.ppo import PPOConfig, train_crowdnav
from pioneer.baselines.sb3 import train_sb3_ppo
from pioneer.cli._files import Input, OutDir
from pioneer.cli._options import Flag, Seed, Workers, metavar, one_of, optional, require_some
from pioneer.cli._parse import config_flags, flag_name
from pioneer.cli._text import command_line
from pioneer.config import default
from pioneer.control.teacher import Assumptions, Patience, SoftMargins
from pioneer.errors import ConfigError, expect
from pioneer.experiments.blind_sector import run_blind_sector_study
from pioneer.io import to_json
from pioneer.laser import UNSEEN_RULES
from pioneer.laser import UnseenRule as LaserUnseenRule
from pioneer.learn.dagger import DaggerConfig, run_dagger
from pioneer.learn.finetune import FinetuneConfig, finetune_student
from pioneer.learn.models import MDN_ONLY, StudentConfig
from pioneer.reward.crowdnav import REWARDS, RewardName
from pioneer.sim.scenarios import DEFAULT_SCENARIO

if TYPE_CHECKING:
    UnseenRule: TypeAlias = LaserUnseenRule
else:
    UnseenRule = one_of(UNSEEN_RULES)

__all__ = ["Distill", "Finetune", "StudyBlindSector", "TrainCrowdNav", "TrainSb3"]

config_flags(DaggerConfig)
config_flags(SoftMargins, human="human_margin", wall="wall_margin", tiers="margin_tiers")
config_flags(
    Assumptions,
    human_radius="assume_radius",
    a_robot="assume_a_robot",
    start_now="assume_start_now",
)
config_flags(
    Patience,
    after="patience",
    progress="patience_progress",
    hold="patience_hold",
    keep_margins="patience_keep_margins",
    stuck_drops_human_margin="patience_stuck_drops_human_margin",
    goal_weight="patience_goal_weight",
)
config_flags(StudentConfig, kind="student", obs_dim=None)  # obs_dim: the observation's width
config_flags(PPOConfig, total_steps="steps", n_envs="envs")
config_flags(FinetuneConfig, total_steps="steps", reward=None)
config_flags(WarmStartConfig, expert="bc_expert")


@dataclasses.dataclass(frozen=True)
class Distill:
    """DAgger: distil the teacher into a LiDAR-only student (resumes an existing --out)."""

    out: OutDir
    """output folder (resumes if it exists)"""
    dagger: tyro.conf.OmitArgPrefixes[DaggerConfig] = DaggerConfig()
    """the DAgger run (defaults: the paper's, §V-B.2)"""
    workers: Workers = None
    """processes collecting episodes"""
    reward: Annotated[str | None, optional("FILE", "fit on the shipped demos"), Input("file")] = (
        None
    )
    """teacher reward model .npz"""

    def run(self) -> int:
        """Run (or resume) DAgger; print where the student is."""
        self._check_student_flags()
        res = run_dagger(self.dagger, self.out, self.workers, reward=self.reward)
        last = res.curves[-1]
        chosen = ""
        if res.selection:
            row = res.selection[res.chosen]
            chosen = (
                f"; round {res.chosen} chosen: SR {100 * row['success_rate']:.0f}% on "
                f"{row['episodes']} validation episodes ({res.out / 'selection.csv'})"
            )
        print(
            f"student: {res.student}  ({last['frames_total']} frames, last round SR "
            f"{100 * last['success_rate']:.0f}%){chosen}; curves: {res.out / 'curves.png'}"
        )
        return 0

    def _check_student_flags(self) -> None:
        """The MDN's own settings (--action-mode, --nll-beta, …) with --student mlp are
        refused, not ignored."""
        student = self.dagger.student
        if student.kind == "mdn":
            return
        kind = flag_name(StudentConfig, "kind")
        for name in MDN_ONLY:
            if getattr(student, name) != default(StudentConfig, name):
                flag = flag_name(StudentConfig, name)
                raise ConfigError(
                    expect(
                        flag,
                        f"{kind} mdn (an MDN setting)",
                        f"{kind} {student.kind}",
                        f"drop {flag}",
                    )
                )


@dataclasses.dataclass(frozen=True)
class Finetune:
    """Fine-tune a DAgger student with PPO over scenarios or a layout distribution (resumes an
    existing --out; docs/general-student.md)."""

    out: OutDir
    """output folder (student, checkpoint, curve)"""
    student: Annotated[str, metavar("FILE"), Input("file")]
    """the student to start from (.safetensors): a DAgger student, or a fine-tuned one to
    fine-tune again"""
    scenario: Annotated[tuple[str, ...], metavar("NAME")] = ("general-*", "hr-rl", "hl-rr")
    """scenarios or patterns (general-*: the layouts of `pioneer --scenarios FILE`), each drawn
    equally often (the default: student-general's)"""
    finetune: tyro.conf.OmitArgPrefixes[FinetuneConfig] = FinetuneConfig()
    """fine-tuning settings"""
    mastery_teacher: Annotated[tuple[str, ...], metavar("DIR"), Input("path")] = ()
    """with --replay-mode mastery: `pioneer eval --seed-set validation` folders of the teacher
    on every layout of the patterns; the curriculum then practises only layouts the teacher
    masters, by how far the student falls below it (regret)"""
    rehearse: Annotated[tuple[str, ...], metavar("NAME")] = ()
    """scenarios or patterns not practised but kept: a pull (--rehearse-coef) towards the
    starting student on its own states there (a later stage keeps what an earlier one learned)"""
    threads: Annotated[int, Ge(1)] = default(finetune_student, "torch_threads")
    """torch's intra-op threads (2 on an otherwise idle 2-core machine: ≈ 1.3× faster)"""
    resume: Flag = False
    """require a checkpoint in --out (default: resume if there is one)"""

    def run(self) -> int:
        """Fine-tune (or resume); print the outputs and the final statistics (JSON lines)."""
        from pioneer.eval.report import success_rates

        require_some("--scenario", self.scenario)
        folders = self.mastery_teacher
        table = {k: v for f in folders for k, v in success_rates(f).items()} if folders else None
        summary = finetune_student(
            self.student,
            self.scenario,
            self.out,
            self.finetune,
            resume=True if self.resume else None,
            command=command_line(),
            torch_threads=self.threads,
            mastery_teacher=table,
            rehearse=self.rehearse,
        )
        student = f"{self.out}/student.safetensors"
        print(to_json({"student": student, "updates": summary["updates"]}))
        print(to_json({"final": summary["final"], "wall_time_s": summary["wall_time_s"]}))
        return 0


@dataclasses.dataclass(frozen=True)
class TrainCrowdNav:
    """CrowdNav++ with PPO, optionally warm-started by imitation (resumes an existing --out)."""

    out: OutDir
    """output folder (checkpoint, policy, curve)"""
    scenario: str = DEFAULT_SCENARIO
    """hr-rl, hl-rr, …"""
    ppo: tyro.conf.OmitArgPrefixes[PPOConfig] = PPOConfig()
    """PPO settings"""
    warm: tyro.conf.OmitArgPrefixes[WarmStartConfig] = WarmStartConfig()
    """imitation warm start and critic warm-up (all off by default: pure PPO)"""
    reward: RewardName = "crowdnav"
    """crowdnav: the CrowdNav++ reward; no-intrusion: the same without its intrusion term
    (docs/baselines.md); a resume must use the run's"""
    threads: Annotated[int, Ge(1)] = default(train_crowdnav, "torch_threads")
    """torch's intra-op threads (2 on an otherwise idle 2-core machine: ≈ 1.2× faster)"""
    resume: Flag = False
    """require a checkpoint in --out (default: resume if there is one)"""

    def run(self) -> int:
        """Train (or resume); print the outputs and the final statistics (JSON lines)."""
        summary = train_crowdnav(
            self.scenario,
            self.out,
            self.ppo,
            reward=REWARDS[self.reward],
            warm=self.warm,
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
    environment's own reward (or --reward); writes policy.safetensors and checkpoint.safetensors
    (no pickle), curve.csv/png, train.json (resumes an existing --out). Needs the sb3 extra."""

    out: OutDir
    """output folder (checkpoint, policy, curve; resumes if it holds a run)"""
    scenario: str = DEFAULT_SCENARIO
    """hr-rl → pioneer/ElevatorHRRL-v1, hl-rr → pioneer/ElevatorHLRR-v1; others by name"""
    steps: int = 1_000_000
    """total environment steps, rounded up to whole PPO updates (SB3's 2,048 steps × envs)"""
    envs: int = default(train_sb3_ppo, "n_envs")
    """environments (SB3's make_vec_env)"""
    seed: Seed = default(train_sb3_ppo, "seed")
    """seeds SB3 and the environments"""
    reward: RewardName = default(train_sb3_ppo, "reward")
    """crowdnav: the environment's own (the CrowdNav++ reward); no-intrusion: the same without
    its intrusion term; a resume must use the run's"""
    resume: Flag = False
    """require a checkpoint in --out (default: resume if there is one)"""

    def run(self) -> int:
        """Train (or resume); print the outputs and the final statistics (JSON lines)."""
        summary = train_sb3_ppo(
            self.scenario,
            self.out,
            steps=self.steps,
            n_envs=self.envs,
            seed=self.seed,
            resume=True if self.resume else None,
            command=command_line(),
            reward=self.reward,
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
