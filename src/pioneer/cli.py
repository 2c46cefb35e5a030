"""The ``pioneer`` command. Thin: parse, call, print. Any PioneerError is one line, exit 2."""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from pioneer.errors import ConfigError, PioneerError, expect

if TYPE_CHECKING:
    from pioneer.eval.harness import PolicySpec

__all__ = ["main"]


def _cmd_run(args: argparse.Namespace) -> int:
    from pioneer.control.registry import build_policy
    from pioneer.eval.episode import run_episode
    from pioneer.sim.scenarios import get_scenario
    from pioneer.sim.world import scan

    scenario = get_scenario(args.scenario)
    spec = _policy_spec(args.policy)
    abl = _ablation_kwargs(args)
    if abl and not spec.name.startswith("teacher"):
        raise ConfigError(
            expect(
                "--no-density/--no-goal/--no-obstacle",
                "a teacher policy",
                args.policy,
                "drop the flags",
            )
        )
    policy = build_policy(spec.name, scenario.name, **{**dict(spec.kwargs), **abl})
    if spec.label:
        policy.name = spec.label
    if abl:
        policy.name = spec.row + "".join(f"-no-{k}" for k in abl)
    want_frames = bool(args.gif or args.png)
    rec, traj = run_episode(scenario, policy, seed=args.seed, record=want_frames)
    if traj is not None:
        from tqdm import tqdm

        from pioneer.viz import plot_trajectory, render_frame, save_gif

        if args.gif:
            frames = []
            robot = traj.robot
            for k, st in enumerate(tqdm(traj.states, desc="frames", unit="f", disable=None)):
                rays = scan(traj.world, st)[0] if args.lidar else None
                frames.append(render_frame(traj.world, st, rays, trail=robot[: k + 1, :2]))
            save_gif(frames, args.gif, fps=1.0 / scenario.sim.dt)
            print(f"wrote {args.gif}")
        if args.png:
            title = f"{scenario.name} · {policy.name} · seed {args.seed} · {rec.event}"
            plot_trajectory(traj.world, traj.states, args.png, title=title)
            print(f"wrote {args.png}")
    print(json.dumps(rec.to_dict()))
    return 0


def _cmd_demos_generate(args: argparse.Namespace) -> int:
    from pioneer.demos.generate import generate

    cmd = " ".join(["pioneer", *sys.argv[1:]]) if sys.argv[0].endswith("pioneer") else ""
    d = generate(args.scenario, args.positive, args.negative, seed=args.seed, command=cmd)
    d.save(args.out)
    print(json.dumps({"out": args.out, **d.summary()}))
    return 0


def _cmd_demos_show(args: argparse.Namespace) -> int:
    from pioneer.reward.dataset import Dataset

    d = Dataset.load(args.demos)
    meta = {k: v for k, v in d.meta.items() if k not in ("feature_names", "units")}
    print(json.dumps({**d.summary(), "meta": meta}, indent=2))
    return 0


def _cmd_teleop(args: argparse.Namespace) -> int:
    from pioneer.demos.teleop import TeleopSession

    cmd = " ".join(["pioneer", *sys.argv[1:]]) if sys.argv[0].endswith("pioneer") else ""
    session = TeleopSession(
        args.scenario, args.out, seed=args.seed, max_episodes=args.max_episodes, command=cmd
    )
    print(json.dumps(session.run()))
    return 0


def _cmd_reward_fit(args: argparse.Namespace) -> int:
    from pioneer.reward.dataset import Dataset
    from pioneer.reward.density import DensityConfig, DensityReward
    from pioneer.reward.features import default_feature_map, feature_map
    from pioneer.reward.select import select_length_scale

    d = Dataset.load(args.demos)
    if args.min_gamma is not None:
        d = d.filter(min_gamma=args.min_gamma)
    fm = feature_map(args.features or default_feature_map(d.scenarios))
    z = fm.from_dataset(d)
    cfg = DensityConfig(
        length_scale=args.length_scale,
        lam=args.lam,
        beta=args.beta,
        max_inducing=args.max_inducing,
        inducing=args.inducing,
    )
    records = None
    if args.select_length:
        length, records = select_length_scale(z, d.gamma, d.episode, cfg)
        cfg = cfg.replace(length_scale=length)
    model = DensityReward(cfg).fit(z, d.gamma, list(fm.names))
    model.info_.update({"demos": str(args.demos), "features": fm.name})
    if records is not None:
        model.info_["length_selection"] = records
    model.save(args.out)
    print(
        json.dumps(
            {
                "out": args.out,
                "length_scale": model.length_,
                "scale": model.scale_,
                "n_train": model.n_train_,
                **model.info_,
            }
        )
    )
    return 0


