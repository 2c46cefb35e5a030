"""Helpers shared by the test modules: hand-built states, worlds and reference geometry, and
a CLI run stopped by a signal."""

from __future__ import annotations

import dataclasses
import math
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pioneer.sim.humans import WALKING
from pioneer.sim.world import SimConfig, State, World

__all__ = [
    "Stopped",
    "angle_diff",
    "assert_house_message",
    "concat_states",
    "descendants",
    "file_tree",
    "interrupted_line",
    "make_state",
    "one_error_line",
    "open_world",
    "room_world",
    "sector_minima",
    "states_equal",
    "still_running",
    "stop_cli",
    "wall_distances",
    "wrong_width_onnx",
]


def open_world(sim: SimConfig | None = None, bounds: Sequence[float] = (-50, 50, -50, 50)) -> World:
    """A world with no walls at all."""
    return World(
        walls=np.zeros((0, 4)), bounds=np.asarray(bounds, dtype=float), sim=sim or SimConfig()
    )


def room_world(half_x: float, half_y: float, sim: SimConfig | None = None) -> World:
    """An axis-aligned closed room x ∈ [−half_x, half_x], y ∈ [−half_y, half_y]."""
    w, h = half_x, half_y
    walls = np.array([(-w, -h, w, -h), (w, -h, w, h), (w, h, -w, h), (-w, h, -w, -h)], dtype=float)
    return World(walls=walls, bounds=np.array([-w, w, -h, h]), sim=sim or SimConfig())


def make_state(
    robot: Sequence[float],
    goal: Sequence[float] = (0.0, 0.0),
    humans: Sequence[dict[str, Any]] = (),
) -> State:
    """A single-copy state built by hand.

    Each human is a dict with ``pos`` and optional ``goal`` (default: its position),
    ``waypoints`` (list of points before the goal), ``vel``, ``radius`` (0.6), ``vpref`` (0.6),
    ``status`` (WALKING), ``delay`` (0) and ``wait_for`` (indices).
    """
    n = len(humans)
    wps_list = []
    for h in humans:
        g = h.get("goal", h["pos"])
        wps_list.append([*h.get("waypoints", ()), g])
    w_max = max((len(w) for w in wps_list), default=1)
    wps = np.zeros((1, n, w_max, 2))
    n_wp = np.zeros((1, n), dtype=np.int64)
    for i, pts in enumerate(wps_list):
        wps[0, i, : len(pts)] = pts
        wps[0, i, len(pts) :] = pts[-1]
        n_wp[0, i] = len(pts)
    pos = np.array([h["pos"] for h in humans], dtype=float).reshape(1, n, 2)
    wait = np.zeros((1, n, n), dtype=np.int64)
    for i, h in enumerate(humans):
        for j in h.get("wait_for", ()):
            wait[0, i, j] = 1
    r = np.asarray(robot, dtype=float).reshape(1, 3)
    return State(
        robot=r.copy(),
        command=np.zeros((1, 2)),
        goal=np.asarray(goal, dtype=float).reshape(1, 2),
        start=r[:, :2].copy(),
        t=np.zeros(1),
        path_length=np.zeros(1),
        collided=np.zeros(1, dtype=np.bool_),
        reached=np.zeros(1, dtype=np.bool_),
        gap=np.full(1, np.inf),
        wall_gap=np.full(1, np.inf),
        h_pos=pos,
        h_vel=np.array([h.get("vel", (0.0, 0.0)) for h in humans], dtype=float).reshape(1, n, 2),
        h_radius=np.array([h.get("radius", 0.6) for h in humans], dtype=float).reshape(1, n),
        h_vpref=np.array([h.get("vpref", 0.6) for h in humans], dtype=float).reshape(1, n),
        h_waypoints=wps,
        h_n_waypoints=n_wp,
        h_wp_index=np.zeros((1, n), dtype=np.int64),
        h_status=np.array([h.get("status", WALKING) for h in humans], dtype=np.int8).reshape(1, n),
        h_delay=np.array([h.get("delay", 0.0) for h in humans], dtype=float).reshape(1, n),
        h_wait_for=wait,
        h_home=pos.copy(),
        h_release=np.array(
            [h.get("release", len(w)) for h, w in zip(humans, wps_list, strict=True)],
            dtype=np.int64,
        ).reshape(1, n),
        h_reacts=np.array([h.get("reacts", True) for h in humans], dtype=np.bool_).reshape(1, n),
    )


def concat_states(states: Sequence[State]) -> State:
    """Stack several states (same number of humans and waypoints) along the batch axis."""
    return State(
        **{
            f.name: np.concatenate([getattr(s, f.name) for s in states], axis=0)
            for f in dataclasses.fields(State)
        }
    )


