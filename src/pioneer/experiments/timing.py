"""What a ``pioneer reproduce`` run will take on this machine, announced before it starts.

The stored seconds per episode (``src/pioneer/data/episode_times.json``, written by
``benchmarks/episode_times.py`` from a finished paper-profile run) are one machine's. Two
things carry them to another (docs/performance.md, "The announced time"):

- **this machine's speed**: :func:`probe_seconds` times a fixed batch of world steps and
  rules-only teacher decisions (well under a second), and the stored times are scaled by its
  ratio to the same probe on the machine that measured them (``probe_s`` in the file);
- **the workers it will really use**: ``min(workers, CPUs)`` — more workers than CPUs only
  share them — at the parallel efficiency :func:`parallel_speed` states, and a fair share of
  the CPUs when other processes keep them busy (the one-minute load average).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import os
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from pioneer.errors import DataError, expect

__all__ = [
    "EPISODE_TIMES_FORMAT",
    "SPEED_LOSS_PER_WORKER",
    "EpisodeTimes",
    "Estimate",
    "announcement",
    "episode_times",
    "estimate",
    "jit_cache_warm",
    "load_episode_times",
    "parallel_speed",
    "probe",
    "probe_seconds",
    "row_times",
]

EPISODE_TIMES_FORMAT = "pioneer.episode-times/1"
# The stored times come from a 2-worker run on 2 CPUs. Beyond 2 workers each adds a little
# less: n workers run n / (1 + k (n − 2)) times one of those, with k from a paper-profile run
# on 16 cores (16 workers, 1,420 % CPU) that ran ≈ 7 × as fast as 2 workers on 2 cores do:
# 16 / (1 + 14 k) = 14 → k = 1/98.
SPEED_LOSS_PER_WORKER = 1.0 / 98.0
PROBE_STEPS = 5  # world steps of 120 copies per probe round
PROBE_DECISIONS = 1  # rules-only teacher decisions per probe round
# The probe's time is the fastest round's: a round (≈ 1.7 ms on the 2-core reference) is
# shorter than the scheduler's time slice, so some round runs uninterrupted even beside other
# work (60 rounds under a load of 7 on 2 CPUs: fastest rounds within 3 % of each other).
PROBE_ROUNDS = 60
PROBE_BUDGET_S = 0.8  # [s] at most this long (after 10 rounds at least)
PROBE_FULL_SHARE = 0.95  # a probe with this share of a CPU or more had one to itself


@dataclasses.dataclass(frozen=True)
class EpisodeTimes:
    """What a run costs on the machine it was measured on (``machine``; docs/performance.md),
    stored in ``src/pioneer/data/episode_times.json`` by ``benchmarks/episode_times.py`` from
    a finished paper-profile run. Only for the expected time that ``reproduce`` announces
    before it starts."""

    episode_s: Mapping[str, float]  # [s] mean wall time of one episode per policy, 2 workers
    default_episode_s: float  # [s] a policy not listed
    overhead_s: float  # [s] starting the workers, writing the tables, figures and Table IV
    cold_jit_s: float  # [s] numba compiling the kernels in every worker (empty cache)
    measured: str  # the date of the measurement (YYYY-MM-DD)
    machine: str  # what it was measured on
    source: str = ""  # how it was measured
    notes: tuple[str, ...] = ()
    probe_s: float | None = None  # [s] :func:`probe_seconds` on that machine (None: unknown)

    def of(self, row: str) -> float:
        """The mean time [s] of one episode of the policy row ``row`` (a student's other
        DAgger seeds cost what its seed 0 costs)."""
        name = row.rsplit("-s", 1)[0] if row.rsplit("-s", 1)[-1].isdigit() else row
        return float(self.episode_s.get(row, self.episode_s.get(name, self.default_episode_s)))

    def machine_short(self) -> str:
        """The CPU the times were measured on, without its feature list (``"AMD EPYC
        (znver4)"`` of ``"AMD EPYC (znver4: sse4.2+…), 2 CPUs, Linux…"``, the form
        ``benchmarks/episode_times.py``'s ``machine_line`` writes; any other text up to its
        first comma)."""
        head = self.machine.split(",")[0].strip()
        if "(" in head and ":" in head:
            head = head.split(":")[0] + ")"
        return head or "unknown"

    def to_dict(self) -> dict[str, Any]:
        """The JSON form (the keys :func:`load_episode_times` reads)."""
        return {
            "format": EPISODE_TIMES_FORMAT,
            "measured": self.measured,
            "machine": self.machine,
            "source": self.source,
            "notes": list(self.notes),
            "unit": "s",
            "episode_s": dict(self.episode_s),
            "default_episode_s": self.default_episode_s,
            "overhead_s": self.overhead_s,
            "cold_jit_s": self.cold_jit_s,
            "probe_s": self.probe_s,
        }


def load_episode_times(path: str | Path) -> EpisodeTimes:
    """Read an episode-times file; a missing, foreign or malformed one raises one
    :class:`DataError` naming the file and the field."""
    p = Path(path)
    fix = "regenerate it with benchmarks/episode_times.py"
    try:
        raw = json.loads(p.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise DataError(
            expect("episode times", "a readable JSON file", f"{p}: {exc}", fix)
        ) from exc
    if not isinstance(raw, dict) or raw.get("format") != EPISODE_TIMES_FORMAT:
        got = raw.get("format") if isinstance(raw, dict) else type(raw).__name__
        raise DataError(expect(f"{p}: format", EPISODE_TIMES_FORMAT, got, fix))

    def seconds(key: str, value: Any) -> float:
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        if not ok or not math.isfinite(value) or value < 0:
            raise DataError(expect(f"{p}: {key}", "a finite time >= 0 [s]", value, fix))
        return float(value)

    table = raw.get("episode_s")
    if not isinstance(table, dict) or not table:
        raise DataError(expect(f"{p}: episode_s", "a mapping policy -> seconds", table, fix))
    probe = raw.get("probe_s")
    return EpisodeTimes(
        episode_s={str(k): seconds(f"episode_s.{k}", v) for k, v in table.items()},
        default_episode_s=seconds("default_episode_s", raw.get("default_episode_s")),
        overhead_s=seconds("overhead_s", raw.get("overhead_s")),
        cold_jit_s=seconds("cold_jit_s", raw.get("cold_jit_s")),
        measured=str(raw.get("measured", "")),
        machine=str(raw.get("machine", "")),
        source=str(raw.get("source", "")),
        notes=tuple(str(n) for n in raw.get("notes", ())),
        probe_s=None if probe is None else seconds("probe_s", probe) or None,
    )


@functools.cache
def episode_times() -> EpisodeTimes:
    """The shipped measurement (``src/pioneer/data/episode_times.json``), read once."""
    from pioneer.data import EPISODE_TIMES

    return load_episode_times(EPISODE_TIMES)


def jit_cache_warm() -> bool:
    """Whether numba's on-disk cache already holds the simulator's step kernel and the
    teacher's rollout kernel (else the first episode of every worker compiles them:
    ``episode_times().cold_jit_s``)."""
    from numba.core import config

    import pioneer.sim.kernel as kernel

    patterns = ("kernel.step_kernel-*.nbi", "kernel_simd.trajectory_kernel_lanes-*.nbi")
    cache_dir = str(getattr(config, "CACHE_DIR", "") or "")  # NUMBA_CACHE_DIR, read by numba
    if cache_dir:
        root = Path(cache_dir)
        return root.is_dir() and all(any(root.rglob(p)) for p in patterns)
    here = Path(kernel.__file__).parent / "__pycache__"
    return all(any(here.glob(p)) for p in patterns)


def row_times(records: Sequence[Mapping[str, Any]]) -> dict[str, tuple[int, float]]:
    """Episodes and summed episode run time [s] of every policy row, in first-seen order."""
    out: dict[str, tuple[int, float]] = {}
    for r in records:
        n, sec = out.get(r["policy"], (0, 0.0))
        out[r["policy"]] = (n + 1, sec + float(r.get("wall_time_s", 0.0)))
    return out


def probe(rounds: int = PROBE_ROUNDS) -> tuple[float, float]:
    """This machine's speed: the time [s] of the fastest of ``rounds`` rounds (fewer if they
    take over :data:`PROBE_BUDGET_S`), each :data:`PROBE_STEPS` world steps of 120 copies
    and :data:`PROBE_DECISIONS` decision of the rules-only teacher, in a fixed HR-RL scene
    (≈ 0.1 s in all on the 2-core reference; before the rounds, the kernels' first call
    loads them, or compiles them on an empty numba cache). The fastest round measures the
    CPU rather than other work beside it. Returns that time and the share of a CPU the probe
    got over all its rounds (its CPU time over their wall time: below 1 when other processes
    keep the CPUs busy)."""
    import numpy as np

    from pioneer.control.teacher import make_teacher
    from pioneer.sim.scenarios import get_scenario, sample_state
    from pioneer.sim.world import step

    scenario = get_scenario("hr-rl")
    world = scenario.world()
    state = sample_state(scenario, np.random.default_rng(0))
    teacher = make_teacher("hr-rl", density=False)
    copies = state.repeat(teacher.candidates.shape[0])
    commands = teacher.candidates

    def one_round() -> None:
        s = copies
        for _ in range(PROBE_STEPS):
            s = step(world, s, commands, 0.3)
        for _ in range(PROBE_DECISIONS):
            teacher.decide(world, state)

    one_round()  # loads (or compiles) the kernels
    best = math.inf
    start, cpu = time.perf_counter(), time.process_time()
    for k in range(rounds):
        t0 = time.perf_counter()
        one_round()
        best = min(best, time.perf_counter() - t0)
        if k >= 10 and t0 - start > PROBE_BUDGET_S:
            break
    share = (time.process_time() - cpu) / max(time.perf_counter() - start, 1e-9)
    return best, min(share, 1.0)


def probe_seconds(rounds: int = PROBE_ROUNDS) -> float:
    """The probe's time [s] alone (:func:`probe`)."""
    return probe(rounds)[0]


