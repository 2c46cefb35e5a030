"""``pioneer run``, ``pioneer eval``, ``pioneer reproduce``: episodes, evaluations, the paper."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import TYPE_CHECKING, Annotated, Any, Literal, TypeAlias

import tyro

from pioneer.cli._files import OutDir, Output
from pioneer.cli._options import (
    Ablation,
    Ablations,
    Flag,
    Seed,
    Workers,
    metavar,
    one_of,
    optional,
    policy_spec,
    require_some,
)
from pioneer.cli._text import number
from pioneer.config import default
from pioneer.errors import ConfigError, expect
from pioneer.eval.harness import evaluate
from pioneer.eval.report import metric_tables
from pioneer.eval.tables import METRIC_SETS
from pioneer.experiments.reproduce import reproduce
from pioneer.experiments.reproduce_plan import PROFILES, SCENARIOS
from pioneer.interrupt import kept
from pioneer.io import to_json
from pioneer.seeds import SeedSet
from pioneer.sim.scenarios import DEFAULT_SCENARIO

if TYPE_CHECKING:
    from pioneer.envs.policy import Policy
    from pioneer.eval.episode import Trajectory
    from pioneer.eval.harness import PolicySpec
    from pioneer.sim.scenarios import ScenarioConfig
    from pioneer.sim.world import State

    ProfileName: TypeAlias = str
    MetricSet: TypeAlias = str
else:
    ProfileName = one_of(PROFILES)
    MetricSet = one_of(METRIC_SETS)

__all__ = ["Eval", "Reproduce", "Run", "Summarize"]

_PAPER = PROFILES["paper"]  # the paper's protocol: eval's default seeds × trials


def _frame(s: State) -> dict[str, float]:
    """One frame of ``pioneer run --frames``: time [s], pose [m, m, rad], the last applied
    command [m/s, rad/s] and the swept human and wall gaps of the last step [m]."""
    x, y, theta = (float(v) for v in s.robot[0])
    v, omega = (float(c) for c in s.command[0])
    return {
        "t": float(s.t[0]),
        "x": x,
        "y": y,
        "theta": theta,
        "v": v,
        "omega": omega,
        "gap": float(s.gap[0]),
        "wall_gap": float(s.wall_gap[0]),
    }


@dataclasses.dataclass(frozen=True)
class Run:
    """Run one episode of a policy and print its record (one JSON line, without per-frame
    series); optionally every frame too, and a drawing."""

    scenario: str = DEFAULT_SCENARIO
    """hr-rl, hl-rr, static, hr-rl-r03, …"""
    policy: Annotated[str, metavar("POLICY")] = "goal"
    """controller NAME or NAME:key=value,… (e.g. student-mdn:checkpoint=PATH)"""
    seed: Seed = 0
    """episode seed"""
    gif: Annotated[str | None, optional("FILE", "none"), Output("file")] = None
    """write an animation of the episode here"""
    png: Annotated[str | None, optional("FILE", "none"), Output("file")] = None
    """write a trajectory plot here"""
    lidar: Flag = False
    """draw the LiDAR rays in the GIF"""
    frames: Flag = False
    """print a JSON line of every frame (time, pose, command, gaps) before the record,
    and keep a student's per-frame uncertainty in the record"""
    ablation: Ablations = dataclasses.field(default_factory=Ablation)

    def run(self) -> int:
        """One episode; the record is the last line printed."""
        from pioneer.eval.episode import run_episode
        from pioneer.sim.scenarios import get_scenario

        if self.lidar and not self.gif:
            raise ConfigError(
                expect("--lidar", "--gif FILE (it draws the rays in it)", None, "add --gif FILE")
            )
        scenario = get_scenario(self.scenario)
        policy = self._policy(scenario.name)
        record = bool(self.gif or self.png or self.frames)
        rec, traj = run_episode(scenario, policy, seed=self.seed, record=record)
        if traj is not None and (self.gif or self.png):
            self._draw(scenario, policy, traj, rec.event)
        if traj is not None and self.frames:
            for s in traj.states:
                print(to_json(_frame(s)))
        summary = rec.to_dict()
        summary.pop("series", None)  # the frame lines (--frames) carry the per-step values
        if not self.frames:
            summary.pop("frames", None)
        print(to_json(summary))
        return 0

    def _policy(self, scenario: str) -> Policy:
        from pioneer.control.registry import build_policy

        spec = policy_spec(self.policy)
        abl = self.ablation.kwargs()
        if abl and not spec.name.startswith("teacher"):
            raise ConfigError(
                expect(
                    "--no-density/--no-goal/--no-obstacle",
                    "a teacher policy",
                    self.policy,
                    "drop the flags",
                )
            )
        kwargs = {**dict(spec.kwargs), **abl}
        policy = build_policy(spec.name, scenario, **kwargs)  # refuses missing files clearly
        self._check_policy_files(spec.name, scenario, kwargs)
        if spec.label:
            policy.name = spec.label
        if abl:
            policy.name = spec.row + self.ablation.suffix()
        return policy

    def _check_policy_files(self, name: str, scenario: str, kwargs: dict[str, object]) -> None:
        """Refuse a --gif/--png onto a file the policy loads (its checkpoint, reward, …)."""
        from pioneer.control.registry import policy_paths
        from pioneer.io import check_not_input

        files = policy_paths(name, scenario, kwargs)
        for out in (self.gif, self.png):
            if out:
                check_not_input(out, files)

    def _draw(self, scenario: ScenarioConfig, policy: Policy, traj: Trajectory, event: str) -> None:
        from pioneer.progress import progress_bar
        from pioneer.sim.world import scan
        from pioneer.viz import plot_trajectory, render_frame, save_gif

        world, states = traj.world, traj.states
        if self.gif:
            robot = traj.robot
            frames = []
            for k, st in enumerate(progress_bar(states, desc="frames", unit="f")):
                rays = scan(world, st)[0] if self.lidar else None
                frames.append(render_frame(world, st, rays, trail=robot[: k + 1, :2]))
            save_gif(frames, self.gif, fps=1.0 / scenario.sim.dt)
            print(f"wrote {self.gif}")
        if self.png:
            title = f"{scenario.name} · {policy.name} · seed {self.seed} · {event}"
            plot_trajectory(world, states, self.png, title=title)
            print(f"wrote {self.png}")


