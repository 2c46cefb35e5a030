"""Reinforcement-learning fine-tuning of a DAgger student over a layout distribution (beyond
the paper; docs/general-student.md, "Fine-tuning").

``pioneer finetune --student FILE --scenario 'general-*' --out DIR`` calls
:func:`finetune_student`. DAgger teaches the student the teacher's single choice, made with a
future the student cannot see; fine-tuning lets the student's own outcomes correct what it
learned, while a pull towards the DAgger student keeps what the teacher taught.

Policy
    The student's deterministic command μ(x) — the mean of its most probable component (MDN) or
    its regression (MLP), exactly what it executes when deployed — plus Gaussian exploration
    noise with a learned, state-independent standard deviation σ in standardised action units
    (initial ``init_std``): π(u | x) = N(μ(x), (σ · s_u)²), s_u the student's action scale. A
    symmetric student stays mirror-equivariant (its architecture makes it so).
Critic
    A separate MLP (``critic_hidden``, ReLU) of the student's standardised inputs and the
    privileged state (:func:`pioneer.learn.layout_env.privileged`: elapsed time, goal, every
    person's position, velocity, size, start and reaction). It is not deployed. For the first
    ``critic_warmup`` updates only the critic learns, so the actor's first updates see a fitted
    value.
Pull towards the DAgger student
    β_t · ½ ‖(μ(x) − μ_0(x)) / (s_u σ_0)‖², the KL divergence between the DAgger student's and
    the actor's Gaussians at the initial noise σ_0; β_t falls linearly from ``kl_coef`` to 0
    over the first ``kl_fade`` env steps.
Reward
    The CrowdNav++ reward (:mod:`pioneer.reward.crowdnav`) without its intrusion term
    (``intrusion = 0``): +10 on success, −20 on a collision, 3 per metre towards the goal, the
    discomfort and spin costs. With the intrusion term waiting beside the door pays better than
    arriving (docs/baselines.md); without it, arriving pays most.
Collision constraint (optional; ``collision_limit`` < 1)
    PPO-Lagrangian (Ray et al. 2019): maximise the return subject to "at most the share
    ``collision_limit`` of episodes end in a collision". A second critic V_c (the same
    architecture and inputs) learns the discounted collision count (cost 1 on the colliding
    step); the policy's advantage is (A_r − λ A_c) / (1 + λ)
    (:func:`pioneer.nn.ppo.lagrangian_advantage`); after each update
    λ ← max(0, λ + ``lagrange_lr`` · (c − ``collision_limit``)), c the collision rate of the
    last ``window`` training episodes (under the exploration noise). The reward alone trades
    a collision (−20) against time; the constraint states the risk allowed instead.
Risk-sensitive advantages (optional; ``risk_alpha`` < 1)
    The expected return lets a rare collision be outweighed by the many episodes in which the
    same move arrived sooner. Here the critic learns ``quantiles`` quantiles of the return
    instead (quantile regression towards the λ-returns, QR-DQN's quantile Huber loss,
    :mod:`pioneer.nn.critic`), and the policy's advantages are GAE over
    V_α(s) = CVaR_α, the mean of the worst α share of the returns the critic predicts from s:
    δ_t = r_t + γ V_α(s_{t+1}) − V_α(s_t). A move into states with a bad tail (a person who
    may walk out any moment) loses advantage even when it usually pays — the risk-averse
    reading of the return in the spirit of Tang et al. 2019, "Worst Cases Policy Gradients"
    (arXiv 1911.03618). The critic's own targets stay the λ-returns bootstrapped with its mean.
Teacher guidance (optional; ``teacher_coef`` > 0)
    The privileged teacher labels one copy in each of the first ``teacher_groups`` groups every
    step (:meth:`~pioneer.learn.layout_env.LayoutEnvs.teacher_labels`: DAgger's label, on the
    states the fine-tuned student visits), and the actor's loss gains
    β_T · mean over the labelled rows of w(x) · ½ ‖(μ(x) − u_T) / (s_u σ_0)‖² with β_T =
    ``teacher_coef``, constant. The weight w(x) = exp(−α ‖(μ_0(x) − u_T) / s_u‖²),
    α = ``teacher_alpha``, follows ADVISOR (Weihs et al., arXiv 2007.12173): the DAgger
    student μ_0, trained to imitate the teacher, measures where the teacher can be imitated from
    what the student sees; where it could not, the imitation yields to the return (α = 0:
    imitate everywhere, a fixed-weight teacher-guided RL as in TGRL, arXiv 2307.03186). Unlike
    the pull, which keeps the DAgger student, it teaches in the states the student now reaches.
PPO
    :mod:`pioneer.nn.ppo`'s GAE and clipped surrogate, γ = 0.99 and λ = 0.95 per 0.1 s step,
    clip 0.2, ``epochs`` passes of ``minibatches`` shuffled minibatches of the flattened
    rollout, advantages normalised per rollout, gradient norm ≤ 0.5, Adam for the actor (``lr``,
    with σ) and the critic (``critic_lr``). The environments are
    :class:`~pioneer.learn.layout_env.LayoutEnvs`: ``groups`` layouts × ``group_size`` copies;
    every ``layout_period`` updates every group draws a new layout.
Rehearsal (optional; ``--rehearse PATTERN …``)
    Layouts the stage does not practise, kept by a constant pull towards the starting student
    on its own states there, β_R · ½ ‖(μ(x) − μ_0(x)) / (s_u σ_0)‖² (β_R = ``rehearse_coef``;
    :mod:`pioneer.learn.rehearsal`): a stage over new families does not give back what an
    earlier stage mastered, and spends none of its env steps on it.
Layouts practised to mastery (optional; ``replay_mode = "mastery"``)
    A share ``replay`` of the draws practises a small set of hard layouts, each kept until the
    student masters it (``mastery`` of its last ``mastery_window`` episodes succeed) and then
    replaced by another it fails (:mod:`pioneer.learn.curriculum`): depth of practice on the
    cases it fails, where prioritised layouts meet them often but each only for
    ``layout_period`` updates at a time. ``train.json`` lists the layouts mastered and dropped.
    Given the teacher's success on every layout (``mastery_teacher``), the set follows regret
    instead: only layouts the teacher drives to ``mastery`` join, by how far the student
    falls below the teacher there.

Outputs in ``out/`` (each written atomically)::

    ``student.safetensors``   the fine-tuned student (the input's format and config: it runs,
                              exports and deploys like any student);
    ``checkpoint.safetensors`` the whole training state every ``checkpoint_every`` updates
                              (the actor, the DAgger student it is pulled to, the critic, σ,
                              both optimisers, every copy's state and inputs, the generators):
                              a resumed run equals an uninterrupted one on the same machine;
    ``curve.csv`` / ``curve.png``, ``train.json``.

Resuming: the same command on an ``out`` with a checkpoint continues it; a larger ``--steps``
extends a finished run; any other setting (or another input student) is refused.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import torch

from pioneer.errors import ConfigError, DataError, expect
from pioneer.interrupt import Interrupted
from pioneer.io import (
    check_not_input,
    file_sha256,
    output_dir_kind,
    run_lock,
    to_json,
    write_text_atomic,
)
from pioneer.learn.finetune_trainer import (
    CURVE_COLUMNS,
    FINETUNE_REWARD,
    FinetuneConfig,
    FinetuneTrainer,
)
from pioneer.learn.models import load_student, read_checkpoint_meta, save_student
from pioneer.nn.ppo import check_resume, curve_columns, curve_csv, update_loop

__all__ = ["CURVE_COLUMNS", "FINETUNE_REWARD", "FinetuneConfig", "finetune_student"]


# ------------------------------------------------------------------------------ the run
def _write_outputs(tr: FinetuneTrainer, out: Path, info: dict[str, Any], final: bool) -> None:
    tr.save(out / "checkpoint.safetensors", info["settings"])
    # the DAgger student's own record (its recipe, scenario, losses, earlier fine-tunings)
    # stays, beside this run's
    record = {**tr.start_info, "finetune": info}
    if tr.average is not None:  # the average is the product; the last iterate beside it
        save_student(tr.actor, out / "student-last.safetensors", record)
        save_student(tr.average, out / "student.safetensors", record)
    else:
        save_student(tr.actor, out / "student.safetensors", record)
    write_text_atomic(out / "curve.csv", curve_csv(CURVE_COLUMNS, tr.curve))
    if final:
        from pioneer.viz.plots import plot_learning_curve

        plot_learning_curve(
            curve_columns(CURVE_COLUMNS, tr.curve),
            out / "curve.png",
            title=f"student fine-tuning · {sum(map(len, tr.names))} scenario(s)",
        )
        write_text_atomic(out / "train.json", to_json(info, indent=2) + "\n")


def finetune_student(
    student: str | Path,
    scenarios: Sequence[str],
    out_dir: str | Path,
    config: FinetuneConfig | None = None,
    resume: bool | None = None,
    progress: bool = True,
    command: str = "",
    torch_threads: int | None = 1,
    on_update: Callable[[dict[str, float]], None] | None = None,
    mastery_teacher: Mapping[str, float] | None = None,
    rehearse: Sequence[str] = (),
) -> dict[str, Any]:
    """Fine-tune (or resume) the student at ``student`` over ``scenarios`` (names or patterns
    such as ``general-*``; each entry drawn equally often, a pattern's matches uniformly or,
    with ``stratify``, by situation); returns the summary written to ``train.json``.

    ``resume``: ``None`` continues from ``out/checkpoint.safetensors`` if there is one,
    ``True`` requires it, ``False`` refuses it. ``mastery_teacher``: a reference policy's
    success (0–1) on every layout of the patterns with more than one (``replay_mode =
    "mastery"`` only; the curriculum then follows regret, :mod:`pioneer.learn.curriculum`).
    ``rehearse``: names or patterns of layouts rehearsed, not practised
    (:mod:`pioneer.learn.rehearsal`).
    Every input is checked before ``out`` is created; one run writes to ``out`` at a time
    (:func:`pioneer.io.run_lock`).
    """
    from pioneer.learn.dagger_folder import scenario_set

    cfg = config or FinetuneConfig()
    if not scenarios:
        raise ConfigError(expect("--scenario", "one or more scenarios", "none", "name one"))
    names = [scenario_set(pattern) for pattern in scenarios]
    rehearsed = [scenario_set(pattern) for pattern in rehearse]
    _check_curriculum(cfg, scenarios, names, mastery_teacher)
    src = Path(student)
    start = load_student(src)
    obs_dims = {_obs_dim(n) for pool in [*names, *rehearsed] for n in pool}
    if obs_dims != {start.config.obs_dim}:
        raise DataError(
            expect(
                f"student {src}: obs_dim",
                f"the scenarios' observation width {sorted(obs_dims)}",
                start.config.obs_dim,
                "fine-tune a student of these scenarios' LiDAR",
            )
        )
    if cfg.teacher_coef > 0.0:  # the guiding teacher plans with its base's shipped reward
        from pioneer.data import shipped_demos
        from pioneer.sim.scenarios import scenario_base

        for base in sorted({scenario_base(n) for pool in names for n in pool}):
            try:
                shipped_demos(base)
            except DataError:
                raise DataError(
                    expect(
                        "--teacher-coef: the guiding teacher's reward",
                        "scenarios whose base has shipped demos",
                        base,
                        "give the variant a built-in 'base' or drop --teacher-coef",
                    )
                ) from None
    out = output_dir_kind(out_dir)
    for written in ("student.safetensors", "student-last.safetensors"):
        check_not_input(out / written, [src])
    ckpt = out / "checkpoint.safetensors"
    check_resume(resume, ckpt, out)
    if torch_threads is not None:
        torch.set_num_threads(int(torch_threads))
    tr = FinetuneTrainer(start, names, cfg, mastery_teacher, rehearsed, progress)
    tr.start_info = _start_info(read_checkpoint_meta(src)["info"])
    settings = tr.settings(file_sha256(src))
    with run_lock(out):
        check_resume(resume, ckpt, out)  # again, holding the lock
        resumed_from = None
        if ckpt.is_file():
            tr.load(ckpt, settings)
            resumed_from = tr.update

        def info() -> dict[str, Any]:
            last = tr.curve[-1] if tr.curve else [math.nan] * len(CURVE_COLUMNS)
            return {
                "student": str(src),
                "command": command,
                "settings": settings,
                "updates": tr.update,
                "env_steps": tr.env_steps,
                "episodes": tr.episodes,
                "wall_time_s": round(tr.wall, 1),
                "resumed_from_update": resumed_from,
                "final": dict(zip(CURVE_COLUMNS[3:7], last[3:7], strict=True)),
                **_curriculum_report(tr),
            }

        t_start, s_start = time.perf_counter(), tr.env_steps
        try:
            update_loop(
                tr,
                cfg.updates,
                cfg.steps_per_update,
                CURVE_COLUMNS,
                "fine-tuning",
                progress,
                cfg.checkpoint_every,
                lambda: _write_outputs(tr, out, info(), final=False),
                on_update,
            )
            summary = info()
            summary["steps_per_s_this_run"] = (tr.env_steps - s_start) / max(
                time.perf_counter() - t_start, 1e-9
            )
            _write_outputs(tr, out, summary, final=True)
        except Interrupted as exc:
            _write_outputs(tr, out, info(), final=False)
            exc.kept = f"update {tr.update} of {cfg.updates} kept in {ckpt}"
            raise
        return summary


def _curriculum_report(tr: FinetuneTrainer) -> dict[str, Any]:
    """The curriculum's layouts now in practice and those that left (``"mastery"`` only)."""
    cur = tr.envs.curriculum
    if cur is None:
        return {}
    return {"curriculum": {"active": list(cur.active), "left": list(cur.history)}}


