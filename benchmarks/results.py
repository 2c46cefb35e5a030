"""What a results file records besides the numbers (the machine, a fingerprint of the source),
the printed table, and the JSON file itself (``benchmarks/results/latest.json``, written
atomically, earlier entries of benchmarks not run this time kept)."""

from __future__ import annotations

import contextlib
import datetime
import hashlib
import importlib.metadata
import json
import math
import os
import platform
from pathlib import Path
from typing import Any

import gymnasium as gym
import numba
import numpy as np

import pioneer
from benchmarks.common import REPO, Result, best
from pioneer.io import write_text_atomic

SCHEMA = 1


def now() -> str:
    """The current UTC time, ISO 8601 to the second."""
    return datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")


def _version(dist: str) -> str | None:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return None


def machine_info() -> dict[str, Any]:
    """What the numbers were measured on."""
    cpu_model = None
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu_model = line.split(":", 1)[1].strip()
                break
    affinity = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    # What numba compiles for: the SIMD width decides how fast the vectorised kernels run
    # (cast_rays, the density reward's exp), so results from different hosts differ.
    import llvmlite.binding as llvm

    features = llvm.get_host_cpu_features()
    simd = [f for f in ("sse4.2", "avx", "avx2", "fma", "avx512f") if features.get(f, False)]
    return {
        "cpu_count": os.cpu_count(),
        "cpu_affinity": affinity,
        "cpu_model": cpu_model,
        "llvm_host_cpu": llvm.get_host_cpu_name(),
        "simd": simd,
        "platform": platform.platform(),
        "machine": platform.machine(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        "gymnasium": gym.__version__,
        "pioneer": pioneer.__version__,
        "pysocialforce": _version("pysocialforce"),
        "numba_threading_layer_env": os.environ.get("NUMBA_THREADING_LAYER"),
    }


def source_fingerprint() -> dict[str, Any]:
    """SHA-256 over the sources (path + content): all of ``src/pioneer`` and ``sim`` alone."""
    src = REPO / "src" / "pioneer"
    out: dict[str, Any] = {}
    for label, root in (("package", src), ("sim", src / "sim")):
        digest = hashlib.sha256()
        newest = 0.0
        files = sorted(root.rglob("*.py"))
        for f in files:
            digest.update(str(f.relative_to(src)).encode())
            digest.update(f.read_bytes())
            newest = max(newest, f.stat().st_mtime)
        out[label] = {
            "sha256": digest.hexdigest(),
            "files": len(files),
            "newest_mtime": datetime.datetime.fromtimestamp(newest, datetime.UTC).isoformat(
                timespec="seconds"
            ),
        }
    return out


# --------------------------------------------------------------------------------------------
# The table


def _fmt(v: float) -> str:
    if v == 0 or not math.isfinite(v):
        return f"{v:g}"
    if abs(v) >= 1000:
        return f"{v:,.0f}"
    if abs(v) >= 10:
        return f"{v:.1f}"
    return f"{v:.3g}"


NOT_RUN = ("error", "unavailable", "skipped")  # info["status"] of a benchmark with no numbers


def print_table(results: dict[str, Result]) -> None:
    """Medians, IQRs, best repeats and pass/fail (on the median) of every metric."""
    rows = [("benchmark", "metric", "median", "IQR", "best", "unit", "target", "status")]
    notes: list[str] = []
    for name, res in results.items():
        for mname, m in res["metrics"].items():
            status = "" if "passed" not in m else ("PASS" if m["passed"] else "FAIL")
            rows.append(
                (
                    name,
                    mname,
                    _fmt(m["median"]),
                    _fmt(m["iqr"]),
                    _fmt(best(m)),
                    m["unit"],
                    m.get("target", ""),
                    status,
                )
            )
        info = res.get("info", {})
        if info.get("status") in NOT_RUN:
            rows.append((name, info["status"].upper(), "-", "", "", "", "", "see below"))
            notes.append(f"{name}: {info['status']}: {info.get('reason', '')}")
    widths = [max(len(str(r[i])) for r in rows) for i in range(len(rows[0]))]
    for i, row in enumerate(rows):
        print("  ".join(str(c).ljust(w) for c, w in zip(row, widths, strict=True)).rstrip())
        if i == 0:
            print("  ".join("-" * w for w in widths))
    for note in notes:
        print(note)


# --------------------------------------------------------------------------------------------
# The JSON file


def load_previous(path: Path) -> dict[str, Any]:
    """The results file as it was before this run (``{}`` if missing or unreadable)."""
    with contextlib.suppress(OSError, ValueError):
        if path.exists():
            data = json.loads(path.read_text())
            if isinstance(data, dict):
                return data
    return {}


def merged_benchmarks(
    previous: dict[str, Any], results: dict[str, Result], order: list[str]
) -> dict[str, Result]:
    """This run's results over the earlier entries of benchmarks not run this time (each
    carries its own timestamp), in ``order``."""
    merged: dict[str, Any] = {}
    if previous.get("schema") == SCHEMA:
        merged.update(previous.get("benchmarks", {}))
    merged.update(results)
    return {name: merged[name] for name in order if name in merged}


def write_json_atomic(path: Path, payload: dict[str, Any]) -> None:
    """Write ``payload`` as indented JSON through :func:`pioneer.io.write_text_atomic` (a temp
    file beside ``path``, then a rename: a crash never leaves half a file)."""
    write_text_atomic(path, json.dumps(payload, indent=2, sort_keys=False) + "\n")
