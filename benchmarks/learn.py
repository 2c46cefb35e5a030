"""Learned policies: the student's decision through ONNX Runtime and PyTorch next to the
teacher's (``student_decision``), a full DAgger run (``dagger_run``, opt-in), and CrowdNav++'s
decision time and PPO training throughput (``crowdnav_decision``,
``crowdnav_train_throughput``)."""

from __future__ import annotations

import csv
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import (
    REPO,
    SCENARIO,
    SEED,
    Case,
    Plan,
    Result,
    Target,
    elevator_setup,
    metric,
    mode,
    sgemm_256_case,
    time_cases,
)
from benchmarks.control import episode_decision_times
from pioneer.sim import get_scenario, observe


def scan_360(seed: int) -> tuple[np.ndarray, float, float, float]:
    """A synthetic 360-beam laser scan (1° steps, range_max 10 m, a few ``inf`` returns)."""
    rng = np.random.default_rng(seed)
    ranges = rng.uniform(0.4, 6.0, size=360)
    ranges[rng.random(360) < 0.05] = np.inf
    return ranges, -math.pi, 2 * math.pi / 360, 10.0


def bench_student_decision(plan: Plan) -> Result:
    """Student decision (batch 1): scan → command through ONNX Runtime (the deploy runtime,
    resampling included), observation → command through the policy's NumPy forward (the
    default) and through PyTorch (the reference; uncertainty included in both), and the
    teacher's decision timed apart, for the teacher/student ratio. Weights do not change the
    cost, so a freshly initialised MDN of the paper's architecture is timed."""
    import torch

    from pioneer.control.teacher import make_teacher
    from pioneer.deploy import StudentRuntime
    from pioneer.learn import build_student, export_onnx
    from pioneer.learn.policy import StudentPolicy

    torch.set_num_threads(1)
    model = build_student(seed=SEED + 50)
    policy = StudentPolicy(model, forward="numpy")
    reference = StudentPolicy(model, forward="torch")
    _, world, state = elevator_setup(SEED + 51)
    obs = observe(world, state)[0]
    teacher = make_teacher(SCENARIO)
    ranges, amin, inc, rmax = scan_360(SEED + 52)
    goal = np.array([2.0, 0.5])
    with tempfile.TemporaryDirectory(prefix="pioneer-bench-onnx-") as tmp:
        runtime = StudentRuntime(export_onnx(model, Path(tmp) / "student.onnx"))
        # The students round-robin with each other; the teacher apart (its 1,200 rollout
        # states flush the caches, which would time a cold student, not a 10 Hz loop's).
        cases = {
            "onnx_scan": Case(lambda _: runtime.step(ranges, amin, inc, rmax, goal, age_s=0.05)),
            "numpy_obs": Case(lambda _: policy.act(obs, {})),
            "torch_obs": Case(lambda _: reference.act(obs, {})),
        }
        secs = time_cases(cases, 10 * plan.batch_repeats, warmup=20)
        secs["teacher"] = time_cases(
            {"teacher": Case(lambda _: teacher.decide(world, state))}, plan.batch_repeats, 3
        )["teacher"]
    onnx_ms, numpy_ms, torch_ms, teacher_ms = (
        float(np.median(secs[k])) * 1e3 for k in ("onnx_scan", "numpy_obs", "torch_obs", "teacher")
    )
    return {
        "metrics": {
            "ms_onnx_scan_to_command": metric(secs["onnx_scan"] * 1e3, "ms", ("<=", 0.2)),
            "ms_numpy_obs_to_command": metric(secs["numpy_obs"] * 1e3, "ms", ("<=", 1.0)),
            "ms_torch_obs_to_command": metric(secs["torch_obs"] * 1e3, "ms", ("<=", 1.0)),
            "ms_teacher_decision": metric(secs["teacher"] * 1e3, "ms"),
            "teacher_over_student_onnx": metric([teacher_ms / onnx_ms], "x"),
            "teacher_over_student_numpy": metric([teacher_ms / numpy_ms], "x"),
            "teacher_over_student_torch": metric([teacher_ms / torch_ms], "x"),
        },
        "info": {"scan_beams": 360, "threads": 1, "model": "MDN 29-128-128-K10"},
    }


# --------------------------------------------------------------------------------------------
# dagger_run


