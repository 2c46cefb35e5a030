"""The evaluation harness's scaling: the same teacher episodes with 1 and 2 process workers,
and with Ray on a local cluster of two node processes (one CPU each), each through the CLI
as a user runs it (start-up, the reward fit, loading the compiled kernels, the summary).

From the wall times it derives what Amdahl's law needs: the speed-up S(2) = T1 / T2, the
serial fraction f = 2 / S(2) − 1 of this run (S(N) = 1 / (f + (1 − f) / N)), the fixed
start-up (a one-episode run) and the parallel efficiency of the episodes alone, and from
those the serial fraction of a run as long as the paper profile (docs/performance.md,
"Scaling with workers")."""

from __future__ import annotations

import itertools
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import REPO, SCENARIO, Case, Plan, Result, metric, time_cases
from pioneer.experiments.timing import episode_times

TRIALS = 60  # teacher episodes per timed run (evaluation seed 0)
# The paper profile's episodes on 2 workers: user CPU-seconds of its fourth run on the
# reference machine (docs/performance.md, "Current figures": 2,914 CPU-s): the length of run
# the serial fraction is projected to; its fixed work (start-up and report) is the
# ``overhead_s`` of the shipped episode times (pioneer.experiments.timing.episode_times).
PAPER_EPISODE_CPU_S = 2900.0
PROJECTED_WORKERS = (2, 4, 8, 16, 32)


def _eval(out: Path, trials: int, extra: list[str]) -> None:
    """``pioneer eval`` of the teacher on ``trials`` HR-RL episodes into a fresh folder."""
    cmd = [sys.executable, "-m", "pioneer.cli", "eval", "--scenario", SCENARIO]
    cmd += ["--policy", "teacher", "--seeds", "1", "--trials", str(trials)]
    proc = subprocess.run(
        [*cmd, *extra, "--out", str(out)], cwd=REPO, capture_output=True, text=True, check=False
    )
    if proc.returncode != 0:
        raise RuntimeError(f"pioneer eval failed: {proc.stderr[-2000:]}")


def _ray_cluster() -> Any:
    """A local Ray cluster of two node processes with one CPU each (Ray's own test cluster:
    a head and one more raylet on this host, joined by address as a remote node would be)."""
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    return cluster


def bench_harness_scaling(plan: Plan) -> Result:
    """Wall time of ``pioneer eval`` (teacher, 60 HR-RL episodes) with 1 and 2 process
    workers and on a 2-node local Ray cluster, round-robin; a one-episode run for the fixed
    start-up. Opt-in (``--only harness_scaling``): it takes minutes."""
    cluster = _ray_cluster()
    try:
        with tempfile.TemporaryDirectory(prefix="pioneer-bench-scaling-") as tmp:
            runs = itertools.count()

            def case(trials: int, extra: list[str]) -> Case:
                return Case(lambda _: _eval(Path(tmp) / f"run-{next(runs)}", trials, extra))

            ray_args = ["--backend", "ray", "--ray-address", cluster.address]
            cases = {
                "startup": case(1, ["--workers", "1"]),
                "process_1": case(TRIALS, ["--workers", "1"]),
                "process_2": case(TRIALS, ["--workers", "2"]),
                "ray_cluster_2": case(TRIALS, ray_args),
            }
            secs = time_cases(cases, plan.scaling_repeats, warmup=0)
    finally:
        cluster.shutdown()
    t0, t1, t2, tr = (secs[k] for k in ("startup", "process_1", "process_2", "ray_cluster_2"))
    speedup_2, speedup_ray = t1 / t2, t1 / tr
    serial_2 = 2.0 / speedup_2 - 1.0  # Amdahl: S(2) = 1 / (f + (1 − f) / 2)
    # the episodes alone: one worker's time for them over two workers' (1 = perfect): what two
    # episodes at once on the two cores cost each other, which Amdahl's serial part leaves out
    efficiency = (t1 - t0) / (2.0 * (t2 - t0))
    fixed = episode_times().overhead_s
    f_paper = fixed / (fixed + PAPER_EPISODE_CPU_S)
    e2 = float(np.median(efficiency))

    def projected(n: int) -> float:
        """Amdahl with the paper profile's fixed work, each worker at the 2-worker efficiency
        (an assumption for n > 2: measured only at 2)."""
        return 1.0 / (f_paper + (1.0 - f_paper) / (n * e2))

    return {
        "metrics": {
            "episodes_per_s_1_worker": metric(TRIALS / t1, "episodes/s"),
            "episodes_per_s_2_workers": metric(TRIALS / t2, "episodes/s"),
            "episodes_per_s_ray_cluster_2": metric(TRIALS / tr, "episodes/s"),
            "s_startup": metric(t0, "s"),
            "speedup_2_workers": metric(speedup_2, "x"),
            "speedup_ray_cluster_2": metric(speedup_ray, "x"),
            "amdahl_serial_fraction_this_run": metric(serial_2, "share"),
            "startup_share_this_run": metric(t0 / t1, "share"),
            "episode_efficiency_2_workers": metric(efficiency, "share"),
        },
        "info": {
            "trials": TRIALS,
            "policy": "teacher",
            "ray_cluster": "2 node processes × 1 CPU (ray.cluster_utils.Cluster)",
            "paper_profile": {
                "episode_cpu_s": PAPER_EPISODE_CPU_S,
                "fixed_s": fixed,
                "amdahl_serial_fraction": round(f_paper, 4),
                "speedup_projected": {str(n): round(projected(n), 2) for n in PROJECTED_WORKERS},
            },
        },
    }
