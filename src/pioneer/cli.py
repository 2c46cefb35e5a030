"""The ``pioneer`` command. Thin: parse, call, print. Any PioneerError is one line, exit 2."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence

from pioneer.errors import PioneerError

__all__ = ["main"]


def _cmd_run(args: argparse.Namespace) -> int:
    import pioneer.control  # noqa: F401  (registers the policies)
    from pioneer.control.policy import make_policy
    from pioneer.eval.episode import run_episode
    from pioneer.sim.scenarios import get_scenario
    from pioneer.sim.world import scan

    scenario = get_scenario(args.scenario)
    policy = make_policy(args.policy)
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


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="pioneer", description="PioneeR social navigation toolkit")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run one episode of a policy; optionally write a GIF/PNG")
    r.add_argument("--scenario", default="hr-rl", help="hr-rl, hl-rr, static, hr-rl-r03, …")
    r.add_argument("--policy", default="goal", help="controller name (see pioneer.control)")
    r.add_argument("--seed", type=int, default=0, help="episode seed")
    r.add_argument("--gif", help="write an animation of the episode here")
    r.add_argument("--png", help="write a trajectory plot here")
    r.add_argument("--lidar", action="store_true", help="draw the LiDAR rays in the GIF")
    r.set_defaults(func=_cmd_run)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pioneer`` console script."""
    args = _parser().parse_args(argv)
    try:
        return int(args.func(args))
    except PioneerError as exc:
        print(f"pioneer: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