def _checkpoint_contents(path: Path) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
    """Config, info and tensors of a student checkpoint, read by the project's reader
    (:func:`pioneer.learn.load_student`, :func:`pioneer.learn.read_checkpoint_meta`). Configs
    come with their defaults filled in, so an option added later (default = the old behaviour)
    does not make a checkpoint written before it look different; the DAgger setting that only
    chooses among a run's checkpoints (``select_episodes``) is left out, since it makes none."""
    from pioneer.learn import load_student, read_checkpoint_meta
    from pioneer.learn.dagger import DaggerConfig

    model = load_student(path)
    info = read_checkpoint_meta(path)["info"]
    if isinstance(info, dict) and "dagger" in info:
        info["dagger"] = DaggerConfig.from_dict(info["dagger"]).to_dict()
        info["dagger"].pop("select_episodes")
    return model.config.to_dict(), info, dict(model.state_dict())


def same_checkpoint(a: Path, b: Path) -> bool:
    """Equal tensors, config and info (where and with which torch it was made aside)."""
    import torch

    cfg_a, info_a, ta = _checkpoint_contents(a)
    cfg_b, info_b, tb = _checkpoint_contents(b)
    if (cfg_a, info_a) != (cfg_b, info_b) or ta.keys() != tb.keys():
        return False
    return all(torch.equal(ta[k], tb[k]) for k in ta)


def _torch_cpu_capability(checkpoint: Path) -> str:
    """torch's kernel family (e.g. "AVX2") where ``checkpoint`` was written (its metadata)."""
    from safetensors import safe_open

    with safe_open(str(checkpoint), framework="numpy") as f:
        return str((f.metadata() or {}).get("torch_cpu_capability", "unknown"))


def _chosen_round(out: Path) -> int:
    """The round whose student the run kept (its ``selection.csv``)."""
    with open(out / "selection.csv", newline="") as fh:
        return next(int(r["round"]) for r in csv.DictReader(fh) if r["chosen"] == "1")


def bench_dagger_run(plan: Plan) -> Result:
    """Wall time of a full DAgger run (50 + 10 × 50 episodes, HR-RL, MDN, 2 workers) through
    the CLI, with the shipped student's recipe (the teacher's soft margins, its default,
    ``--previous-observation``, ``--previous-command``, the teacher's previous label in the
    labels and the choice among the rounds on validation episodes: data/students/README.md).
    Opt-in (``--only dagger_run``): it takes minutes."""
    from pioneer.data import (
        STUDENT_LABEL_PREV,
        STUDENT_PREVIOUS_COMMAND,
        STUDENT_SELECT_EPISODES,
    )

    with tempfile.TemporaryDirectory(prefix="pioneer-bench-dagger-") as tmp:
        out = Path(tmp) / "dagger"
        cmd = [sys.executable, "-m", "pioneer.cli", "distill", "--scenario", SCENARIO]
        cmd += ["--previous-observation", "--select-episodes", str(STUDENT_SELECT_EPISODES)]
        cmd += ["--label-prev", STUDENT_LABEL_PREV]
        cmd += ["--previous-command"] if STUDENT_PREVIOUS_COMMAND["mdn"] else []
        t0 = time.perf_counter()
        proc = subprocess.run(
            [*cmd, "--out", str(out), "--workers", "2"],
            cwd=REPO,
            capture_output=True,
            text=True,
            check=False,
        )
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            raise RuntimeError(f"distill failed: {proc.stderr[-2000:]}")
        curves = (out / "curves.csv").read_text().splitlines()
        fresh = out / "student.safetensors"
        shipped = REPO / "src" / "pioneer" / "data" / "students" / f"{SCENARIO}-mdn.safetensors"
        same = same_checkpoint(fresh, shipped)
        capability = _torch_cpu_capability(fresh)
        chosen = _chosen_round(out)
    return {
        "metrics": {"minutes_full_run": metric([wall / 60], "min", ("<=", 5.0))},
        "info": {
            "episodes": 550,
            "workers": 2,
            "last_round": curves[-1],
            "chosen_round": chosen,
            # when the shipped student was made by this very command, a fresh run matches it bit
            # for bit on a CPU where torch picks the same kernels (compare the capabilities)
            "same_weights_as_shipped": same,
            "torch_cpu_capability": capability,
        },
    }


