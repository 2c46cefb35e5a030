"""``pioneer.parallel``: pool workers ignore SIGINT and SIGTERM, are killed at once when the
pool's block raises, and never outlive their parent process."""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from pioneer.parallel import bounded_map, spawn_pool


def _workers(n: int) -> list[mp.process.BaseProcess]:
    """This process's ``n`` pool workers, once they are all started."""
    deadline = time.monotonic() + 60
    while len(mp.active_children()) < n:
        assert time.monotonic() < deadline, "the workers did not start"
        time.sleep(0.01)
    return mp.active_children()


def test_workers_ignore_sigint_and_sigterm():
    with spawn_pool(1) as pool:
        pid = pool.submit(os.getpid).result(timeout=60)
        os.kill(pid, signal.SIGINT)
        os.kill(pid, signal.SIGTERM)
        time.sleep(0.2)
        assert pool.submit(os.getpid).result(timeout=60) == pid  # the same worker, still serving


def test_a_block_that_raises_kills_the_busy_workers_at_once():
    with pytest.raises(RuntimeError, match="stop"), spawn_pool(2) as pool:
        for _ in range(4):
            pool.submit(time.sleep, 60)
        workers = _workers(2)
        time.sleep(0.5)  # the first two tasks run
        t0 = time.monotonic()
        raise RuntimeError("stop")
    assert time.monotonic() - t0 < 2.0
    assert [w.exitcode for w in workers] == [-signal.SIGKILL] * 2  # killed and reaped
    assert mp.active_children() == []


def test_a_failed_pool_drops_only_the_managers_cancelled_future_error(monkeypatch):
    """Python 3.11's pool manager may fail a future that the stop has just cancelled; that
    error alone is kept off stderr while a failed pool stops (a race: tested on the hook)."""
    from concurrent.futures import InvalidStateError

    from pioneer.parallel import _quiet_broken_pool

    seen: list[type[BaseException]] = []
    monkeypatch.setattr(threading, "excepthook", lambda args: seen.append(args.exc_type))

    def report(exc: BaseException) -> None:
        threading.excepthook(threading.ExceptHookArgs([type(exc), exc, None, None]))

    with _quiet_broken_pool():
        report(InvalidStateError("CANCELLED: <Future state=cancelled>"))
        report(ValueError("a real failure"))
    report(InvalidStateError("outside a stop"))
    assert seen == [ValueError, InvalidStateError]
    # a failing block with queued tasks still ends with its own error, the hook restored
    hook = threading.excepthook
    for _ in range(3):
        with pytest.raises(RuntimeError, match="stop"), spawn_pool(2) as pool:
            for _ in range(20):
                pool.submit(time.sleep, 60)
            raise RuntimeError("stop")
    assert threading.excepthook is hook and InvalidStateError not in seen[2:]


def test_an_abandoned_generator_stops_its_pool():
    def results() -> object:
        with spawn_pool(2) as pool:
            yield from bounded_map(pool, time.sleep, [0.0] + [60.0] * 3, 4)

    gen = results()
    next(gen)
    workers = _workers(2)
    t0 = time.monotonic()
    gen.close()
    assert time.monotonic() - t0 < 2.0
    assert not any(w.is_alive() for w in workers)


def test_a_worker_exits_with_its_parent_even_a_killed_one(tmp_path: Path):
    script = (
        "import multiprocessing as mp, os, sys, time\n"
        "from pioneer.parallel import spawn_pool\n"
        "if __name__ == '__main__':\n"
        "    with spawn_pool(1) as pool:\n"
        "        pool.submit(time.sleep, 60)\n"
        "        while not mp.active_children():\n"
        "            time.sleep(0.01)\n"
        "        time.sleep(0.5)\n"
        "        print(mp.active_children()[0].pid, flush=True)\n"
        "        os.kill(os.getpid(), 9)\n"
    )
    path = tmp_path / "parent.py"
    path.write_text(script)
    out, err = tmp_path / "stdout.txt", tmp_path / "stderr.txt"
    with open(out, "w") as fo, open(err, "w") as fe:  # files: an orphan may hold a pipe open
        proc = subprocess.run([sys.executable, str(path)], stdout=fo, stderr=fe, timeout=120)
    assert proc.returncode == -signal.SIGKILL, err.read_text()
    worker = int(out.read_text())
    deadline = time.monotonic() + 2.0
    while _running(worker) and time.monotonic() < deadline:
        time.sleep(0.01)
    if _running(worker):
        os.kill(worker, signal.SIGKILL)
        pytest.fail("the worker outlived its parent")


def _running(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"
