"""PioneeR performance benchmarks (``make bench`` → ``.venv/bin/python benchmarks/run.py``).

Every benchmark is warmed up first (numba compilation and cache loading are excluded), then
timed with :func:`time.perf_counter` over repeated runs. The table shows medians and
interquartile ranges; ``benchmarks/results/latest.json`` gets the same numbers plus the
machine description and a timestamp (written atomically: temp file + ``os.replace``).

    .venv/bin/python benchmarks/run.py                 # everything (≈ 1–2 minutes)
    .venv/bin/python benchmarks/run.py --quick         # fewer repeats
    .venv/bin/python benchmarks/run.py --only env_step # one benchmark (others kept in the JSON)

By default the script re-runs itself with ``NUMBA_CACHE_DIR`` set to an empty temporary
directory, so the kernels are compiled from the current source (numba's cache does not notice
edits to functions in other files); ``--reuse-numba-cache`` skips that.

This file is the entry point only; the benchmarks live in the ``benchmarks`` package by area
(``common``, ``results``, ``sim``, ``psf``, ``vector``, ``control``, ``learn``, ``memory``).

Benchmarks and targets (docs/performance.md explains them):

- ``env_step``            Gymnasium env steps/s, raw and ``gym.make``-wrapped   >= 5,000 /s
- ``pysocialforce_step``  the same scene in the ``pysocialforce`` package, and ours/theirs
- ``raycast_batch``       ``cast_rays`` for 1,200 poses x 72 beams              <= 2 ms
                          (and in float32 beside it: the speed-up)
- ``world_step_batch``    ``step`` on 120 copies x 10 steps of 0.3 s            <= 3 ms
- ``teacher_decision``    one lookahead-teacher decision (120 x 10 rollouts)   <= 10 ms
                          and its ratio to the host probe's GEMM (256³ float32) <= 12
                          (float64 rays; float32 rays beside them: speed-ups)
- ``teacher_equivalence`` float32 vs float64 rays over ≈ 2,300 teacher states: the
                          same candidate in >= 99 %, score loss elsewhere < 0.05
- ``student_decision``    student scan → command via ONNX Runtime              <= 0.2 ms
                          obs → command via NumPy (the default) and PyTorch    <= 1 ms
                          and the teacher/student decision-time ratio
- ``deploy_memory``       peak RSS of the torch-free deploy runtime, 1,000 scans < 200 MB
- ``memory``              peak RSS of a fresh process doing 1,000 env steps     < 300 MB
- ``dagger_run``          a full DAgger run (550 episodes), opt-in via --only   <= 5 min
- ``harness_scaling``     ``pioneer eval`` with 1 / 2 workers and a 2-node Ray cluster:
                          speed-ups and the Amdahl serial fraction, opt-in via --only
- ``cvar_bf_decision``    CVaR-BF over 4 seeded HR-RL episodes                <= 4 ms, p90 <= 8 ms
                          and its ratio to the host probe's GEMM (256³ float32) <= 19
- ``crowdnav_decision``   CrowdNav++ policy.act, shipped weights (NumPy; torch  <= 1 ms
                          beside it, 1 thread)
- ``crowdnav_train_throughput``  PPO trainer env steps/s, 16 and 32 envs       >= 2,000 /s (32)
                          64 envs, also without the intrusion term          >= 10,000 /s (64)
                          (``--reward no-intrusion``: crowdnav++-il-teacher)
- ``finetune_throughput`` students' PPO fine-tuning env steps/s, 64 copies  >= 20,000 /s (2 threads)
- ``vector_env``          64 envs: native vector env vs ``SyncVectorEnv``      native >= 5x sync
"""

from __future__ import annotations

import argparse
import logging
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

# Run as a script, sys.path[0] is this file's folder: replace it with the repository, so the
# benchmarks import as one package (``benchmarks.sim``, not a top-level ``sim``).
if sys.path and Path(sys.path[0] or ".").resolve() == Path(__file__).resolve().parent:
    sys.path.pop(0)
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks import control, harness, learn, memory, psf, sim, vector
from benchmarks.common import (
    DEFAULT_OUTPUT,
    FULL,
    QUICK,
    Plan,
    Result,
    host_probe,
    log,
    missed_targets,
    mode,
    probe_line,
)
from benchmarks.results import (
    SCHEMA,
    load_previous,
    machine_info,
    merged_benchmarks,
    now,
    print_table,
    source_fingerprint,
    write_json_atomic,
)

# In the order they run and appear in the JSON.
BENCHMARKS: dict[str, Callable[[Plan], Result]] = {
    "env_step": sim.bench_env_step,
    "pysocialforce_step": psf.bench_pysocialforce_step,
    "raycast_batch": sim.bench_raycast_batch,
    "world_step_batch": sim.bench_world_step_batch,
    "density_fit": control.bench_density_fit,
    "density_eval": control.bench_density_eval,
    "teacher_decision": control.bench_teacher_decision,
    "teacher_equivalence": control.bench_teacher_equivalence,
    "cvar_bf_decision": control.bench_cvar_bf_decision,
    "student_decision": learn.bench_student_decision,
    "deploy_memory": memory.bench_deploy_memory,
    "memory": memory.bench_memory,
    "dagger_run": learn.bench_dagger_run,
    "harness_scaling": harness.bench_harness_scaling,
    "crowdnav_decision": learn.bench_crowdnav_decision,
    "crowdnav_train_throughput": learn.bench_crowdnav_train_throughput,
    "finetune_throughput": learn.bench_finetune_throughput,
    "vector_env": vector.bench_vector_env,
}
OPT_IN = ("dagger_run", "harness_scaling")  # run only when named with --only (minutes long)
FRESH_CACHE_ENV = "PIONEER_BENCH_FRESH_NUMBA_CACHE"