# --------------------------------------------------------------------------------------------
# CrowdNav++


def bench_crowdnav_decision(plan: Plan) -> Result:
    """CrowdNav++ ``policy.act`` (graph observation from the privileged state, attention, GRU
    step, increments → command) over the states of seeded HR-RL episodes, shipped weights:
    the NumPy forward (the default) and the module's (``forward="torch"``, one torch thread)."""
    from pioneer.control.registry import build_policy

    policy = build_policy("crowdnav++", SCENARIO)  # sets torch to 1 thread
    reference = build_policy("crowdnav++", SCENARIO, forward="torch")
    # the same episode count as CVaR-BF's benchmark
    secs = episode_decision_times(lambda _: policy, plan.cvar_episodes, SEED + 70, warmup=5)
    ref = episode_decision_times(lambda _: reference, plan.cvar_episodes, SEED + 70, warmup=5)
    return {
        "metrics": {
            "ms_decision": metric(secs * 1e3, "ms", ("<=", 1.0)),
            "ms_decision_p90": metric([float(np.percentile(secs, 90) * 1e3)], "ms"),
            "ms_decision_torch": metric(ref * 1e3, "ms"),
        },
        "info": {"decisions": int(secs.size), "episodes": plan.cvar_episodes, "threads": 1},
    }


# the parts of a PPO update that the profile separates: module functions of the trainer
_PHASES = {
    "build_observation": "observation",
    "step": "env",
    "classify": "env",
    "crowdnav_reward": "env",
}


