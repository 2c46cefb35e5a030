"""The smoke test of an installed ``pioneer-nav-runtime`` wheel (the light robot runtime), run
by the Python of a fresh virtual environment (``tests/smoke/dist.py`` makes it).

``python runtime_check.py --onnx FILE``: a student exported by ``pioneer export`` drives on a
synthetic scan; a dead scan stops the robot; the framework's heavy dependencies are absent.
Prints one line per check and, last, a JSON line ``{"passed": N, "failed": N}``; exit code 1
if any check failed.
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import os
import sys
from collections.abc import Callable
from pathlib import Path

from checks import run_checks  # beside this file

HEAVY = ("torch", "numba", "scipy", "matplotlib", "gymnasium", "tyro", "onnx")


def check_light() -> str:
    import pioneer

    where = Path(pioneer.__file__).resolve()
    assert where.is_relative_to(Path(sys.prefix).resolve()), where
    present = [name for name in HEAVY if importlib.util.find_spec(name) is not None]
    assert not present, f"installed beside the runtime: {present}"
    assert importlib.util.find_spec("pioneer.sim") is None  # the simulator is not shipped
    return f"{pioneer.__version__} from {where.parent}, none of {', '.join(HEAVY)}"


def check_student(onnx: Path) -> str:
    from pioneer.deploy import StudentRuntime

    runtime = StudentRuntime(onnx)
    inc = 2 * math.pi / 360
    ranges = [1.5 + 0.5 * math.cos(2 * i * inc) for i in range(360)]
    drive = runtime.step(ranges, -math.pi, inc, 5.0, (2.0, 0.5), age_s=0.05)
    assert drive.stop_reason is None and 0.0 <= drive.v <= 0.8, drive
    dead = runtime.step([math.inf] * 360, -math.pi, inc, 5.0, (2.0, 0.5), age_s=0.05)
    assert (dead.v, dead.stop_reason) == (0.0, "invalid"), dead
    return f"v {drive.v:.2f} m/s, ω {drive.omega:.2f} rad/s; a dead scan stops it"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--onnx", type=Path, required=True)
    args = parser.parse_args()
    onnx = args.onnx.resolve()
    os.chdir(onnx.parent)  # nothing from the source tree on the path
    checks: list[tuple[str, Callable[[], str]]] = [
        ("installed alone, light", check_light),
        ("student runtime on an exported student", lambda: check_student(onnx)),
    ]
    return run_checks(checks)


if __name__ == "__main__":
    sys.exit(main())
