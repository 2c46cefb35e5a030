"""The smoke test of an installed ``pioneer-nav`` wheel, run by the Python of a fresh virtual
environment (``tests/smoke/dist.py`` makes it): the commands a new user types first.

``python check.py --tmp DIR [--learn] [--onnx FILE]``: prints one line per check and, last, a
JSON line ``{"passed": N, "failed": N}``; exit code 1 if any check failed. ``--learn``: the
``learn`` extra is installed, so also a student from the shipped weights and its ONNX export
(written to ``--onnx``, for the light runtime's smoke test). Standard library only, besides
the package itself, and nothing from the source tree: the package must come from the venv.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

from checks import run_checks  # beside this file

BIN = Path(sys.executable).parent
PIONEER = str(BIN / "pioneer")


def _pioneer(*args: str, timeout: float = 900) -> str:
    """Run the installed console script; its stdout (raises with its stderr on failure)."""
    proc = subprocess.run(
        [PIONEER, *args], capture_output=True, text=True, timeout=timeout, check=False
    )
    if proc.returncode != 0:
        raise AssertionError(f"pioneer {' '.join(args)}: exit {proc.returncode}\n{proc.stderr}")
    return proc.stdout


def check_installed_not_from_source() -> str:
    import pioneer

    where = Path(pioneer.__file__).resolve()
    assert where.is_relative_to(Path(sys.prefix).resolve()), where  # site-packages, no src/
    return str(where.parent)


def check_version() -> str:
    from importlib.metadata import version

    out = _pioneer("--version").strip()
    assert out == f"pioneer {version('pioneer-nav')}", out
    return out


def check_shipped_data() -> str:
    from pioneer.data import STUDENTS_DIR

    data = STUDENTS_DIR.parent
    kinds = {p.parent.name for p in data.rglob("*") if p.is_file() and p.suffix != ".py"}
    assert {"demos", "students", "baselines", "data"} <= kinds, kinds
    return f"{sum(1 for p in data.rglob('*') if p.is_file())} files in {data}"


def check_run_teacher() -> str:
    t0 = time.perf_counter()
    record = json.loads(
        _pioneer("run", "--scenario", "hr-rl", "--policy", "teacher", "--seed", "0")
    )
    first = time.perf_counter() - t0
    assert record["event"] in {"success", "collision", "timeout"}, record
    t0 = time.perf_counter()
    again = json.loads(_pioneer("run", "--scenario", "hr-rl", "--policy", "teacher", "--seed", "0"))
    second = time.perf_counter() - t0
    assert again == record, (again, record)  # the same episode, from numba's cache or not
    return f"event {record['event']}; {first:.1f} s, again {second:.1f} s"


def check_eval(tmp: Path) -> str:
    out = tmp / "eval"
    _pioneer(
        "eval", "--scenario", "hr-rl", "--policy", "teacher", "goal",
        "--seeds", "1", "--trials", "2", "--out", str(out),
    )  # fmt: skip
    records = (out / "episodes.jsonl").read_text().splitlines()
    summary = json.loads((out / "summary.json").read_text())
    assert len(records) == 4 and sorted(summary) == ["hr-rl/goal", "hr-rl/teacher"], summary
    rate = summary["hr-rl/teacher"]["success_rate"]["mean"]
    return f"{len(records)} episodes in {out}, teacher SR {rate}%"


def check_gymnasium_env() -> str:
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env

    import pioneer  # noqa: F401  (registers the environments)

    env = gym.make("pioneer/ElevatorHRRL-v1")
    check_env(env.unwrapped, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    obs, _, _, _, info = env.step(env.action_space.sample())
    env.close()
    return f"obs {obs.shape} {obs.dtype}, event {info['event']}"


def check_numba_cache() -> str:
    """Where numba's cache went (information: a read-only site-packages falls back to the
    user's cache folder)."""
    import pioneer

    root = Path(pioneer.__file__).parent
    beside = len(list(root.rglob("*.nbi")))
    return f"{beside} index files beside the package" + (
        "" if beside else f" (NUMBA_CACHE_DIR={os.environ.get('NUMBA_CACHE_DIR')})"
    )


def check_student() -> str:
    record = json.loads(
        _pioneer("run", "--scenario", "hr-rl", "--policy", "student-mdn", "--seed", "0")
    )
    assert record["event"] in {"success", "collision", "timeout"}, record
    import torch

    return f"event {record['event']} (torch {torch.__version__})"


def check_export(onnx: Path) -> str:
    from pioneer.data import shipped_student

    summary = json.loads(
        _pioneer("export", "--model", str(shipped_student("hr-rl")), "--out", str(onnx))
    )
    assert onnx.is_file(), summary
    return f"{onnx.stat().st_size} bytes"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tmp", type=Path, required=True)
    parser.add_argument("--learn", action="store_true")
    parser.add_argument("--onnx", type=Path)
    args = parser.parse_args()
    args.tmp.mkdir(parents=True, exist_ok=True)
    os.chdir(args.tmp)  # nothing from the source tree on the path
    checks: list[tuple[str, Callable[[], str]]] = [
        ("installed, not the source tree", check_installed_not_from_source),
        ("pioneer --version", check_version),
        ("shipped data files", check_shipped_data),
        ("pioneer run --policy teacher", check_run_teacher),
        ("pioneer eval", lambda: check_eval(args.tmp)),
        ("gymnasium.make + check_env", check_gymnasium_env),
        ("numba cache", check_numba_cache),
    ]
    if args.learn:
        checks.append(("student from the shipped weights", check_student))
        if args.onnx:
            checks.append(("pioneer export (ONNX)", lambda: check_export(args.onnx)))
    return run_checks(checks)


if __name__ == "__main__":
    sys.exit(main())