def states_equal(a: State, b: State) -> bool:
    """Exact equality of every array of two states."""
    return all(
        np.array_equal(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(State)
    )


def wall_distances(points: np.ndarray, walls: np.ndarray) -> np.ndarray:
    """Distances ``(..., M)`` from points ``(..., 2)`` to every wall segment ``(M, 4)``."""
    p = np.asarray(points, dtype=float)[..., None, :]
    a = walls[:, :2]
    e = walls[:, 2:] - a
    ll = np.maximum(np.einsum("ij,ij->i", e, e), 1e-300)
    s = np.clip(((p - a) * e).sum(-1) / ll, 0.0, 1.0)
    closest = a + s[..., None] * e
    return np.linalg.norm(p - closest, axis=-1)


def sector_minima(ranges: np.ndarray, group: int = 3) -> np.ndarray:
    """Brute-force sector features ``(..., G / group)`` of beam ranges ``(..., G)`` with the
    centred layout: sector k is the minimum of beams group·k − s … group·k − s + group − 1
    (mod G), s = (group − 1) // 2 (beams 71, 0, 1 for sector 0 of 72 beams in threes)."""
    r = np.asarray(ranges, dtype=float)
    n = r.shape[-1]
    shift = (group - 1) // 2
    out = np.empty((*r.shape[:-1], n // group))
    for k in range(n // group):
        beams = [(group * k - shift + j) % n for j in range(group)]
        out[..., k] = np.min(r[..., beams], axis=-1)
    return out


def assert_house_message(msg: str, *needles: str) -> None:
    """Every user-facing error says what was expected, what was received and how to fix it."""
    for word in ("expected", "received", "fix"):
        assert word in msg, f"{word!r} missing from error message: {msg}"
    for needle in needles:
        assert needle in msg, f"{needle!r} missing from error message: {msg}"


def one_error_line(err: str, code: int, *needles: str) -> str:
    """Exit code 2 and stderr ending in exactly one ``pioneer: error:`` line (progress bars of
    work done before may precede it), no traceback, holding every needle; returns the line."""
    assert code == 2, err[-2000:]
    lines = err.strip().splitlines()
    errors = [line for line in lines if line.startswith("pioneer: error: ")]
    assert len(errors) == 1 and lines[-1] == errors[0] and "Traceback" not in err, err[-2000:]
    for needle in needles:
        assert needle in errors[0], (needle, errors[0])
    return errors[0]


def file_tree(root: Path) -> dict[str, tuple[int, bytes | None]]:
    """Every entry under ``root`` (hidden ones too): its type bits and, for a regular file,
    its bytes — to assert that a refused command left the file system as it found it."""
    import stat

    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in [*dirnames, *filenames]:
            p = Path(dirpath) / name
            mode = p.lstat().st_mode
            out[str(p.relative_to(root))] = (
                stat.S_IFMT(mode),
                p.read_bytes() if stat.S_ISREG(mode) else None,
            )
    return out


def wrong_width_onnx(path: Path, width: int = 28) -> Path:
    """An exported MDN student whose graph takes ``width``-D observations while its export
    metadata claims the 29-D observation (as a hand-edited or foreign file might)."""
    import json

    import onnx

    from pioneer.learn import MDN, StudentConfig, export_onnx

    export_onnx(MDN(StudentConfig(obs_dim=width, hidden=(8, 8), n_components=2), seed=0), path)
    model = onnx.load(str(path))
    for prop in model.metadata_props:
        if prop.key == "config":
            prop.value = json.dumps({**json.loads(prop.value), "obs_dim": 29})
    onnx.save(model, str(path))
    return path


def angle_diff(a: float, b: float) -> float:
    """Smallest absolute difference of two angles [rad]."""
    d = (a - b) % (2 * math.pi)
    return min(d, 2 * math.pi - d)


# ------------------------------------------------------------------- regression references
def keyed_runs(run: Any, names: Sequence[str], seeds: Sequence[int]) -> dict[str, np.ndarray]:
    """``{"name/seed/key": array}`` of ``run(name, seed) -> {key: array}`` over all pairs."""
    return {
        f"{name}/{seed}/{key}": value
        for name in names
        for seed in seeds
        for key, value in run(name, seed).items()
    }


def load_reference(path: Any) -> dict[str, np.ndarray]:
    """A stored regression reference (npz, no pickle); a missing file fails the test."""
    import pytest

    if not path.exists():
        pytest.fail(f"{path} is missing; regenerate it (see the test module's docstring)")
    with np.load(path, allow_pickle=False) as data:
        return {k: data[k] for k in data.files}


def regenerate_reference(path: Any, data: dict[str, np.ndarray], argv: Sequence[str]) -> None:
    """The ``--regenerate`` entry of a regression test module: write ``data`` atomically."""
    import sys

    from pioneer.io import atomic_path

    if list(argv) != ["--regenerate"]:
        sys.exit("usage: python <test module> --regenerate")
    path.parent.mkdir(exist_ok=True)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(fh, **data)
    print(f"wrote {path}")


# ---------------------------------------------------------------------- import hygiene
# The prelude of a child script that must run without torch, numba, scipy, matplotlib or the
# simulator: importing any of them raises ImportError (checked first), and ``heavy()`` lists
# the heavy modules that got loaded anyway. (tests/deploy/test_light_install.py blocks every
# package the light robot install lacks.)
ROBOT_SIDE_PRELUDE = """
import importlib.abc, json, sys

BLOCKED = ("torch", "numba", "llvmlite", "scipy", "matplotlib", "pioneer.sim")

class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if any(name == b or name.startswith(b + ".") for b in BLOCKED):
            raise ImportError(f"{name} is blocked in this test")
        return None

sys.meta_path.insert(0, Block())
for name in BLOCKED:
    try:
        __import__(name)
        raise SystemExit(f"the {name} blocker does not work")
    except ImportError:
        pass

def heavy():
    names = ("torch", "numba", "scipy", "matplotlib", "pioneer.sim", "pioneer.learn",
             "pioneer.control")
    return sorted(m for m in names if m in sys.modules)
"""


# ---------------------------------------------------------------------- signals
@dataclasses.dataclass(frozen=True)
class Stopped:
    """A ``pioneer`` run stopped by a signal: its exit code, the seconds from the signal to
    its exit, its stderr, and the processes it had started that still ran afterwards."""

    returncode: int
    seconds: float
    stderr: str
    left: list[int]

    def assert_clean(self, signum: int) -> None:
        """Exit 128 + ``signum`` within 2 s, and no process left behind."""
        assert self.returncode == 128 + signum
        assert self.seconds < 2.0
        assert self.left == []


def run_cli(*argv: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    """``pioneer ARGV`` in a fresh interpreter (exit code and stderr as a user sees them)."""
    return subprocess.run(
        [sys.executable, "-m", "pioneer.cli", *argv],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def _processes() -> dict[int, tuple[int, str, str]]:
    """pid → (parent pid, state, start time) of every process (Linux ``/proc``)."""
    table = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:  # ended meanwhile
                continue
            table[int(entry.name)] = (int(fields[1]), fields[0], fields[19])
    return table


def descendants(pid: int) -> dict[int, str]:
    """The processes below ``pid``, with their start times (to tell a reused pid)."""
    table = _processes()
    found: dict[int, str] = {}
    parents = [pid]
    while parents:
        parent = parents.pop()
        for child, (ppid, _, start) in table.items():
            if ppid == parent and child not in found:
                found[child] = start
                parents.append(child)
    return found


def still_running(procs: dict[int, str]) -> list[int]:
    """Those of ``procs`` (pid → start time) that still run: a zombie has ended."""
    table = _processes()
    return sorted(
        pid
        for pid, start in procs.items()
        if pid in table and table[pid][2] == start and table[pid][1] != "Z"
    )


def stop_cli(
    argv: Sequence[str],
    started: Callable[[], bool],
    signum: int,
    workdir: Path,
    group: bool,
) -> Stopped:
    """Run ``pioneer ARGV`` in a fresh interpreter and session, wait until ``started()`` (the
    run has done some work), send ``signum`` — to the whole process group like a terminal's
    Ctrl-C when ``group``, else to the command alone like ``kill`` — and wait for the exit.
    Whatever happens, nothing it started is left running after the test."""
    import pytest

    err_path = workdir / f"stderr-{signal.Signals(signum).name}.txt"
    with open(err_path, "w") as err:
        proc = subprocess.Popen(
            [sys.executable, "-m", "pioneer.cli", *argv],
            stdout=subprocess.DEVNULL,
            stderr=err,
            start_new_session=True,
        )
    procs: dict[int, str] = {}
    try:
        deadline = time.monotonic() + 300  # a guard against a hang, not a timing assertion
        while not started():
            if proc.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"the run ended or hung before any work: {err_path.read_text()}")
            time.sleep(0.005)
        procs = descendants(proc.pid)
        t0 = time.monotonic()
        if group:
            os.killpg(proc.pid, signum)
        else:
            proc.send_signal(signum)
        code = proc.wait(timeout=60)
        seconds = time.monotonic() - t0
        deadline = time.monotonic() + 2.0
        while still_running(procs) and time.monotonic() < deadline:
            time.sleep(0.01)
        return Stopped(code, seconds, err_path.read_text(), still_running(procs))
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        for pid in still_running(procs):
            os.kill(pid, signal.SIGKILL)


def interrupted_line(stderr: str) -> str:
    """The line an interrupted run printed last; before it only progress bars, no traceback."""
    lines = [x for x in re.split(r"[\r\n]", stderr) if x.strip()]
    assert lines, "nothing on stderr"
    others = [x for x in lines[:-1] if not re.search(r"\d+%\|", x)]  # tqdm: " 12%|█▎  | 1/8"
    assert others == [], stderr
    assert lines[-1].startswith("pioneer: interrupted ("), stderr
    return lines[-1]


# The two ways a long command is stopped: Ctrl-C (SIGINT to the whole process group, as a
# terminal sends it) and ``kill`` (SIGTERM to the command alone).
STOP_SIGNALS = pytest.mark.parametrize(
    ("signum", "group"),
    [(signal.SIGINT, True), (signal.SIGTERM, False)],
    ids=["SIGINT-to-the-group", "SIGTERM-to-the-command"],
)
