"""The evaluation harness: N seeds × M trials per scenario and policy, in parallel, resumable.

Every episode is identified by (scenario, policy label, seed, trial); its environment seed is
derived deterministically from (scenario, seed, trial), so any episode can be replayed alone
(`episode_seed`) and every policy meets the same initial states. Finished episodes are
appended to ``episodes.jsonl`` by the parent process as they arrive (one JSON object a line,
flushed and fsynced, each written whole even when a signal arrives), so an interrupted run
resumes where it stopped; a malformed line is reported with its line number, never skipped.
On SIGINT or SIGTERM (:mod:`pioneer.interrupt`) the workers are killed at once, the running
episodes are lost (a resumed run repeats them) and the run names what it kept. Backends:
local processes (default) or a Ray cluster (extra ``distributed``). ``scenarios.json``
records the full config of every scenario evaluated into the folder; resuming with a
scenario whose definition changed under the same name (an edited scenario file) is refused,
so one table never mixes two layouts.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import signal
import threading
import time
from collections.abc import Callable, Generator, Mapping, Sequence
from pathlib import Path
from typing import Any

from pioneer.errors import ConfigError, DataError, expect
from pioneer.interrupt import deferred, kept
from pioneer.io import check_regular_target, naming_path, output_dir, to_json
from pioneer.parallel import worker_count
from pioneer.progress import progress_bar
from pioneer.seeds import SEED_SETS
from pioneer.seeds import episode_seed as _seed_of

__all__ = ["PolicySpec", "Task", "episode_seed", "evaluate", "read_records", "run_task"]

EPISODES_FILE = "episodes.jsonl"
SCENARIOS_FILE = "scenarios.json"


@dataclasses.dataclass(frozen=True)
class PolicySpec:
    """A policy by registered name, its keyword arguments (JSON-able) and its row label."""

    name: str
    kwargs: tuple[tuple[str, Any], ...] = ()
    label: str = ""

    @property
    def row(self) -> str:
        """The label used in records and tables."""
        return self.label or self.name

    @classmethod
    def make(cls, name: str, label: str = "", **kwargs: Any) -> PolicySpec:
        """Convenience constructor with keyword arguments."""
        return cls(name, tuple(sorted(kwargs.items())), label)

    @classmethod
    def parse(cls, text: str) -> PolicySpec:
        """``NAME`` or ``NAME:key=value,key=value`` (the CLI's ``--policy`` syntax).

        Values are read as JSON when they parse (``0.5``, ``true``, ``"x"``, ``[1, 2]``),
        else taken as text (paths); ``label=`` names the row. Parameters are separated by the
        commas outside brackets and double quotes, so a list or a quoted text may hold commas
        (``checkpoint="runs/a,b/s.safetensors"``). E.g.
        ``student-mdn:checkpoint=runs/d/student.safetensors,action_mode=mean,label=mine``.
        """
        name, sep, rest = text.partition(":")
        fix = "write NAME or NAME:key=value,key=value (e.g. student-mdn:checkpoint=PATH)"
        if not name.strip() or (sep and not rest.strip()):
            raise ConfigError(expect("policy", "NAME[:key=value,…]", text, fix))
        kwargs: dict[str, Any] = {}
        for item in _split_parameters(rest, text, fix) if rest else []:
            key, eq, raw = item.partition("=")
            key = key.strip()
            if not eq or not key.isidentifier() or key in kwargs:
                raise ConfigError(
                    expect(f"policy {name!r} parameter", "a new key=value", item.strip(), fix)
                )
            try:
                value = json.loads(raw)
            except json.JSONDecodeError:
                value = raw
            if isinstance(value, dict):
                raise ConfigError(
                    expect(f"policy {name!r} parameter {key!r}", "a number, text or list", raw, fix)
                )
            kwargs[key] = tuple(value) if isinstance(value, list) else value  # hashable
        label = kwargs.pop("label", "")
        return cls(name.strip(), tuple(sorted(kwargs.items())), str(label))


def _split_parameters(rest: str, text: str, fix: str) -> list[str]:
    """``rest`` split at the commas outside ``[…]``, ``{…}`` and ``"…"`` (JSON values)."""
    items: list[str] = []
    depth, quoted, escaped, start = 0, False, False, 0
    for i, ch in enumerate(rest):
        if escaped:  # the character after a backslash inside quotes
            escaped = False
        elif quoted:
            escaped, quoted = ch == "\\", ch != '"'
        elif ch == '"':
            quoted = True
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            items.append(rest[start:i])
            start = i + 1
    if quoted or depth != 0:
        raise ConfigError(
            expect("policy", "balanced brackets and quotes in NAME:key=value,…", text, fix)
        )
    items.append(rest[start:])
    return items


@dataclasses.dataclass(frozen=True)
class Task:
    """One episode to run."""

    scenario: str
    policy: PolicySpec
    seed: int
    trial: int
    seed_set: str = "evaluation"  # or "validation" (pioneer.seeds.SEED_SETS)

    @property
    def key(self) -> tuple[str, str, int, int]:
        """Identity of the episode in ``episodes.jsonl``."""
        return (self.scenario, self.policy.row, self.seed, self.trial)


def episode_seed(scenario: str, seed: int, trial: int, seed_set: str = "evaluation") -> int:
    """The environment seed of trial ``trial`` of seed ``seed`` in ``scenario`` (deterministic;
    the evaluation or validation seeds of :mod:`pioneer.seeds`)."""
    return _seed_of(seed_set, scenario, seed, trial)


# ------------------------------------------------------------------------------ worker side
_POLICY_CACHE: dict[tuple[str, PolicySpec], Any] = {}


def _make_policy(spec: PolicySpec, scenario: str) -> Any:
    key = (scenario, spec)
    if key not in _POLICY_CACHE:
        from pioneer.control.registry import build_policy

        pol = build_policy(spec.name, scenario, **dict(spec.kwargs))
        if spec.label:
            pol.name = spec.label
        _POLICY_CACHE[key] = pol
    return _POLICY_CACHE[key]


def _worker_init() -> None:
    from threadpoolctl import threadpool_limits

    threadpool_limits(1, user_api="blas")


def run_task(task: Task) -> dict[str, Any]:
    """Run one episode and return its JSON-able record."""
    from pioneer.eval.episode import run_episode

    policy = _make_policy(task.policy, task.scenario)
    t0 = time.perf_counter()
    env_seed = episode_seed(task.scenario, task.seed, task.trial, task.seed_set)
    rec, _ = run_episode(task.scenario, policy, env_seed)
    wall = time.perf_counter() - t0
    d = rec.to_dict()
    d.update(
        policy=task.policy.row,
        seed=task.seed,
        trial=task.trial,
        seed_set=task.seed_set,
        episode_seed=env_seed,
        wall_time_s=wall,
        decision_ms=1000.0 * wall / max(rec.steps, 1),
    )
    return d


# ------------------------------------------------------------------------------ records file
def read_records(path: str | Path) -> list[dict[str, Any]]:
    """All records of an ``episodes.jsonl``; a malformed line raises :class:`DataError`.

    A last line without a newline (a write cut by a crash) is dropped with a warning on
    stderr, since its episode will simply be run again.
    """
    p = Path(path)
    if not p.exists():
        return []
    text = p.read_text()
    lines = text.split("\n")
    partial = lines[-1] if lines[-1] else None
    out = []
    for i, line in enumerate(lines[:-1], start=1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except json.JSONDecodeError as exc:
            raise DataError(
                expect(
                    f"{p}: line {i}",
                    "one JSON record",
                    line[:60],
                    "delete or repair that line, then resume",
                )
            ) from exc
        if not isinstance(rec, dict):
            raise DataError(
                expect(f"{p}: line {i}", "a JSON object", line[:60], "delete or repair that line")
            )
        missing = {"scenario", "policy", "seed", "trial", "event"} - set(rec)
        if missing:
            raise DataError(
                expect(
                    f"{p}: line {i}",
                    "fields scenario/policy/seed/trial/event",
                    sorted(missing),
                    "delete that line",
                )
            )
        out.append(rec)
    if partial is not None:
        import sys

        print(
            f"pioneer: warning: {p}: ignoring an unfinished last line (re-running it)",
            file=sys.stderr,
        )
        with open(p, "w") as fh:  # drop the partial tail so appends stay line-aligned
            fh.write("\n".join(lines[:-1]) + ("\n" if len(lines) > 1 else ""))
    return out


def _append(fh: Any, rec: dict[str, Any]) -> None:
    """Append one whole record line; if the disk is full, cut the torn line off again so the
    file resumes cleanly, and name the file in the error."""
    line = to_json(rec) + "\n"
    with naming_path(fh.name):
        pos = fh.tell()
        try:
            fh.write(line)
            fh.flush()
            os.fsync(fh.fileno())
        except OSError:
            with contextlib.suppress(OSError):
                fh.truncate(pos)
            raise


def _check_seed_set(path: Path, records: Sequence[Mapping[str, Any]], seed_set: str) -> None:
    """A folder holds episodes of one seed set (records before seed sets: evaluation)."""
    found = sorted({str(r.get("seed_set", "evaluation")) for r in records})
    if found and found != [seed_set]:
        raise ConfigError(
            expect(
                f"{path}: records of the {seed_set} seed set",
                f"only {seed_set} episodes in one folder",
                f"{'/'.join(found)} episodes",
                "evaluate into another --out",
            )
        )


# ------------------------------------------------------------------------------ driver
def _tasks(
    scenarios: Sequence[str],
    policies: Sequence[PolicySpec],
    seeds: int,
    trials: int,
    seed_set: str = "evaluation",
) -> list[Task]:
    return [
        Task(sc, pol, s, t, seed_set)
        for sc in scenarios
        for pol in policies
        for s in range(seeds)
        for t in range(trials)
    ]


def build_check(pair: tuple[str, PolicySpec]) -> str:
    """Build the policy of ``pair`` = (scenario, spec) in this process (kept in its cache);
    any error it raises surfaces before the first episode runs."""
    scenario, spec = pair
    _make_policy(spec, scenario)
    return spec.row


def _pairs(tasks: list[Task]) -> list[tuple[str, PolicySpec]]:
    return list(dict.fromkeys((t.scenario, t.policy) for t in tasks))


# A stream first yields None once every policy of the run is built (a policy that cannot be
# built fails the run before any episode, and before the records file is opened), then the
# records as the episodes finish.
def _local(tasks: list[Task], workers: int) -> Generator[dict[str, Any] | None, None, None]:
    if workers <= 1:
        for pair in _pairs(tasks):
            build_check(pair)
        yield None
        for t in tasks:
            yield run_task(t)
        return
    from pioneer.parallel import bounded_map, spawn_pool

    with spawn_pool(workers, _worker_init) as pool:
        list(pool.map(build_check, _pairs(tasks)))
        yield None
        yield from bounded_map(pool, run_task, tasks, 4 * workers)


def _ray(tasks: list[Task], address: str | None) -> Generator[dict[str, Any] | None, None, None]:
    try:
        import ray
    except ImportError as exc:
        raise ConfigError(
            expect(
                "backend",
                "ray installed",
                "not installed",
                "pip install 'pioneer-nav[distributed]'",
            )
        ) from exc
    started = not ray.is_initialized()
    if started:
        _ray_init(ray, address)
    from pioneer.sim.scenarios import SCENARIOS_ENV

    files = os.environ.get(SCENARIOS_ENV)  # scenario files: the same paths on every node
    remote: Any = ray.remote(run_task)
    build: Any = ray.remote(build_check)
    if files:
        env = {"env_vars": {SCENARIOS_ENV: files}}
        remote, build = (ray.remote(runtime_env=env)(f) for f in (run_task, build_check))
    refs: list[Any] = []
    try:
        ray.get([build.remote(pair) for pair in _pairs(tasks)])
        yield None
        refs = [remote.remote(t) for t in tasks]
        while refs:
            done, refs = ray.wait(refs, num_returns=1)
            yield ray.get(done[0])
    except BaseException:  # interrupted or abandoned: stop the tasks, and the Ray we started
        for ref in refs:
            ray.cancel(ref, force=True)
        if started:
            ray.shutdown()
        raise


def _ray_init(ray: Any, address: str | None) -> None:
    """``ray.init``, keeping this process's SIGTERM handler (Ray sets its own, which exits
    without the interruption's line)."""
    main = threading.current_thread() is threading.main_thread()
    handler = signal.getsignal(signal.SIGTERM) if main else None
    ray.init(address=address, include_dashboard=False, log_to_driver=False)
    if handler is not None:
        signal.signal(signal.SIGTERM, handler)


def _check_shipped_parts(scenarios: Sequence[str], policies: Sequence[PolicySpec]) -> None:
    """Fail before running anything when a policy would load a part the scenario does not
    have — each registry entry's light check, without building the policies (no torch)."""
    from pioneer.control.registry import check_parts

    for sc in scenarios:
        for spec in policies:
            check_parts(spec.name, sc, dict(spec.kwargs))


def _record_scenarios(out: Path, names: Sequence[str]) -> None:
    """Add the scenarios' full configs to ``out/scenarios.json``; refuse a changed one."""
    from pioneer.io import write_text_atomic
    from pioneer.sim.scenarios import pin_scenario

    p = out / SCENARIOS_FILE
    try:
        known: dict[str, Any] = json.loads(p.read_text()) if p.exists() else {}
    except json.JSONDecodeError as exc:
        raise DataError(
            expect(str(p), "valid JSON", exc.msg, "delete the file (it is rewritten)")
        ) from exc
    mine = {n: pin_scenario(n, known.get(n), str(out)) for n in names}
    if any(n not in known for n in mine):
        write_text_atomic(p, to_json({**known, **mine}, indent=1) + "\n")


def evaluate(
    scenarios: Sequence[str],
    policies: Sequence[PolicySpec],
    seeds: int,
    trials: int,
    out_dir: str | Path,
    workers: int | None = None,
    backend: str = "process",
    ray_address: str | None = None,
    progress: bool = True,
    on_record: Callable[[dict[str, Any]], None] | None = None,
    seed_set: str = "evaluation",
) -> list[dict[str, Any]]:
    """Run (or resume) the evaluation on the ``seed_set`` episodes (evaluation seeds, or
    validation seeds for choices and tuning); returns every record (old and new)."""
    if seeds < 1 or trials < 1:
        raise ConfigError(
            expect("seeds/trials", "integers >= 1", (seeds, trials), "fix the counts")
        )
    if seed_set not in SEED_SETS:
        raise ConfigError(expect("seed set", f"one of {SEED_SETS}", seed_set, "pick one"))
    if backend not in ("process", "ray"):
        raise ConfigError(expect("backend", "'process' or 'ray'", backend, "pick one"))
    from pioneer.control.registry import check_policy_name
    from pioneer.sim.scenarios import get_scenario

    for sc in scenarios:  # fail before running anything, not hours in
        get_scenario(sc)
    for spec in policies:
        check_policy_name(spec.name)
    _check_shipped_parts(scenarios, policies)
    out = Path(out_dir)
    output_dir(out)
    _record_scenarios(out, scenarios)
    path = out / EPISODES_FILE
    records = read_records(path)
    _check_seed_set(path, records, seed_set)
    done = {(r["scenario"], r["policy"], int(r["seed"]), int(r["trial"])) for r in records}
    todo = [t for t in _tasks(scenarios, policies, seeds, trials, seed_set) if t.key not in done]
    n_workers = worker_count(workers)
    stream = _ray(todo, ray_address) if backend == "ray" else _local(todo, n_workers)
    total = len(done) + len(todo)
    with (
        kept(lambda: f"{len(records)} of {total} episodes kept in {path}"),
        contextlib.closing(stream),  # its pool stops with the run, whatever stops the run
    ):
        next(stream)  # every policy built before the first episode and the records file
        with (
            open(check_regular_target(path), "a") as fh,
            progress_bar(
                total=total, initial=len(done), desc="episodes", unit="ep", enabled=progress
            ) as bar,
        ):
            for rec in stream:
                assert rec is not None
                with deferred():  # a record is written whole and counted
                    _append(fh, rec)
                    records.append(rec)
                if on_record is not None:
                    on_record(rec)
                bar.update(1)
    return records
