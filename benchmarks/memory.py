"""Peak RSS of fresh processes: ``import pioneer`` and 1,000 env steps (``memory``), and the
torch-free deploy runtime on 1,000 scans (``deploy_memory``)."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import ENV_ID, REPO, SEED, Plan, Result, metric

MEMORY_CHILD = """
import json, resource, sys
rss_start = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
import numpy as np
import gymnasium as gym
import pioneer
rss_import = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
env = gym.make({env_id!r})
rng = np.random.default_rng({seed})
actions = rng.uniform(env.action_space.low, env.action_space.high, size=({n}, 2))
env.reset(seed={seed})
for a in actions.astype(np.float32):
    _, _, terminated, truncated, _ = env.step(a)
    if terminated or truncated:
        env.reset()
env.close()
rss_peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
hwm = None
try:
    with open("/proc/self/status") as f:
        hwm = next(int(ln.split()[1]) for ln in f if ln.startswith("VmHWM:"))
except (OSError, StopIteration):
    pass
heavy = sorted(m for m in ("torch", "matplotlib") if m in sys.modules)
print(json.dumps({{"rss_start_kb": rss_start, "rss_import_kb": rss_import, "rss_peak_kb": rss_peak,
                  "vm_hwm_kb": hwm, "heavy": heavy, "n_modules": len(sys.modules)}}))
assert not heavy, f"heavy modules imported: {{heavy}}"
"""

DEPLOY_CHILD = """
import json, resource, sys, tempfile, math
sys.modules["torch"] = None  # the robot runtime must not need torch
import numpy as np
from pioneer.deploy import StudentRuntime
rt = StudentRuntime({onnx!r})
rng = np.random.default_rng({seed})
for _ in range({n}):
    ranges = rng.uniform(0.4, 6.0, size=360)
    rt.step(ranges, -math.pi, 2 * math.pi / 360, 10.0, np.array([2.0, 0.5]), age_s=0.05)
print(json.dumps({{"rss_peak_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
                  "torch": "torch" in sys.modules and sys.modules["torch"] is not None,
                  "numba": "numba" in sys.modules}}))
"""

# Linux carries the RSS high-water mark of the address space a process replaces across
# execve into ru_maxrss, so a child spawned straight from this (large) benchmark process would
# report at least our own RSS. A bare ``python -S`` launcher (≈ 10 MB) spawns the real child.
MEMORY_LAUNCHER = (
    "import subprocess, sys; "
    "sys.exit(subprocess.run([sys.executable, '-c', sys.argv[1]]).returncode)"
)

# ru_maxrss is in KiB on Linux (bytes on macOS).
MAXRSS_TO_MB = 1.0 / (1024 * 1024) if sys.platform == "darwin" else 1.0 / 1024


def run_child(code: str, what: str) -> dict[str, Any]:
    """Run ``code`` in a fresh interpreter (through the launcher) and return the JSON record
    it prints last."""
    proc = subprocess.run(
        [sys.executable, "-S", "-c", MEMORY_LAUNCHER, code],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=False,
    )
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if not lines:
        raise RuntimeError(f"{what} child failed ({proc.returncode}): {proc.stderr[-2000:]}")
    record: dict[str, Any] = json.loads(lines[-1])
    return record


def bench_memory(plan: Plan) -> Result:
    """Peak RSS (ru_maxrss) of a fresh interpreter that imports pioneer and runs 1,000 steps."""
    n_steps = 1000
    code = MEMORY_CHILD.format(env_id=ENV_ID, seed=SEED + 7, n=n_steps)
    run_child(code, "memory")  # this run only fills the numba cache
    recs = [run_child(code, "memory") for _ in range(plan.memory_repeats)]
    hwms = [r["vm_hwm_kb"] / 1024 for r in recs if r["vm_hwm_kb"] is not None]
    heavy = sorted({m for r in recs for m in r["heavy"]})
    peak = metric([r["rss_peak_kb"] * MAXRSS_TO_MB for r in recs], "MB", ("<", 300.0))
    if heavy:
        peak["passed"] = False
    return {
        "metrics": {
            "peak_rss_mb": peak,
            "rss_after_import_mb": metric([r["rss_import_kb"] * MAXRSS_TO_MB for r in recs], "MB"),
            **({"vm_hwm_mb": metric(hwms, "MB")} if hwms else {}),
        },
        "info": {
            "env_steps": n_steps,
            "ru_maxrss_at_child_start_mb": float(
                np.median([r["rss_start_kb"] * MAXRSS_TO_MB for r in recs])
            ),
            "torch_imported": "torch" in heavy,
            "matplotlib_imported": "matplotlib" in heavy,
            "modules_loaded": int(np.median([r["n_modules"] for r in recs])),
        },
    }


def bench_deploy_memory(plan: Plan) -> Result:
    """Peak RSS of a fresh process running the torch-free deploy runtime for 1,000 scans."""
    from pioneer.learn import build_student, export_onnx

    with tempfile.TemporaryDirectory(prefix="pioneer-bench-deploy-") as tmp:
        path = export_onnx(build_student(seed=SEED + 60), Path(tmp) / "student.onnx")
        code = DEPLOY_CHILD.format(onnx=str(path), seed=SEED + 61, n=1000)
        run_child(code, "deploy")  # this run only warms the file cache
        recs = [run_child(code, "deploy") for _ in range(plan.memory_repeats)]
    return {
        "metrics": {
            "peak_rss_mb": metric(
                [r["rss_peak_kb"] * MAXRSS_TO_MB for r in recs], "MB", ("<", 200.0)
            )
        },
        "info": {
            "scans": 1000,
            "torch_imported": recs[-1]["torch"],  # as reported by the last child process
            "numba_imported": recs[-1]["numba"],
            "runtime": "onnxruntime, 1 thread",
        },
    }