@dataclasses.dataclass(frozen=True)
class Eval:
    """Evaluate policies: N seeds × M trials per scenario, in parallel, resumable (records in
    OUT/episodes.jsonl); prints one summary line per row and writes OUT/summary.json."""

    out: OutDir
    """output folder (episodes.jsonl, summary.json)"""
    scenario: Annotated[tuple[str, ...], metavar("NAME")] = SCENARIOS
    """scenario names"""
    policy: Annotated[tuple[str, ...], metavar("POLICY")] = ("teacher",)
    """NAME or NAME:key=value,…,label=ROW (e.g. student-mdn:checkpoint=PATH,label=mine)"""
    seeds: int = _PAPER.seeds
    """seeds (each of --trials episodes)"""
    seed_set: SeedSet = default(evaluate, "seed_set")
    """evaluation (reported results) or validation (choices and tuning) episodes"""
    trials: int = _PAPER.trials
    """episodes per seed"""
    workers: Workers = None
    """processes"""
    backend: Literal["process", "ray"] = default(evaluate, "backend")
    """where the episodes run"""
    ray_address: Annotated[str | None, optional("ADDRESS", "start a local Ray")] = None
    """Ray cluster address (HOST:PORT), with --backend ray"""
    overwrite: Flag = False
    """delete the records, manifest and summaries in --out and start over (default: resume,
    if the rows there were made the same way)"""
    metrics: MetricSet = default(metric_tables, "metrics")
    """the tables printed: paper (SR, TT, PL … and collisions by kind), social (efficiency,
    smoothness, social distances, collisions by kind) or all (docs/metrics.md); the summary
    files hold every one"""
    ablation: Ablations = dataclasses.field(default_factory=Ablation)

    def run(self) -> int:
        """Evaluate, then print the chosen tables and the summary of every row."""
        from pioneer.eval.metrics import summarize
        from pioneer.eval.report import write_summary

        require_some("--scenario", self.scenario)
        require_some("--policy", self.policy)
        self._check_backend_flags()
        specs = self._specs()
        recs = evaluate(
            self.scenario,
            specs,
            self.seeds,
            self.trials,
            self.out,
            self.workers,
            backend=self.backend,
            ray_address=self.ray_address,
            seed_set=self.seed_set,
            overwrite=self.overwrite,
        )
        summary = summarize(recs)
        write_summary(self.out, summary)
        print(metric_tables(summary, self.metrics))
        _print_rows(summary)
        return 0

    def _check_backend_flags(self) -> None:
        """A flag of the other backend is refused, not ignored."""
        if self.ray_address is not None and self.backend != "ray":
            raise ConfigError(
                expect("--ray-address", "--backend ray", "--backend process", "add --backend ray")
            )
        if self.workers is not None and self.backend == "ray":
            raise ConfigError(
                expect(
                    "--workers",
                    "--backend process (Ray places the episodes on its cluster's cores)",
                    "--backend ray",
                    "drop --workers",
                )
            )

    def _specs(self) -> list[PolicySpec]:
        """The checked policies, the teacher ablated as asked; every row label distinct."""
        from pioneer.eval.harness import PolicySpec

        abl = self.ablation.kwargs()
        if abl and not any(PolicySpec.parse(text).name == "teacher" for text in self.policy):
            raise ConfigError(
                expect(
                    "--no-density/--no-goal/--no-obstacle",
                    "a 'teacher' among the policies (the flags ablate it)",
                    list(self.policy),
                    "drop the flags, or add --policy teacher",
                )
            )
        specs = []
        for text in self.policy:
            spec = policy_spec(text)
            if abl and spec.name == "teacher":
                kw = {**dict(spec.kwargs), **abl}
                spec = PolicySpec(
                    spec.name, tuple(sorted(kw.items())), spec.row + self.ablation.suffix()
                )
            specs.append(spec)
        rows = [s.row for s in specs]
        twice = sorted({r for r in rows if rows.count(r) > 1})
        if twice:
            raise ConfigError(
                expect(
                    "--policy rows",
                    "distinct labels",
                    twice,
                    "add label=NAME to the repeated policy",
                )
            )
        return specs