def _cmd_reward_show(args: argparse.Namespace) -> int:
    import numpy as np

    from pioneer.reward.dataset import Dataset
    from pioneer.reward.density import DensityReward
    from pioneer.reward.features import default_feature_map, feature_map
    from pioneer.stats import auroc

    m = DensityReward.load(args.model)
    out = {
        "model": args.model,
        "features": m.info_.get("features", "?"),
        "feature_dim": len(m.feature_names),
        "n_train": m.n_train_,
        "n_inducing": int(m.alpha_.shape[0]) if m.alpha_ is not None else 0,
        "length_scale": m.length_,
        "scale": m.scale_,
        "hyperparameters": m.config.to_dict(),
    }
    demos = args.demos or m.info_.get("demos")
    if demos:
        d = Dataset.load(demos)
        r = m(
            feature_map(
                str(m.info_.get("features", default_feature_map(d.scenarios)))
            ).from_dataset(d)
        )
        pos, neg = d.gamma > 0, d.gamma < 0
        out["demos"] = str(demos)
        out["reward_positive_mean"] = float(np.mean(r[pos])) if pos.any() else None
        out["reward_negative_mean"] = float(np.mean(r[neg])) if neg.any() else None
        out["auroc_pos_vs_neg"] = auroc(r[pos | neg], pos[pos | neg])
    print(json.dumps(out, indent=2))
    return 0


def _cmd_study_static(args: argparse.Namespace) -> int:
    from pioneer.experiments.static_study import run_static_study
    from pioneer.reward.dataset import Dataset

    summary = run_static_study(Dataset.load(args.demos), args.out)
    print(json.dumps(summary, indent=2))
    return 0


def _ablation_kwargs(args: argparse.Namespace) -> dict[str, bool]:
    kw = {}
    for flag in ("density", "goal", "obstacle"):
        if getattr(args, f"no_{flag}", False):
            kw[flag] = False
    return kw


def _add_ablation_flags(p: argparse.ArgumentParser) -> None:
    p.add_argument("--no-density", action="store_true", help="teacher without the learned term")
    p.add_argument("--no-goal", action="store_true", help="teacher without the goal term")
    p.add_argument("--no-obstacle", action="store_true", help="teacher without the obstacle term")


def _policy_spec(text: str) -> PolicySpec:
    """``--policy NAME[:key=value,…]`` → a checked spec (parameters against the factory; a
    ``checkpoint``/``model``/``reward``/``weights`` path made absolute for every worker)."""
    from pioneer.control.registry import check_policy_kwargs, check_policy_name
    from pioneer.eval.harness import PolicySpec

    spec = PolicySpec.parse(text)
    check_policy_name(spec.name)
    kwargs = dict(spec.kwargs)
    if kwargs:
        check_policy_kwargs(spec.name, kwargs)
        for key in ("checkpoint", "model", "reward", "weights"):
            if isinstance(kwargs.get(key), str) and "{" not in kwargs[key]:
                kwargs[key] = str(Path(kwargs[key]).resolve())
    return dataclasses.replace(spec, kwargs=tuple(sorted(kwargs.items())))


def _cmd_scenarios(args: argparse.Namespace) -> int:
    """List the scenarios (built-in and from ``--scenarios`` files); optionally draw each."""
    import numpy as np

    from pioneer.data import base_scenario
    from pioneer.sim.scenarios import get_scenario, sample_state, scenario_names

    configs = {name: get_scenario(name) for name in scenario_names()}
    print(
        f"{'scenario':<24} {'learned parts of':<16} {'humans':>6} {'map [m]':>11} {'limit [s]':>9}"
    )
    for name, cfg in configs.items():
        xmin, xmax, ymin, ymax = cfg.bounds
        size = f"{xmax - xmin:.1f} × {ymax - ymin:.1f}"
        print(
            f"{name:<24} {base_scenario(name):<16} {len(cfg.humans):>6} {size:>11} "
            f"{cfg.sim.time_limit:>9.1f}"
        )
    if args.png_dir:
        from tqdm import tqdm

        from pioneer.viz import plot_trajectory

        out = Path(args.png_dir)
        out.mkdir(parents=True, exist_ok=True)
        for name, cfg in tqdm(configs.items(), desc="layouts", unit="png", disable=None):
            state = sample_state(cfg, np.random.default_rng(args.seed))
            title = f"{name} · initial state, seed {args.seed}"
            plot_trajectory(cfg.world(), [state], out / f"{name}.png", title=title)
        print(f"wrote {len(configs)} layouts to {out}")
    return 0