def run_benchmarks(names: list[str], plan: Plan) -> dict[str, Result]:
    """Run the selected benchmarks in a fixed order; failures are recorded, not raised."""
    results: dict[str, Result] = {}
    for name, bench in BENCHMARKS.items():
        if name not in names:
            continue
        print(f"[bench] {name} …", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        try:
            res = bench(plan)
        except Exception as exc:
            log.exception("benchmark %s failed", name)
            res = {"metrics": {}, "info": {"status": "error", "reason": repr(exc)}}
        res["timestamp"] = now()
        res["mode"] = mode(plan)
        res["wall_time_s"] = round(time.perf_counter() - t0, 2)
        res["repeats"] = {m: v["n"] for m, v in res["metrics"].items()}
        res["load_average"] = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
        results[name] = res
    return results


def _rerun_with_fresh_numba_cache(argv: list[str]) -> int:
    """Run this script again with ``NUMBA_CACHE_DIR`` pointing at an empty temp directory.

    numba's on-disk cache is keyed on the source file of the jitted function only: after an
    edit to ``humans.py`` or ``geometry.py`` the cached ``kernel.step_kernel`` (which inlines
    them) is still loaded, so a benchmark would silently time the old code. Compiling afresh
    costs a few seconds (excluded from every timing by the warm-up runs).
    """
    with tempfile.TemporaryDirectory(prefix="pioneer-bench-numba-") as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache, FRESH_CACHE_ENV: "1"}
        cmd = [sys.executable, str(Path(__file__).resolve()), *argv]
        return subprocess.run(cmd, env=env, check=False).returncode


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """The command line (docs/performance.md)."""
    names = list(BENCHMARKS)
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats (smoke run)")
    parser.add_argument(
        "--only",
        action="append",
        choices=names,
        metavar="NAME",
        help=f"run only this benchmark (repeatable): {', '.join(names)}",
    )
    parser.add_argument(
        "--output", type=Path, default=DEFAULT_OUTPUT, help="results JSON (default: %(default)s)"
    )
    parser.add_argument(
        "--strict", action="store_true", help="exit with status 1 if any target is missed"
    )
    parser.add_argument(
        "--reuse-numba-cache",
        action="store_true",
        help="use the kernels cached in src/**/__pycache__ instead of compiling afresh",
    )
    return parser.parse_args(argv)


def measure(names: list[str], plan: Plan, output: Path) -> tuple[dict[str, Result], dict[str, Any]]:
    """Run ``names`` between two host probes and print the table; returns the results and the
    JSON payload (earlier entries of ``output`` kept for benchmarks not run this time)."""
    previous = load_previous(output)
    source_before = source_fingerprint()
    probe_before = host_probe()
    t0 = time.perf_counter()
    results = run_benchmarks(names, plan)
    elapsed = time.perf_counter() - t0
    probe_after = host_probe()
    source = source_fingerprint()
    sim_changed = source["sim"]["sha256"] != source_before["sim"]["sha256"]
    if sim_changed:
        log.warning("src/pioneer/sim changed while the benchmarks ran: numbers may be mixed")

    print()
    print_table(results)
    print(f"\n{len(results)} benchmark(s) in {elapsed:.1f} s ({mode(plan)})")
    print(probe_line("before", probe_before))
    print(probe_line("after ", probe_after))
    return results, {
        "schema": SCHEMA,
        "timestamp": now(),
        "mode": mode(plan),
        "ran": names,
        "elapsed_s": round(elapsed, 2),
        "machine": machine_info(),
        "host_probe": {"before": probe_before, "after": probe_after},
        "source": source,
        "sim_source_changed_during_run": sim_changed,
        "numba_cache": "fresh" if os.environ.get(FRESH_CACHE_ENV) else "reused",
        "benchmarks": merged_benchmarks(previous, results, list(BENCHMARKS)),
    }


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if not args.reuse_numba_cache and FRESH_CACHE_ENV not in os.environ:
        return _rerun_with_fresh_numba_cache(sys.argv[1:] if argv is None else argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    names = list(args.only) if args.only else [b for b in BENCHMARKS if b not in OPT_IN]
    plan = QUICK if args.quick else FULL
    from threadpoolctl import threadpool_limits

    threadpool_limits(1, user_api="blas")  # as the CLI and the evaluation workers run

    results, payload = measure(names, plan, args.output)
    write_json_atomic(args.output, payload)
    print(f"results → {args.output}")
    missed = missed_targets(results)
    if missed:
        print("targets missed: " + ", ".join(missed))
    return 1 if (args.strict and missed) else 0


if __name__ == "__main__":
    sys.exit(main())
