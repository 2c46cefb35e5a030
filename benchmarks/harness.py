"""The evaluation harness's scaling: the same teacher episodes with 1 and 2 process workers,
and with Ray on a local cluster of two node processes (one CPU each), each through the CLI
as a user runs it (start-up, the reward fit, loading the compiled kernels, the summary).

From the wall times it derives what Amdahl's law needs: the speed-up S(2) = T1 / T2, the
serial fraction f = 2 / S(2) − 1 of this run (S(N) = 1 / (f + (1 − f) / N)), the fixed
start-up (a one-episode run) and the parallel efficiency of the episodes alone, and from
those the serial fraction of a run as long as the paper profile (docs/performance.md,
"Scaling with workers")."""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import REPO, SCENARIO, Case, Plan, Result, metric, time_cases

TRIALS = 60  # teacher episodes per timed run (evaluation seed 0)
# CPU-seconds of the paper profile's episodes on the reference machine (docs/performance.md,
# "The paper profile end to end"): the length of run the serial fraction is projected to
PAPER_EPISODE_CPU_S = 2900.0


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
            runs = iter(range(10**6))

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
    # the episodes alone: one worker's episode time over two workers' (ideal 2)
    efficiency = (t1 - t0) / (2.0 * (t2 - t0))
    # the paper profile: the same fixed start-up, its episodes' CPU time in parallel
    serial_paper = t0 / (t0 + PAPER_EPISODE_CPU_S)

    def amdahl(f: float, n: int) -> float:
        return 1.0 / (f + (1.0 - f) / n)

    f_paper = float(np.median(serial_paper))
    return {
        "metrics": {
            "episodes_per_s_1_worker": metric(TRIALS / t1, "episodes/s"),
            "episodes_per_s_2_workers": metric(TRIALS / t2, "episodes/s"),
            "episodes_per_s_ray_cluster_2": metric(TRIALS / tr, "episodes/s"),
            "s_startup": metric(t0, "s"),
            "speedup_2_workers": metric(speedup_2, "x"),
            "speedup_ray_cluster_2": metric(speedup_ray, "x"),
            "amdahl_serial_fraction_this_run": metric(serial_2, "share"),
            "episode_efficiency_2_workers": metric(efficiency, "share"),
            "amdahl_serial_fraction_paper_profile": metric(serial_paper, "share"),
        },
        "info": {
            "trials": TRIALS,
            "policy": "teacher",
            "ray_cluster": "2 node processes × 1 CPU (ray.cluster_utils.Cluster)",
            "paper_episode_cpu_s": PAPER_EPISODE_CPU_S,
            # the projection these figures give (an extrapolation, said so in the docs)
            "paper_profile_speedup_projected": {
                str(n): round(amdahl(f_paper, n), 2) for n in (2, 4, 8, 16, 32)
            },
        },
    }