def _cmd_eval(args: argparse.Namespace) -> int:
    from pioneer.eval.harness import PolicySpec, evaluate
    from pioneer.eval.metrics import summarize

    abl = _ablation_kwargs(args)
    suffix = "".join(f"-no-{k}" for k in abl)
    specs = []
    for text in args.policy:
        spec = _policy_spec(text)
        if abl and spec.name == "teacher":
            kw = {**dict(spec.kwargs), **abl}
            spec = PolicySpec(spec.name, tuple(sorted(kw.items())), spec.row + suffix)
        specs.append(spec)
    rows = [s.row for s in specs]
    twice = sorted({r for r in rows if rows.count(r) > 1})
    if twice:
        raise ConfigError(
            expect(
                "--policy rows", "distinct labels", twice, "add label=NAME to the repeated policy"
            )
        )
    recs = evaluate(
        args.scenario,
        specs,
        args.seeds,
        args.trials,
        args.out,
        args.workers,
        backend=args.backend,
        ray_address=args.ray_address,
    )
    summary = summarize(recs)
    from pioneer.eval.report import write_summary

    write_summary(args.out, summary)
    for key, s in summary.items():
        print(
            f"{key}: SR {s['success_rate']['mean']:.1f}%  TT {s['time_mean_s']['mean']:.2f} s  "
            f"PL {s['path_length_mean_m']['mean']:.2f} m  ({s['episodes']} episodes)"
        )
    return 0


def _cmd_reproduce(args: argparse.Namespace) -> int:
    from pioneer.experiments.reproduce import reproduce

    print(json.dumps(reproduce(args.profile, args.out, args.workers), indent=2))
    return 0


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from pioneer.experiments.calibration import BANDS, calibrate

    res = calibrate(args.scenario, args.episodes, args.out, args.workers, driver=args.driver)
    for name, st in res["scenarios"].items():
        cells = []
        for key in (*BANDS, "teacher_risky_frame_share_gap", "risky_at_start_share"):
            lo_hi = BANDS.get(key)
            mark = "" if lo_hi is None else (" ok" if st["within_band"][key] else " OUT")
            cells.append(f"{key} {st[key]:.3g}{mark}")
        print(f"{name}: " + "; ".join(cells))
    print(f"wrote {Path(args.out) / 'calibration.json'} ({res['elapsed_s']:.0f} s)")
    return 0


def _cmd_distill(args: argparse.Namespace) -> int:
    from pioneer.learn.dagger import DaggerConfig, run_dagger

    cfg = DaggerConfig(
        scenario=args.scenario,
        student=args.student,
        action_mode=args.action_mode,
        nll_beta=args.nll_beta,
        label_prev=args.label_prev,
        teacher_episodes=args.teacher_episodes,
        rounds=args.rounds,
        episodes_per_round=args.episodes_per_round,
        epochs_initial=args.epochs_initial,
        epochs_per_round=args.epochs_per_round,
        seed=args.seed,
    )
    res = run_dagger(cfg, args.out, args.workers, reward=args.reward)
    last = res.curves[-1]
    print(
        f"student: {res.student}  ({last['frames_total']} frames, last round SR "
        f"{100 * last['success_rate']:.0f}%); curves: {res.out / 'curves.png'}"
    )
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from pioneer.learn.export import export_checkpoint

    print(json.dumps(export_checkpoint(args.model, args.out, action_mode=args.action_mode)))
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from pioneer.deploy.bag import replay_bag

    summary = replay_bag(
        args.bag,
        args.model,
        args.out,
        goal=args.goal,
        goal_frame=args.goal_frame,
        scan_topic=args.scan_topic,
        odom_topic=args.odom_topic,
    )
    print(json.dumps(summary))
    return 0