_CURRICULUM = ("mastery_layouts", "mastery", "mastery_window", "mastery_limit")


def _check_curriculum(
    cfg: FinetuneConfig,
    scenarios: Sequence[str],
    names: Sequence[Sequence[str]],
    table: Mapping[str, float] | None,
) -> None:
    """The curriculum has something to practise, its settings go with ``replay_mode =
    "mastery"``, and a teacher table covers every layout it may practise."""
    if cfg.replay_mode == "mastery" and (cfg.replay <= 0.0 or all(len(p) < 2 for p in names)):
        raise ConfigError(
            expect(
                "--replay-mode mastery",
                "--replay above 0 and a --scenario pattern of two or more layouts to practise",
                f"--replay {cfg.replay}, --scenario {' '.join(scenarios)}",
                "give e.g. --replay 0.5 and a pattern such as 'general-*'",
            )
        )
    plain = FinetuneConfig()
    given = [f for f in _CURRICULUM if getattr(cfg, f) != getattr(plain, f)]
    given += ["mastery_teacher"] if table is not None else []
    if cfg.replay_mode != "mastery" and given:
        flags = " ".join("--" + f.replace("_", "-") for f in given)
        raise ConfigError(
            expect(
                flags,
                "--replay-mode mastery (the curriculum they set)",
                f"--replay-mode {cfg.replay_mode}",
                f"add --replay-mode mastery or drop {flags}",
            )
        )
    if table is None:
        return
    missing = [n for pool in names if len(pool) > 1 for n in pool if n not in table]
    if missing:
        raise ConfigError(
            expect(
                "--mastery-teacher",
                "the teacher's success on every layout of the --scenario patterns",
                f"none for {len(missing)} layout(s), e.g. {missing[0]}",
                "evaluate the teacher on those layouts (pioneer eval --seed-set validation)",
            )
        )
    if not any(table[n] >= cfg.mastery for pool in names if len(pool) > 1 for n in pool):
        raise ConfigError(
            expect(
                "--mastery-teacher",
                f"a layout the teacher drives to --mastery {cfg.mastery} (one to practise)",
                "none",
                "lower --mastery or give layouts the teacher drives",
            )
        )


def _obs_dim(name: str) -> int:
    from pioneer.sim.scenarios import get_scenario

    return int(get_scenario(name).sim.lidar.obs_dim)


def _start_info(info: dict[str, Any]) -> dict[str, Any]:
    """The starting student's record, carried into the fine-tuned one; a student fine-tuned
    before keeps its earlier fine-tunings, oldest first, under ``finetune_earlier``."""
    out = {k: v for k, v in info.items() if k not in ("finetune", "finetune_earlier")}
    earlier = [
        *info.get("finetune_earlier", []),
        *([info["finetune"]] if "finetune" in info else []),
    ]
    return out | ({"finetune_earlier": earlier} if earlier else {})
