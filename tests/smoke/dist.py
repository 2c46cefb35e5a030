"""Build the distributions a user installs and smoke-test them from fresh virtual environments
(``make smoke``, run by CI after ``make test``).

1. ``python -m build``: the sdist of ``pioneer-nav`` and its wheel (built from that sdist), and
   the wheel of the light runtime (``runtime/``).
2. Their metadata checked: name, version, ``Requires-Python``, ranges and no exact pin in
   ``Requires-Dist``, the console script, every shipped data file (``src/pioneer/data``) in
   the wheel and in the sdist; the runtime wheel holds exactly its modules.
3. Fresh venvs (not editable), each running ``check.py`` or ``runtime_check.py`` beside this
   file: Python 3.11 with ``[learn]`` (pinned by ``constraints.txt``: torch's CPU build), the
   newest Python (3.13) with the wheel alone, as a user's pip resolves it, side by side; then
   the runtime wheel on 3.13 driving a student exported in the first venv.

Prints one line per check and closes with ``smoke: N passed, N failed``; exit code 1 if any
failed. Everything goes into ``--out`` (``build/smoke``), which is emptied first.
"""

from __future__ import annotations

import argparse
import email.parser
import glob
import json
import os
import re
import shutil
import subprocess
import sys
import tarfile
import threading
import time
import tomllib
import zipfile
from collections.abc import Callable
from pathlib import Path

from packaging.requirements import Requirement  # pip's and build's, in the dev environment
from packaging.specifiers import SpecifierSet

ROOT = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
MAIN = tomllib.loads((ROOT / "pyproject.toml").read_text())
RUNTIME = tomllib.loads((ROOT / "runtime" / "pyproject.toml").read_text())


class Job:
    """Steps that run one after another; their lines are printed when asked (jobs run side
    by side, each printed whole)."""

    def __init__(self, out: Path) -> None:
        self.out = out
        self.passed = 0
        self.failed = 0
        self.lines: list[str] = []

    def flush(self) -> None:
        if self.lines:
            print("\n".join(self.lines), flush=True)
        self.lines = []

    def step(self, name: str, fn: Callable[[], str]) -> bool:
        t0 = time.perf_counter()
        try:
            note = fn()
        except Exception as exc:  # one failed step is reported, the rest still run
            self.failed += 1
            self.lines.append(f"FAIL {name}: {exc}")
            return False
        self.passed += 1
        self.lines.append(f"ok   {name} ({time.perf_counter() - t0:.0f} s): {note}")
        return True

    def run(self, cmd: list[str], log: str) -> str:
        """Run ``cmd`` with its output in ``out/log``; raise with the log's tail if it fails."""
        path = self.out / log
        with path.open("w") as f:
            proc = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT, check=False)
        text = path.read_text()
        if proc.returncode != 0:
            tail = "\n".join(text.splitlines()[-30:])
            raise RuntimeError(f"{' '.join(cmd)}: exit {proc.returncode} (log {path})\n{tail}")
        return text

    def checks_in(self, name: str, python: Path, script: str, *args: str) -> None:
        """Run a check script in a venv; its per-check lines are kept and counted."""
        t0 = time.perf_counter()
        proc = subprocess.run(
            [str(python), str(HERE / script), *args],
            capture_output=True,
            text=True,
            cwd=self.out,
            check=False,
        )
        (self.out / f"{name}-check.log").write_text(proc.stdout + proc.stderr)
        lines = proc.stdout.rstrip().splitlines()
        try:
            counts = json.loads(lines[-1])
        except (IndexError, ValueError):
            counts = {"passed": 0, "failed": 1}
        self.lines.append(f"{name} smoke ({time.perf_counter() - t0:.0f} s):")
        self.lines += lines[:-1] or proc.stderr.splitlines()[-30:]
        self.passed += counts["passed"]
        self.failed += counts["failed"] + (proc.returncode != 0 and not counts["failed"])


PATIENT_DOWNLOADS = ["--retries", "10", "--resume-retries", "20", "--timeout", "60"]
"""pip's options for a slow or interrupted registry: an install downloads ≈ 100 MB of
wheels, and one cut connection must not fail the smoke (CI saw a 27.8 MB wheel stop at 11.8 MB
six times in a row)."""

NETWORK_ERRORS = ("incomplete-download", "Connection", "ReadTimeout", "Max retries exceeded")
"""What in pip's log says the network failed, not the package: such an install is retried."""


def install(job: Job, cmd: list[str], log: str, attempts: int = 3) -> str:
    """``job.run(cmd)``, run again (up to ``attempts`` in all, 10 s apart) when pip failed on
    the network; a failure of the package itself is raised at once."""
    for attempt in range(1, attempts):
        try:
            return job.run(cmd, log if attempt == 1 else f"{log}.{attempt}")
        except RuntimeError as exc:
            if not any(e in str(exc) for e in NETWORK_ERRORS):
                raise
            time.sleep(10)
    return job.run(cmd, log if attempts == 1 else f"{log}.{attempts}")


