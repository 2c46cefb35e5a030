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

A run folder cannot lie about what made its records. Every record carries ``made_by`` (the
policy's resolved parameters and the content hash of every file it loaded) and
``manifest.json`` holds the same per row and scenario (:mod:`pioneer.eval.manifest`); a run
whose row differs from the one of the same label in the folder is refused before it writes
anything (``overwrite=True`` deletes the folder's records and starts over). One run writes
to a folder at a time (its lock file, :func:`pioneer.io.run_lock`), and reading the records
counts each episode once. Every input is checked — every policy built, in the workers —
before the folder is created: a refused run leaves the file system as it found it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import time
from collections.abc import Callable, Generator, Mapping, Sequence
from pathlib import Path
from typing import Any

from pioneer.config import MAX_EPISODES, check_count
from pioneer.errors import ConfigError, DataError, expect
from pioneer.eval.manifest import (
    MANIFEST_FILE,
    MadeBy,
    check_made_by,
    read_manifest,
    write_manifest,
)
from pioneer.eval.ray_backend import ray_stream
from pioneer.eval.records import (
    append_record,
    check_seed_set,
    key_of,
    parse_records,
    read_records,
)
from pioneer.interrupt import deferred, kept
from pioneer.io import (
    check_name,
    check_regular_target,
    file_record,
    output_dir_kind,
    read_text_bounded,
    run_lock,
    to_json,
)
from pioneer.parallel import worker_count
from pioneer.progress import progress_bar
from pioneer.seeds import SEED_SETS
from pioneer.seeds import episode_seed as _seed_of

__all__ = [
    "PolicySpec",
    "Task",
    "episode_seed",
    "evaluate",
    "made_by",
    "made_by_record",
    "read_records",
    "run_task",
]

EPISODES_FILE = "episodes.jsonl"
SCENARIOS_FILE = "scenarios.json"
# What --overwrite deletes: the run's records and what describes them (the summaries too).
RUN_FILES = (
    EPISODES_FILE,
    MANIFEST_FILE,
    SCENARIOS_FILE,
    "summary.json",
    "summary.md",
    "summary.csv",
)


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
        if label != "":
            check_name(f"policy {name!r} label", str(label))
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
    made_by: str = ""  # what makes its row (JSON of made_by()), copied into its record

    @property
    def key(self) -> tuple[str, str, int, int]:
        """Identity of the episode in ``episodes.jsonl``."""
        return (self.scenario, self.policy.row, self.seed, self.trial)


def episode_seed(scenario: str, seed: int, trial: int, seed_set: str = "evaluation") -> int:
    """The environment seed of trial ``trial`` of seed ``seed`` in ``scenario`` (deterministic;
    the evaluation or validation seeds of :mod:`pioneer.seeds`)."""
    return _seed_of(seed_set, scenario, seed, trial)


# ------------------------------------------------------------------------------ worker side
# Built policies, by what they are made of: a checkpoint changed in place between two runs in
# one process (a notebook, a Ray worker) is built again, never served from the cache.
_POLICY_CACHE: dict[tuple[str, PolicySpec, str], Any] = {}


def _make_policy(spec: PolicySpec, scenario: str, made: str = "") -> Any:
    key = (scenario, spec, made)
    if key not in _POLICY_CACHE:
        from pioneer.control.registry import build_policy

        pol = build_policy(spec.name, scenario, **dict(spec.kwargs))
        if spec.label:
            pol.name = spec.label
        _POLICY_CACHE[key] = pol
    return _POLICY_CACHE[key]


def made_by(spec: PolicySpec, scenario: str) -> dict[str, Any]:
    """What makes ``spec``'s row in ``scenario``, as JSON data: its resolved parameters and the
    files it loads (hashed now), with the scenario file of a variant."""
    from pioneer.control.registry import resolve_policy

    return made_by_record(resolve_policy(spec.name, scenario, dict(spec.kwargs)), scenario)


def made_by_record(made: Mapping[str, Any], scenario: str) -> dict[str, Any]:
    """A record's ``made_by`` from ``made`` = ``{"policy", "params", "files"}`` (as
    :func:`pioneer.control.registry.resolve_policy` gives it, or the same for a policy built
    outside the registry, the files as :func:`pioneer.io.file_record`): with the scenario file
    of a variant added, as JSON data exactly as it reads back from a file."""
    from pioneer.sim.scenarios import scenario_source

    out = {**made, "files": dict(made["files"])}
    source = scenario_source(scenario)
    if source is not None:
        out["files"]["scenario_file"] = file_record(source)
    return dict(json.loads(to_json(out)))


def _worker_init() -> None:
    from threadpoolctl import threadpool_limits

    threadpool_limits(1, user_api="blas")


def run_task(task: Task) -> dict[str, Any]:
    """Run one episode and return its JSON-able record."""
    from pioneer.eval.episode import run_episode

    policy = _make_policy(task.policy, task.scenario, task.made_by)
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
    if task.made_by:
        d["made_by"] = json.loads(task.made_by)
    return d


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


def build_check(pair: tuple[str, PolicySpec]) -> dict[str, Any]:
    """Build the policy of ``pair`` = (scenario, spec) in this process (kept in its cache) and
    return what makes it (:func:`made_by`); any error it raises surfaces before the first
    episode runs, and before the run folder is created."""
    scenario, spec = pair
    made = made_by(spec, scenario)
    _make_policy(spec, scenario, to_json(made))
    return made


# A stream first yields what makes every (scenario, row) of the run, once every policy is
# built (a policy that cannot be built fails the run before anything is written); then it runs
# ``tasks`` — a list the caller fills after that first yield, holding the folder's lock — and
# yields the records as the episodes finish.
def _local(
    pairs: list[tuple[str, PolicySpec]], tasks: list[Task], workers: int
) -> Generator[Any, None, None]:
    keys = [(sc, spec.row) for sc, spec in pairs]
    if workers <= 1:
        yield dict(zip(keys, map(build_check, pairs), strict=True))
        for t in tasks:
            yield run_task(t)
        return
    from pioneer.parallel import bounded_map, spawn_pool

    with spawn_pool(workers, _worker_init) as pool:
        yield dict(zip(keys, pool.map(build_check, pairs), strict=True))
        yield from bounded_map(pool, run_task, tasks, 4 * workers)


def _check_shipped_parts(scenarios: Sequence[str], policies: Sequence[PolicySpec]) -> None:
    """Fail before running anything when a policy would load a part the scenario does not
    have, or a given reward model that does not fit it — each registry entry's light check,
    without building the policies (no torch)."""
    from pioneer.control.registry import check_parts

    for sc in scenarios:
        for spec in policies:
            check_parts(spec.name, sc, dict(spec.kwargs))


def _pinned_scenarios(out: Path, names: Sequence[str]) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(recorded, mine)``: the scenario definitions in ``out/scenarios.json`` and those of
    ``names`` now; a changed one is refused (reads only)."""
    from pioneer.sim.scenarios import pin_scenario
    from pioneer.sim.scenarios.registry import MAX_SCENARIO_FILE_BYTES

    p = out / SCENARIOS_FILE
    try:
        known: dict[str, Any] = (
            json.loads(read_text_bounded(p, "scenarios file", MAX_SCENARIO_FILE_BYTES))
            if p.exists()
            else {}
        )
    except json.JSONDecodeError as exc:
        raise DataError(
            expect(str(p), "valid JSON", exc.msg, "delete the file (it is rewritten)")
        ) from exc
    return known, {n: pin_scenario(n, known.get(n), str(out)) for n in names}


def _record_scenarios(out: Path, names: Sequence[str]) -> None:
    """Add the scenarios' full configs to ``out/scenarios.json``; refuse a changed one."""
    from pioneer.io import write_text_atomic

    known, mine = _pinned_scenarios(out, names)
    if any(n not in known for n in mine):
        write_text_atomic(out / SCENARIOS_FILE, to_json({**known, **mine}, indent=1) + "\n")


def _check_folder(
    out: Path,
    scenarios: Sequence[str],
    seed_set: str,
    made: MadeBy,
    records: Sequence[Mapping[str, Any]],
) -> None:
    """Everything a resume must agree with in ``out``: the seed set of its records, the
    scenarios' definitions and what made its rows (reads only)."""
    check_seed_set(out / EPISODES_FILE, records, seed_set)
    _pinned_scenarios(out, scenarios)
    check_made_by(out, made, read_manifest(out), records)


def _start_over(out: Path) -> None:
    """Delete the run's records and what describes them (``overwrite``), nothing else."""
    for name in RUN_FILES:
        with contextlib.suppress(FileNotFoundError):
            (out / name).unlink()


def _check_rows(policies: Sequence[PolicySpec]) -> None:
    for spec in policies:
        if spec.label:
            check_name(f"policy {spec.name!r} label", spec.label)
    rows = [spec.row for spec in policies]
    twice = sorted({r for r in rows if rows.count(r) > 1})
    if twice:
        raise ConfigError(
            expect("policy rows", "distinct labels", twice, "add label=NAME to the repeated policy")
        )


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
    overwrite: bool = False,
) -> list[dict[str, Any]]:
    """Run (or resume) the evaluation on the ``seed_set`` episodes (evaluation seeds, or
    validation seeds for choices and tuning); returns every record (old and new).

    Every input is checked and every policy built before ``out_dir`` is created or changed;
    then the run holds the folder's lock (:func:`pioneer.io.run_lock`). Resuming a row made
    otherwise than the folder's row of the same label is refused (module docstring);
    ``overwrite`` deletes the folder's records, manifest and summaries first and starts over.
    """
    if seeds < 1 or trials < 1:
        raise ConfigError(
            expect(
                "seeds/trials",
                "integers >= 1",
                (seeds, trials),
                "set seeds and trials (--seeds, --trials) >= 1",
            )
        )
    check_count(
        "episodes (scenarios × policies × --seeds × --trials)",
        len(set(scenarios)) * len(policies) * seeds * trials,
        MAX_EPISODES,
        "ask for fewer --seeds or --trials, or split the run over several --out folders",
    )
    if seed_set not in SEED_SETS:
        raise ConfigError(expect("seed set", f"one of {SEED_SETS}", seed_set, "pick one"))
    if backend not in ("process", "ray"):
        raise ConfigError(expect("backend", "'process' or 'ray'", backend, "pick one"))
    from pioneer.control.registry import check_policy_name
    from pioneer.sim.scenarios import get_scenario

    # fail before running anything, not hours in; each scenario by its own name, as its records
    # carry it (and its episode seeds derive from it)
    scenarios = list(dict.fromkeys(get_scenario(sc).name for sc in scenarios))
    for spec in policies:
        check_policy_name(spec.name)
    _check_rows(policies)
    _check_shipped_parts(scenarios, policies)
    out = output_dir_kind(out_dir)  # a file there is refused; nothing is created yet
    path = out / EPISODES_FILE
    records: list[dict[str, Any]] = [] if overwrite else parse_records(path)[0]
    if not overwrite:  # a folder that cannot be resumed is refused before any policy is built
        check_seed_set(path, records, seed_set)
        _pinned_scenarios(out, scenarios)
    every = _tasks(scenarios, policies, seeds, trials, seed_set)
    total = len({key_of(r) for r in records} | {t.key for t in every})
    pairs = list(dict.fromkeys((t.scenario, t.policy) for t in every))
    todo: list[Task] = []  # filled under the folder's lock, once every policy is built
    n_workers = worker_count(workers)
    stream = (
        ray_stream(pairs, todo, ray_address, run_task, build_check)
        if backend == "ray"
        else _local(pairs, todo, n_workers)
    )
    with (
        kept(lambda: f"{len(records)} of {total} episodes kept in {path}"),
        contextlib.closing(stream),  # its pool stops with the run, whatever stops the run
    ):
        made: MadeBy = next(stream)  # every policy built, before anything is written
        if not overwrite:
            check_made_by(out, made, read_manifest(out), records)
        with run_lock(out):
            if overwrite:
                _start_over(out)
            records = read_records(path)  # again, holding the lock: the folder is ours now
            _check_folder(out, scenarios, seed_set, made, records)
            _record_scenarios(out, scenarios)
            write_manifest(out, read_manifest(out), made)
            done = {key_of(r) for r in records}
            made_json = {pair: to_json(m) for pair, m in made.items()}
            todo.extend(
                dataclasses.replace(t, made_by=made_json[t.scenario, t.policy.row])
                for t in every
                if t.key not in done
            )
            total = len(done) + len(todo)
            with (
                open(check_regular_target(path), "a") as fh,
                progress_bar(
                    total=total, initial=len(done), desc="episodes", unit="ep", enabled=progress
                ) as bar,
            ):
                for rec in stream:
                    with deferred():  # a record is written whole and counted
                        append_record(fh, rec)
                        records.append(rec)
                    if on_record is not None:
                        on_record(rec)
                    bar.update(1)
    return records