def _cmd_train_crowdnav(args: argparse.Namespace) -> int:
    from pioneer.baselines.crowdnav.imitation import WarmStartConfig
    from pioneer.baselines.crowdnav.ppo import PPOConfig, train_crowdnav

    ppo = PPOConfig(
        total_steps=args.steps,
        n_envs=args.envs,
        lr=args.lr,
        entropy_coef=args.entropy_coef,
        seed=args.seed,
        checkpoint_every=args.checkpoint_every,
    )
    warm = WarmStartConfig(
        expert=args.bc_expert,
        bc_episodes=args.bc_episodes,
        bc_epochs=args.bc_epochs,
        dagger_rounds=args.dagger_rounds,
        dagger_episodes=args.dagger_episodes,
        critic_warmup=args.critic_warmup,
    )
    cmd = " ".join(["pioneer", *sys.argv[1:]]) if sys.argv[0].endswith("pioneer") else ""
    summary = train_crowdnav(
        args.scenario,
        args.out,
        ppo,
        warm=warm,
        resume=True if args.resume else None,
        command=cmd,
        torch_threads=args.threads,
    )
    print(json.dumps({"out": args.out, **{k: summary[k] for k in ("updates", "env_steps")}}))
    print(json.dumps({"final": summary["final"], "wall_time_s": summary["wall_time_s"]}))
    return 0


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="pioneer", description="PioneeR social navigation toolkit")
    p.add_argument(
        "--scenarios",
        action="append",
        default=[],
        metavar="FILE",
        help="register the scenario variants of a JSON file (format pioneer.scenarios/1, see "
        "docs/simulator.md) for the command; repeatable; same as listing it in PIONEER_SCENARIOS",
    )
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run one episode of a policy; optionally write a GIF/PNG")
    r.add_argument("--scenario", default="hr-rl", help="hr-rl, hl-rr, static, hr-rl-r03, …")
    r.add_argument(
        "--policy",
        default="goal",
        help="controller NAME or NAME:key=value,… (e.g. student-mdn:checkpoint=PATH)",
    )
    r.add_argument("--seed", type=int, default=0, help="episode seed")
    r.add_argument("--gif", help="write an animation of the episode here")
    r.add_argument("--png", help="write a trajectory plot here")
    r.add_argument("--lidar", action="store_true", help="draw the LiDAR rays in the GIF")
    _add_ablation_flags(r)
    r.set_defaults(func=_cmd_run)

    sc = sub.add_parser("scenarios", help="list the scenarios (with --scenarios files); draw them")
    sc.add_argument("--png-dir", help="write one PNG per scenario (its layout and a start state)")
    sc.add_argument("--seed", type=int, default=0, help="seed of the drawn start state")
    sc.set_defaults(func=_cmd_scenarios)

    e = sub.add_parser("eval", help="evaluate policies: N seeds × M trials, parallel, resumable")
    e.add_argument("--scenario", nargs="+", default=["hr-rl", "hl-rr"])
    e.add_argument(
        "--policy",
        nargs="+",
        default=["teacher"],
        help="NAME or NAME:key=value,…,label=ROW (e.g. student-mdn:checkpoint=PATH,label=mine)",
    )
    e.add_argument("--seeds", type=int, default=5)
    e.add_argument("--trials", type=int, default=100)
    e.add_argument("--out", required=True, help="output folder (episodes.jsonl, summary.json)")
    e.add_argument("--workers", type=int, help="processes (default: all cores)")
    e.add_argument("--backend", choices=["process", "ray"], default="process")
    e.add_argument("--ray-address", help="Ray cluster address (default: start a local Ray)")
    _add_ablation_flags(e)
    e.set_defaults(func=_cmd_eval)

    rp = sub.add_parser("reproduce", help="the paper's tables and figures (the main job)")
    rp.add_argument(
        "--profile",
        choices=["smoke", "quick", "paper"],
        default="quick",
        help="smoke: 1 episode per row (a pipeline check); quick: 2 × 10; paper: 5 × 100",
    )
    rp.add_argument("--out", default="out/reproduce")
    rp.add_argument("--workers", type=int, help="processes (default: all cores)")
    rp.set_defaults(func=_cmd_reproduce)

    cal = sub.add_parser(
        "calibrate", help="world statistics beside the paper's evidence (validation seeds)"
    )
    cal.add_argument("--scenario", nargs="+", default=["hr-rl", "hl-rr"], help="hr-rl hl-rr …")
    cal.add_argument("--episodes", type=int, default=100, help="validation episodes per scenario")
    cal.add_argument("--out", required=True, help="folder for calibration.json")
    cal.add_argument("--workers", type=int, help="processes (default: all cores)")
    cal.add_argument(
        "--driver", default="teacher", help="policy behind the teacher_* statistics (teacher)"
    )
    cal.set_defaults(func=_cmd_calibrate)

    d = sub.add_parser("distill", help="DAgger: distil the teacher into a LiDAR-only student")
    d.add_argument("--scenario", default="hr-rl", help="hr-rl, hl-rr, …")
    d.add_argument("--student", choices=["mdn", "mlp"], default="mdn")
    d.add_argument(
        "--action-mode", choices=["mode", "mean"], default="mode", help="MDN's executed action"
    )
    d.add_argument("--nll-beta", type=float, default=0.0, help="MDN's β-NLL exponent in [0, 1]")
    d.add_argument(
        "--label-prev",
        choices=["applied", "teacher"],
        default="applied",
        help="u_{t-1} in the teacher's smoothed label on student-driven steps",
    )
    d.add_argument("--out", required=True, help="output folder (resumes if it exists)")
    d.add_argument("--teacher-episodes", type=int, default=50, help="round 0 episodes")
    d.add_argument("--rounds", type=int, default=10, help="student-driven rounds")
    d.add_argument("--episodes-per-round", type=int, default=50)
    d.add_argument("--epochs-initial", type=int, default=40, help="epochs after round 0")
    d.add_argument("--epochs-per-round", type=int, default=10, help="epochs after later rounds")
    d.add_argument("--seed", type=int, default=0)
    d.add_argument("--workers", type=int, help="processes collecting episodes (default: cores)")
    d.add_argument("--reward", help="teacher reward model .npz (default: fit on shipped demos)")
    d.set_defaults(func=_cmd_distill)

    x = sub.add_parser("export", help="student checkpoint → ONNX, with a parity check")
    x.add_argument("--model", required=True, help="student .safetensors or a distill folder")
    x.add_argument("--out", required=True, help="output .onnx")
    x.add_argument("--action-mode", choices=["mode", "mean"], help="default: the model's")
    x.set_defaults(func=_cmd_export)

    rb = sub.add_parser("replay", help="ROS bag LaserScans → student commands CSV (no ROS)")
    rb.add_argument("--bag", required=True, help="ROS 1 .bag file or ROS 2 bag folder")
    rb.add_argument("--model", required=True, help="student .onnx (from pioneer export)")
    rb.add_argument("--out", required=True, help="output CSV")
    rb.add_argument("--goal", nargs=2, type=float, required=True, metavar=("X", "Y"), help="[m]")
    rb.add_argument("--goal-frame", choices=["robot", "odom"], default="robot")
    rb.add_argument("--scan-topic", help="LaserScan topic (default: the bag's only one)")
    rb.add_argument("--odom-topic", help="Odometry topic for --goal-frame odom (default: only)")
    rb.set_defaults(func=_cmd_replay)

    train = sub.add_parser("train", help="train an RL baseline").add_subparsers(
        dest="train_command", required=True
    )
    tc = train.add_parser("crowdnav++", help="CrowdNav++ with PPO (resumes an existing --out)")
    tc.add_argument("--scenario", default="hr-rl", help="hr-rl, hl-rr, …")
    tc.add_argument("--out", required=True, help="output folder (checkpoint, policy, curve)")
    tc.add_argument("--steps", type=int, default=2_000_000, help="total environment steps")
    tc.add_argument("--envs", type=int, default=16, help="environments stepped together")
    tc.add_argument("--seed", type=int, default=0)
    tc.add_argument("--lr", type=float, default=3e-4, help="Adam learning rate")
    tc.add_argument("--entropy-coef", type=float, default=0.01, help="PPO entropy bonus")
    tc.add_argument(
        "--bc-episodes", type=int, default=0, help="expert demonstrations to imitate first (0: no)"
    )
    tc.add_argument(
        "--bc-expert",
        choices=["sfm", "dwa", "teacher"],
        default="sfm",
        help="the demonstrator (sfm, dwa: independent of PioneeR; teacher: PioneeR's own)",
    )
    tc.add_argument("--bc-epochs", type=int, default=30, help="behaviour-cloning epochs")
    tc.add_argument("--dagger-rounds", type=int, default=0, help="DAgger rounds after cloning")
    tc.add_argument("--dagger-episodes", type=int, default=20, help="episodes per DAgger round")
    tc.add_argument(
        "--critic-warmup", type=int, default=0, help="[updates] critic-only updates before PPO"
    )
    tc.add_argument("--checkpoint-every", type=int, default=50, help="[updates]")
    tc.add_argument("--threads", type=int, default=1, help="torch threads")
    tc.add_argument(
        "--resume", action="store_true", help="require a checkpoint in --out (default: if any)"
    )
    tc.set_defaults(func=_cmd_train_crowdnav)

    demos = sub.add_parser("demos", help="demonstration datasets").add_subparsers(
        dest="demos_command", required=True
    )
    g = demos.add_parser("generate", help="scripted demonstrations (γ = +1 and −1)")
    g.add_argument("--scenario", required=True, help="hr-rl, hl-rr or static")
    g.add_argument("--out", required=True, help="output .npz")
    g.add_argument("--positive", type=int, help="positive samples (default: the paper's count)")
    g.add_argument("--negative", type=int, help="negative samples (default: the paper's count)")
    g.add_argument("--seed", type=int, default=0)
    g.set_defaults(func=_cmd_demos_generate)
    sh = demos.add_parser("show", help="summary of a dataset file")
    sh.add_argument("demos")
    sh.set_defaults(func=_cmd_demos_show)

    t = sub.add_parser("teleop", help="drive with the keyboard and record labelled demos")
    t.add_argument("--scenario", default="hr-rl", help="hr-rl, hl-rr, static, …")
    t.add_argument("--out", required=True, help="dataset .npz (appended to after every episode)")
    t.add_argument("--seed", type=int, default=0, help="episode k is seeded seed + k")
    t.add_argument("--max-episodes", type=int, help="stop after this many saved episodes")
    t.set_defaults(func=_cmd_teleop)

    reward = sub.add_parser("reward", help="the learned density reward").add_subparsers(
        dest="reward_command", required=True
    )
    f = reward.add_parser("fit", help="fit the density reward on a dataset")
    f.add_argument("--demos", required=True)
    f.add_argument("--out", required=True, help="output model .npz")
    f.add_argument("--features", choices=["xy", "obs_action"], help="default: by scenario")
    f.add_argument("--length-scale", type=float, help="l in standardised units")
    f.add_argument("--select-length", action="store_true", help="pick l by held-out AUROC")
    f.add_argument("--lam", type=float, default=1e-2)
    f.add_argument("--beta", type=float, default=1e-3)
    f.add_argument("--max-inducing", type=int, default=2000)
    f.add_argument("--inducing", choices=["kmeans", "fps"], default="kmeans")
    f.add_argument("--min-gamma", type=float, help="drop samples with γ below this")
    f.set_defaults(func=_cmd_reward_fit)
    s2 = reward.add_parser("show", help="summary of a fitted model")
    s2.add_argument("--model", required=True)
    s2.add_argument("--demos", help="dataset to score (default: the training set)")
    s2.set_defaults(func=_cmd_reward_show)

    study = sub.add_parser("study", help="paper studies").add_subparsers(
        dest="study_command", required=True
    )
    st = study.add_parser("static", help="the synthetic static study (paper Fig. 3)")
    st.add_argument("--demos", default=str(_shipped("static.npz")), help="static-study demos")
    st.add_argument("--out", required=True, help="output folder")
    st.set_defaults(func=_cmd_study_static)
    return p


def _shipped(name: str) -> Path:
    """Path of a dataset shipped with the package."""
    return Path(__file__).parent / "data" / "demos" / name


def _single_threaded_blas() -> None:
    """The matrices here are small; BLAS threads only fight the simulation and the workers
    for the cores (a teacher decision takes 3x longer with OpenBLAS's default threads)."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(1, user_api="blas")


def _register_scenario_files(files: Sequence[str]) -> None:
    """Add ``--scenarios`` files to ``PIONEER_SCENARIOS``, which spawned worker processes
    inherit, and load them here once (a bad file fails before any work). Without files the
    simulator is not imported, so robot-side commands (``replay``) stay free of numba."""
    if files:
        from pioneer.sim.scenarios import SCENARIOS_ENV, load_env_scenarios

        paths = [str(Path(f).resolve()) for f in files]
        old = os.environ.get(SCENARIOS_ENV, "")
        os.environ[SCENARIOS_ENV] = os.pathsep.join([*filter(None, [old]), *paths])
        load_env_scenarios()


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pioneer`` console script."""
    args = _parser().parse_args(argv)
    _single_threaded_blas()
    try:
        _register_scenario_files(args.scenarios)
        return int(args.func(args))
    except PioneerError as exc:
        print(f"pioneer: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