def _print_rows(summary: Mapping[str, Mapping[str, Any]]) -> None:
    """One line per row: SR, TT, PL and the episodes. TT and PL are means over successes; a
    row without any says so once: ``TT, PL – (no successes)``; no value prints ``nan``."""
    for key, s in summary.items():
        tt = number(s["time_mean_s"]["mean"], ".2f", "s")
        pl = number(s["path_length_mean_m"]["mean"], ".2f", "m")
        means = "TT, PL – (no successes)" if tt == pl == "–" else f"TT {tt}  PL {pl}"
        sr = number(s["success_rate"]["mean"], ".1f")
        print(f"{key}: SR {sr}%  {means}  ({s['episodes']} episodes)")


@dataclasses.dataclass(frozen=True)
class Summarize:
    """Re-summarise a run folder of pioneer eval from its records alone (runs no episode):
    rewrites RUN_DIR/summary.json, summary.md and summary.csv and prints the tables. Records
    written before the social-navigation measures leave those columns empty (one note);
    --metrics social or all on a run of such records only is refused."""

    run_dir: Annotated[str, tyro.conf.Positional, metavar("RUN_DIR")]
    """the folder holding episodes.jsonl"""
    metrics: MetricSet = default(metric_tables, "metrics")
    """the tables printed: paper, social or all (docs/metrics.md)"""

    def run(self) -> int:
        """Summarise, write, print."""
        from pioneer.eval.report import summarize_run

        summary = summarize_run(self.run_dir, self.metrics)
        print(metric_tables(summary, self.metrics))
        _print_rows(summary)
        return 0


@dataclasses.dataclass(frozen=True)
class Reproduce:
    """The paper's tables and figures (the main job); prints the summary (JSON)."""

    profile: ProfileName = default(reproduce, "profile")
    """smoke: 1 episode per row (a pipeline check); quick: 2 × 10; paper: 5 × 100"""
    out: OutDir = default(reproduce, "out_dir")
    """output folder"""
    workers: Workers = None
    """processes"""
    seed_set: SeedSet = default(reproduce, "seed_set")
    """evaluation (the reported tables) or validation (to check a choice) episodes"""
    overwrite: Flag = False
    """delete the evaluation's records in OUT/eval and start over (default: resume)"""

    def run(self) -> int:
        """Reproduce, then print what was written."""
        with kept(lambda: f"the finished steps kept in {self.out}"):  # the harness names its own
            summary = reproduce(
                self.profile,
                self.out,
                self.workers,
                seed_set=self.seed_set,
                overwrite=self.overwrite,
            )
        print(to_json(summary, indent=2))
        return 0