def _crowdnav_phases(tr: Any, n_updates: int) -> dict[str, list[float]]:
    """µs per environment step of each part of ``n_updates`` PPO updates of trainer ``tr``:
    the graph observation, the policy's forward pass (encode, GRU, heads), the world's step
    with its events and reward, the update (PPO epochs), and the rest (sampling, buffers,
    GAE, the loop), each update a sample."""
    import pioneer.baselines.crowdnav.trainer as trainer

    spent: dict[str, float] = {}

    def timed(name: str, fn: Any) -> Any:
        def run(*args: Any, **kwargs: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                spent[name] = spent.get(name, 0.0) + time.perf_counter() - t0

        return run

    saved = {name: getattr(trainer, name) for name in _PHASES}
    out: dict[str, list[float]] = {}
    try:
        for name, phase in _PHASES.items():
            setattr(trainer, name, timed(phase, saved[name]))
        act = trainer.CrowdNavInference.act
        trainer.CrowdNavInference.act = timed("policy", act)  # type: ignore[method-assign]
        for _ in range(n_updates):
            spent.clear()
            t0 = time.perf_counter()
            batch = tr.rollout()
            t1 = time.perf_counter()
            tr.learn(batch)
            spent["update"] = time.perf_counter() - t1
            spent["rest"] = (t1 - t0) - sum(spent[k] for k in ("observation", "policy", "env"))
            for k, v in spent.items():
                out.setdefault(k, []).append(v / tr.ppo.steps_per_update * 1e6)
    finally:
        for name, fn in saved.items():
            setattr(trainer, name, fn)
        trainer.CrowdNavInference.act = act  # type: ignore[method-assign]
    return out


def bench_crowdnav_train_throughput(plan: Plan) -> Result:
    """Environment steps/s of the CrowdNav++ PPO trainer (rollout + update, HR-RL, one torch
    thread: ``pioneer train crowdnav++``'s default), per update after a warm-up one, with 16
    (the original's), 32 and 64 environments; with 64 also on two torch threads
    (``--threads 2``) and paid without the intrusion term (the ``crowdnav++-il-teacher`` row's
    PPO phase, ``--reward no-intrusion``), where an environment step's time goes
    (:func:`_crowdnav_phases`), and the rate times the host's GEMM (256³ float32), the figure
    that travels between hosts."""
    import torch

    from pioneer.baselines.crowdnav.network import CrowdNavConfig
    from pioneer.baselines.crowdnav.ppo import PPOConfig, _Trainer
    from pioneer.reward.crowdnav import NO_INTRUSION, CrowdNavRewardConfig

    metrics: dict[str, Any] = {}
    n_updates = 3 if mode(plan) == "quick" else 8

    def rates_of(tr: Any) -> list[float]:
        tr.learn(tr.rollout())
        rates = []
        for _ in range(n_updates):
            t0 = time.perf_counter()
            tr.learn(tr.rollout())
            rates.append(tr.ppo.steps_per_update / (time.perf_counter() - t0))
        return rates

    def trainer(n_envs: int, reward: CrowdNavRewardConfig | None = None) -> Any:
        return _Trainer(
            get_scenario(SCENARIO),
            PPOConfig(n_envs=n_envs, seed=SEED % 1000),
            CrowdNavConfig(max_humans=3),
            reward or CrowdNavRewardConfig(),
        )

    torch.set_num_threads(2)
    metrics["steps_per_s_64_envs_2_threads"] = metric(rates_of(trainer(64)), "steps/s")
    torch.set_num_threads(1)
    targets: dict[int, Target | None] = {16: None, 32: (">=", 2000.0), 64: (">=", 10_000.0)}
    for n_envs, target in targets.items():
        tr = trainer(n_envs)
        rates = rates_of(tr)
        metrics[f"steps_per_s_{n_envs}_envs"] = metric(rates, "steps/s", target)
    # the crowdnav++-il-teacher row's PPO phase: 64 environments paid without the intrusion term
    metrics["steps_per_s_64_envs_no_intrusion"] = metric(
        rates_of(trainer(64, NO_INTRUSION)), "steps/s", (">=", 10_000.0)
    )
    gemm = time_cases({"gemm": sgemm_256_case()}, plan.batch_repeats, warmup=3)["gemm"]
    metrics["steps_per_s_64_envs_x_gemm_ms"] = metric(
        [float(np.median(rates)) * float(np.median(gemm)) * 1e3], "steps/s·ms", (">=", 4500.0)
    )
    for phase, us in _crowdnav_phases(tr, n_updates).items():
        metrics[f"us_per_step_64_envs_{phase}"] = metric(us, "µs")
    return {
        "metrics": metrics,
        "info": {
            "rollout": 30,
            "epochs": 5,
            "minibatches": 2,
            "threads": 1,
            "updates": n_updates,
        },
    }


def bench_finetune_throughput(plan: Plan) -> Result:
    """Environment steps/s of the students' PPO fine-tuning (``pioneer finetune``'s defaults:
    8 layouts × 8 copies, 64-step rollouts), rollout and update together including the
    student's and the critic's forward passes, per update after a warm-up one; the shipped
    general student (symmetric: two passes of its network) over the two paper worlds, on one
    torch thread (the default) and on two (``--threads 2``: both cores of the 2-core
    machine for the update)."""
    import torch

    from pioneer.data import shipped_student
    from pioneer.learn.finetune_trainer import FinetuneConfig, FinetuneTrainer
    from pioneer.learn.models import load_student

    n_updates = 3 if mode(plan) == "quick" else 10
    cfg = FinetuneConfig(critic_warmup=0, seed=SEED % 1000)
    metrics: dict[str, Any] = {}
    for threads in (1, 2):
        torch.set_num_threads(threads)
        tr = FinetuneTrainer(
            load_student(shipped_student("", "mdn", True)), [["hr-rl"], ["hl-rr"]], cfg
        )
        tr.learn(tr.rollout())
        tr.end_update()
        rates, rollout_s, update_s = [], [], []
        for _ in range(n_updates):
            t0 = time.perf_counter()
            batch = tr.rollout()
            t1 = time.perf_counter()
            tr.learn(batch)
            tr.end_update()
            t2 = time.perf_counter()
            rates.append(cfg.steps_per_update / (t2 - t0))
            rollout_s.append(t1 - t0)
            update_s.append(t2 - t1)
        target: Target | None = (">=", 20_000.0) if threads == 2 else None
        metrics[f"steps_per_s_{threads}_threads"] = metric(rates, "steps/s", target)
        metrics[f"rollout_s_{threads}_threads"] = metric(rollout_s, "s")
        metrics[f"update_s_{threads}_threads"] = metric(update_s, "s")
    torch.set_num_threads(1)
    return {
        "metrics": metrics,
        "info": {"envs": cfg.envs, "rollout": cfg.rollout, "updates": n_updates},
    }
