"""The light robot install (``runtime/pyproject.toml``, ``pip install ./runtime``), checked
without a network: it declares numpy and onnxruntime only, with the main project's pins; its
wheel lists the runtime modules of ``src/pioneer`` (no copy), and they import nothing else;
and the runtime runs on a shipped student with every other package blocked.

The installed size is measured by hand in a fresh venv (docs/deployment.md, "The light runtime").
"""

from __future__ import annotations

import ast
import json
import math
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
RUNTIME = tomllib.loads((ROOT / "runtime" / "pyproject.toml").read_text())
MAIN = tomllib.loads((ROOT / "pyproject.toml").read_text())
FORCED: dict[str, str] = RUNTIME["tool"]["hatch"]["build"]["targets"]["wheel"]["force-include"]


def _name(requirement: str) -> str:
    return requirement.split(";")[0].split("[")[0].split(">")[0].split("<")[0].split("=")[0]


def _specs(requirements: list[str]) -> dict[str, str]:
    return {_name(r).strip(): r for r in requirements}


def _module(target: str) -> str:
    """``pioneer/deploy/__init__.py`` → ``pioneer.deploy``."""
    parts = Path(target).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


SHIPPED = {_module(t) for t in FORCED.values() if t.endswith(".py")}


def test_declares_numpy_and_onnxruntime_only_with_the_main_pins():
    deps = _specs(RUNTIME["project"]["dependencies"])
    assert sorted(deps) == ["numpy", "onnxruntime"]
    main = _specs(MAIN["project"]["dependencies"]) | _specs(
        MAIN["project"]["optional-dependencies"]["deploy"]
    )
    assert deps == {k: main[k] for k in deps}  # one pin, the same in both distributions
    ros = _specs(RUNTIME["project"]["optional-dependencies"]["ros"])
    assert ros["rosbags"] == _specs(MAIN["project"]["optional-dependencies"]["ros"])["rosbags"]
    assert ros["tqdm"] == _specs(MAIN["project"]["dependencies"])["tqdm"]
    assert RUNTIME["project"]["requires-python"] == MAIN["project"]["requires-python"]


def test_the_wheel_is_the_source_tree_not_a_copy():
    for source, target in FORCED.items():
        src = (ROOT / "runtime" / source).resolve()
        assert src.is_file() and src.is_relative_to(ROOT / "src" / "pioneer"), source
        assert src.relative_to(ROOT / "src").as_posix() == target
    assert not list((ROOT / "runtime").rglob("*.py"))  # no code of its own
    assert {"pioneer", "pioneer.deploy", "pioneer.deploy.runtime", "pioneer.laser"} <= SHIPPED


def _imports(path: Path) -> tuple[set[str], set[str]]:
    """(modules imported at module level, modules imported inside functions) of a file."""
    top: set[str] = set()
    lazy: set[str] = set()
    tree = ast.parse(path.read_text())
    in_function = {
        id(n)
        for f in ast.walk(tree)
        if isinstance(f, ast.FunctionDef | ast.AsyncFunctionDef)
        for n in ast.walk(f)
    }
    for node in ast.walk(tree):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        (lazy if id(node) in in_function else top).update(names)
    return top, lazy


def test_the_shipped_modules_import_only_each_other_numpy_and_onnxruntime():
    """Every ``pioneer`` module they import is shipped; at module level they import only the
    standard library, numpy and ``pioneer`` (``pioneer.registration`` also Gymnasium, which
    ``pioneer/__init__`` skips where it is absent); inside functions also onnxruntime, the
    [ros] extra (rosbags, tqdm) and annotated-types (only for declared bounds)."""
    allowed_lazy = {"onnxruntime", "rosbags", "tqdm", "annotated_types"}
    for target in FORCED.values():
        if not target.endswith(".py"):
            continue
        top, lazy = _imports(ROOT / "src" / target)
        for name in top | lazy:
            root = name.split(".")[0]
            if root == "pioneer":
                assert name in SHIPPED, f"{target} imports {name}, not in the light wheel"
            elif name in top:
                light = root in sys.stdlib_module_names or root == "numpy"
                assert light or (target, root) == ("pioneer/registration.py", "gymnasium"), name
            else:
                assert root in sys.stdlib_module_names | allowed_lazy, f"{target}: {name}"


LIGHT = """
import importlib.abc, json, math, sys

SHIPPED = set(json.loads(sys.argv[2]))
BLOCKED = ("torch", "numba", "llvmlite", "scipy", "matplotlib", "gymnasium", "annotated_types",
           "tqdm", "tyro", "PIL", "onnx", "safetensors", "rosbags", "osqp", "pygame")

class Light(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        top = name.split(".")[0]
        if top in BLOCKED or (top == "pioneer" and name not in SHIPPED):
            raise ModuleNotFoundError(f"{name} is not in the light install", name=name)
        return None

sys.meta_path.insert(0, Light())
import pioneer.deploy
from pioneer.deploy import StudentRuntime

rt = StudentRuntime(sys.argv[1])
inc = 2 * math.pi / 360
ranges = [1.0 + 0.5 * math.cos(3 * i * inc) for i in range(360)]
drive = rt.step(ranges, -math.pi, inc, 5.0, (2.0, 1.0), age_s=0.05)
rear_blind = rt.step(ranges[45:316], -0.75 * math.pi, inc, 5.0, (2.0, 1.0), age_s=0.05)
dead = rt.step([math.inf] * 360, -math.pi, inc, 5.0, (2.0, 1.0), age_s=0.05)
loaded = sorted(m for m in sys.modules if m.split(".")[0] == "pioneer")
print(json.dumps({"drive": [drive.v, drive.omega, drive.stop_reason],
                  "coverage": rear_blind.coverage_rad, "dead": [dead.v, dead.stop_reason],
                  "loaded": loaded}))
"""


@pytest.fixture(scope="module")
def shipped_onnx(tmp_path_factory) -> Path:
    from pioneer.data import shipped_student
    from pioneer.learn import export_onnx
    from pioneer.learn.models import load_student

    model = load_student(shipped_student("hl-rr-compact"))
    return export_onnx(model, tmp_path_factory.mktemp("light") / "student.onnx")


def test_runtime_runs_with_only_the_light_modules(shipped_onnx):
    proc = subprocess.run(
        [sys.executable, "-c", LIGHT, str(shipped_onnx), json.dumps(sorted(SHIPPED))],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    v, omega, reason = out["drive"]
    assert reason is None and 0.0 <= v <= 0.8 and abs(omega) <= 0.4 * math.pi
    assert out["coverage"] == pytest.approx(math.radians(275))
    assert out["dead"] == [0.0, "invalid"]
    assert set(out["loaded"]) <= SHIPPED