def find_python(version: str) -> Path:
    """A ``python{version}`` that runs: on the PATH, else pyenv's (whose shims answer only
    for the selected version)."""
    root = Path(os.environ.get("PYENV_ROOT", Path.home() / ".pyenv"))
    found = shutil.which(f"python{version}")
    candidates = [found] if found else []
    candidates += sorted(glob.glob(str(root / "versions" / f"{version}*" / "bin" / "python3")))
    for candidate in candidates:
        ok = subprocess.run(
            [candidate, "-c", f"import sys; assert sys.version.startswith('{version}.')"],
            capture_output=True,
            check=False,
        )
        if ok.returncode == 0:
            return Path(candidate)
    raise RuntimeError(f"no python{version} found (PATH, {root}/versions)")


def _source_version() -> str:
    text = (ROOT / "src" / "pioneer" / "__init__.py").read_text()
    match = re.search(r'^__version__ = "([^"]+)"$', text, re.MULTILINE)
    assert match, "no __version__ in src/pioneer/__init__.py"
    return match.group(1)


def _shipped_data() -> set[str]:
    """The data files the package ships (tracked by git), as ``pioneer/data/…`` paths."""
    listed = subprocess.run(
        ["git", "ls-files", "src/pioneer/data"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()
    files = {p.removeprefix("src/") for p in listed if not p.endswith(".py")}
    assert len(files) > 10, files
    return files


def _specifier(requirement: str) -> SpecifierSet:
    return Requirement(requirement).specifier


def _pinned(requirement: str) -> bool:
    return any(s.operator in {"==", "==="} for s in _specifier(requirement))


def _metadata(wheel: Path) -> email.message.Message:
    with zipfile.ZipFile(wheel) as z:
        name = next(n for n in z.namelist() if n.endswith(".dist-info/METADATA"))
        return email.parser.Parser().parsestr(z.read(name).decode())


def check_main_dist(dist: Path) -> str:
    version = _source_version()
    wheels = list(dist.glob(f"pioneer_nav-{version}-py3-none-any.whl"))
    sdists = list(dist.glob(f"pioneer_nav-{version}.tar.gz"))
    assert len(wheels) == 1 and len(sdists) == 1, sorted(p.name for p in dist.iterdir())
    meta = _metadata(wheels[0])
    assert meta["Name"] == "pioneer-nav" and meta["Version"] == version, meta["Version"]
    assert meta["Requires-Python"] == MAIN["project"]["requires-python"] == ">=3.11"
    assert meta["Description-Content-Type"] == "text/markdown"
    assert "# PioneeR" in (meta.get_payload() or ""), "no README as the long description"
    requires = meta.get_all("Requires-Dist") or []
    pinned = [r for r in requires if _pinned(r)]
    assert not pinned, f"exact pins in the package: {pinned}"
    unbounded = [r for r in requires if not any(s.operator == "<" for s in _specifier(r))]
    assert not unbounded, f"no upper bound: {unbounded}"
    extras = set(meta.get_all("Provides-Extra") or [])
    assert set(MAIN["project"]["optional-dependencies"]) == extras, extras
    torch = [r for r in requires if r.startswith("torch") and 'extra == "learn"' in r]
    assert torch, requires
    shipped = _shipped_data()
    with zipfile.ZipFile(wheels[0]) as z:
        names = set(z.namelist())
        entry = next(n for n in names if n.endswith(".dist-info/entry_points.txt"))
        assert "pioneer = pioneer.cli:main" in z.read(entry).decode()
    missing = shipped - names
    assert not missing, f"not in the wheel: {sorted(missing)}"
    assert "pioneer/py.typed" in names
    assert not [n for n in names if n.endswith((".nbi", ".nbc", ".pyc"))], "caches in the wheel"
    with tarfile.open(sdists[0]) as t:
        top = f"pioneer_nav-{version}/"
        in_sdist = {m.removeprefix(top + "src/") for m in t.getnames()}
    missing = shipped - in_sdist
    assert not missing, f"not in the sdist: {sorted(missing)}"
    size = wheels[0].stat().st_size / 1e6
    return (
        f"{wheels[0].name} ({size:.1f} MB, {len(shipped)} data files), {sdists[0].name}; {torch[0]}"
    )


def check_runtime_dist(dist: Path) -> str:
    version = _source_version()
    wheels = list(dist.glob(f"pioneer_nav_runtime-{version}-py3-none-any.whl"))
    assert len(wheels) == 1, sorted(p.name for p in dist.iterdir())
    meta = _metadata(wheels[0])
    assert meta["Name"] == "pioneer-nav-runtime" and meta["Version"] == version
    assert meta["Requires-Python"] == RUNTIME["project"]["requires-python"] == ">=3.11"
    requires = meta.get_all("Requires-Dist") or []
    plain = sorted(Requirement(r).name for r in requires if Requirement(r).marker is None)
    assert plain == ["numpy", "onnxruntime"], requires
    assert not [r for r in requires if _pinned(r)], requires
    forced = RUNTIME["tool"]["hatch"]["build"]["targets"]["wheel"]["force-include"]
    with zipfile.ZipFile(wheels[0]) as z:
        modules = {n for n in z.namelist() if ".dist-info/" not in n}
    assert modules == set(forced.values()), modules ^ set(forced.values())
    return f"{wheels[0].name}: {len(modules)} files, requires {', '.join(requires)}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "build" / "smoke")
    parser.add_argument("--learn-python", default="3.11", help="the venv with [learn]")
    parser.add_argument(
        "--python",
        action="append",
        help="a venv with the wheel alone, unpinned (repeatable; default 3.13)",
    )
    args = parser.parse_args()
    out = args.out.resolve()
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    dist = out / "dist"
    t_start = time.perf_counter()
    first = Job(out)

    def build() -> str:
        first.run([sys.executable, "-m", "build", "--outdir", str(dist), str(ROOT)], "build.log")
        runtime = [sys.executable, "-m", "build", "--wheel", "--outdir", str(dist)]
        first.run([*runtime, str(ROOT / "runtime")], "build-runtime.log")
        return ", ".join(sorted(p.name for p in dist.iterdir()))

    built = first.step("python -m build", build)
    if built:
        first.step("pioneer-nav metadata and files", lambda: check_main_dist(dist))
        first.step("pioneer-nav-runtime metadata and files", lambda: check_runtime_dist(dist))
    first.flush()
    if not built:
        print(f"smoke: {first.passed} passed, {first.failed} failed")
        return 1
    wheel = next(dist.glob("pioneer_nav-*.whl"))
    runtime_wheel = next(dist.glob("pioneer_nav_runtime-*.whl"))
    onnx = out / "student.onnx"
    plain = args.python or ["3.13"]

    def venv(job: Job, version: str, name: str, requirement: str, pinned: bool) -> bool:
        """A fresh venv ``out/name`` of Python ``version`` with ``requirement`` installed."""

        def make() -> str:
            python = find_python(version)
            where = out / name
            job.run([str(python), "-m", "venv", str(where)], f"{name}-venv.log")
            pip = [str(where / "bin" / "python"), "-m", "pip", "install"]
            pip += ["-c", str(ROOT / "constraints.txt")] if pinned else []
            job.run([*pip, "--upgrade", "pip"], f"{name}-pip.log")
            install(job, [*pip, *PATIENT_DOWNLOADS, requirement], f"{name}-install.log")
            freeze = job.run([str(where / "bin" / "python"), "-m", "pip", "freeze"], f"{name}.txt")
            picked = [x for x in freeze.split() if x.startswith(("numpy==", "numba==", "torch=="))]
            return f"{python} → {', '.join(picked)} (all: {name}.txt)"

        label = f"Python {version}: pip install {Path(requirement).name}"
        return job.step(label + (" -c constraints.txt" if pinned else ""), make)

    def learn_job(job: Job) -> None:
        """The wheel with [learn], pinned; it exports the student the runtime job drives."""
        name = f"py{args.learn_python}-learn"
        if venv(job, args.learn_python, name, f"{wheel}[learn]", pinned=True):
            tmp = str(out / f"{name}-tmp")
            python = out / name / "bin" / "python"
            job.checks_in(name, python, "check.py", "--tmp", tmp, "--learn", "--onnx", str(onnx))

    def plain_job(job: Job) -> None:
        """The wheel alone, resolved as a user's pip would; then the runtime's venv."""
        for version in plain:
            name = f"py{version}"
            if venv(job, version, name, str(wheel), pinned=False):
                tmp = str(out / f"{name}-tmp")
                job.checks_in(name, out / name / "bin" / "python", "check.py", "--tmp", tmp)
        runtime_ready.append(venv(job, plain[-1], "runtime", str(runtime_wheel), pinned=False))

    runtime_ready: list[bool] = []  # the runtime's venv installed (checks run only then)
    jobs = [Job(out), Job(out)]
    threads = [
        threading.Thread(target=learn_job, args=(jobs[0],)),
        threading.Thread(target=plain_job, args=(jobs[1],)),
    ]
    for thread in threads:
        thread.start()
    for thread, job in zip(threads, jobs, strict=True):
        thread.join()
        job.flush()
    last = Job(out)
    if runtime_ready == [True]:
        last.checks_in("runtime", out / "runtime" / "bin" / "python", "runtime_check.py",
                       "--onnx", str(onnx))  # fmt: skip
    last.flush()
    passed = sum(j.passed for j in [first, *jobs, last])
    failed = sum(j.failed for j in [first, *jobs, last])
    minutes = (time.perf_counter() - t_start) / 60
    print(f"(logs and venvs in {out}; {minutes:.1f} min)")
    print(f"smoke: {passed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