def parallel_speed(workers: int) -> float:
    """How many of the stored episode times' workers (2 workers on 2 CPUs) ``workers``
    workers on as many free CPUs are worth: n / (1 + k (n − 2)), k =
    :data:`SPEED_LOSS_PER_WORKER` (2 → 2, 8 → 7.6, 16 → 14)."""
    n = max(workers, 1)
    return n / (1.0 + SPEED_LOSS_PER_WORKER * (n - 2))


@dataclasses.dataclass(frozen=True)
class Estimate:
    """The announced time of a run and what it rests on."""

    paper_s: float  # [s] the episodes of the paper's rows
    extra_s: float  # [s] the episodes of the other rows
    fixed_s: float  # [s] start-up (and compiling the kernels) and the report
    workers: int  # worker processes asked for
    cores: int  # the CPUs they run on: min(workers, CPUs)
    busy: float  # other processes running beside this one (the load average less this one)
    speed: float  # the stored machine's probe time ÷ this one's (1: as fast; 0.5: half)

    @property
    def total_s(self) -> float:
        """[s] the whole run."""
        return self.paper_s + self.extra_s + self.fixed_s


def estimate(
    paper_rows: Sequence[str],
    extra_rows: Sequence[str],
    episodes_per_row: float,
    workers: int,
    cold: bool,
    *,
    speed: float | None = None,
    cpus: int | None = None,
    load: float | None = None,
    times: EpisodeTimes | None = None,
) -> Estimate:
    """The expected wall time of ``episodes_per_row`` episodes of every row on ``workers``
    workers. ``speed`` (the stored machine's :func:`probe_seconds` ÷ this machine's),
    ``cpus`` and ``load`` (the one-minute load average, this process included) are measured
    when not given — the other running processes from the share of a CPU the probe got when it
    got less than all of one (each process an equal share: cpus / share − 1 others), else from
    the load average, at most cpus − 1 (a lone process gets a whole CPU beside as many);
    ``cold``: the kernels are compiled first."""
    times = times or episode_times()
    share_one = 1.0
    if speed is None:
        seconds, share_one = probe()
        speed = times.probe_s / seconds if times.probe_s else 1.0
    if cpus is None:
        affinity = getattr(os, "sched_getaffinity", None)
        cpus = len(affinity(0)) if affinity is not None else os.cpu_count() or 1
    if load is None and share_one < PROBE_FULL_SHARE:
        load = cpus / share_one
    elif load is None:
        average = os.getloadavg()[0] if hasattr(os, "getloadavg") else 1.0
        load = min(average, float(cpus))
    cores = max(1, min(workers, cpus))
    busy = max(load - 1.0, 0.0)  # this process is one of the load's
    # the CPUs' share our workers get beside the other work (each runnable process an equal one)
    share = min(1.0, cpus / (busy + cores))
    rate = parallel_speed(cores) * share * speed  # stored episode-seconds per second

    def wall(rows: Sequence[str]) -> float:
        return sum(times.of(r) for r in rows) * episodes_per_row / rate

    alone = min(1.0, cpus / (busy + 1.0))  # the start-up and the report: mostly one process
    fixed = (times.overhead_s + (times.cold_jit_s if cold else 0.0)) / (speed * alone)
    return Estimate(wall(paper_rows), wall(extra_rows), fixed, workers, cores, busy, speed)


def announcement(profile: str, episodes: int, done: int, est: Estimate) -> str:
    """The one line (under 300 characters) ``reproduce`` prints before the work."""
    times = episode_times()
    digits = 1 if est.total_s < 600 else 0  # short runs in tenths of a minute

    def minutes(sec: float) -> str:
        return f"{sec / 60:.{digits}f}"

    shared = f", ≈ {est.busy:.1f} other busy processes" if est.busy >= 0.5 else ""
    machine = times.machine_short()
    machine = machine if len(machine) <= 40 else machine[:39] + "…"
    return (
        f"pioneer reproduce --profile {profile}: {episodes:,} episodes ({done:,} done), expected "
        f"≈ {minutes(est.total_s)} min (paper's rows {minutes(est.paper_s)}, others "
        f"{minutes(est.extra_s)}, start-up and report {minutes(est.fixed_s)}) with "
        f"{est.workers} worker(s) on {est.cores} CPU(s){shared}; CPU speed {est.speed:.2f}× "
        f"{machine}'s"
    )
