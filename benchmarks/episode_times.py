"""The seconds per episode that ``pioneer reproduce`` announces its expected time from.

After a paper-profile run on the reference machine (docs/performance.md)::

    pioneer reproduce --profile paper --out runs/paper --workers 2
    .venv/bin/python benchmarks/episode_times.py runs/paper

writes every policy row's mean wall time of one episode (over both scenarios and every
invocation of a resumed run) into ``src/pioneer/data/episode_times.json``, with the date of
the run, the machine it ran on and that machine's speed (``probe_s``: the time probe of
:mod:`pioneer.experiments.timing`, measured here, on the machine of the run, by this script),
which the announced time of any other machine is scaled by. Rows the run did not evaluate
keep their earlier figures. ``--scale F`` divides the measured times by F, for a run that
other work on the machine slowed F times (the probe, timed by its fastest rounds, measures
the CPU itself; say why with ``--note``); the notes of the earlier file are replaced.
``--rows R …`` re-measures only those rows; ``--relative-to ROW`` takes the scale from the
run's ROW against the file's (for new rows measured on a busy machine of the file's CPU
model beside a row the file holds; the file keeps its date and machine, a note says so).
``--round-robin N --rows R …`` times the rows in this process instead, in turn with
``--references`` on N validation episodes per scenario, by CPU time scaled to the
references' stored times (for a host too busy for a run's wall times to mean anything).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import sys
from pathlib import Path
from typing import Any

# Run as a script, sys.path[0] is this file's folder: replace it with the repository, so the
# benchmarks import as one package.
if sys.path and Path(sys.path[0] or ".").resolve() == Path(__file__).resolve().parent:
    sys.path.pop(0)
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pioneer.data import EPISODE_TIMES
from pioneer.eval.harness import EPISODES_FILE, read_records
from pioneer.experiments.timing import EpisodeTimes, load_episode_times, probe_seconds, row_times
from pioneer.io import write_text_atomic


def machine_line() -> str:
    """One line naming the machine this runs on (what ``make bench`` records, abridged)."""
    from benchmarks.results import machine_info

    m = machine_info()
    simd = "+".join(m["simd"]) or "no SIMD"
    return (
        f"{m['cpu_model'] or m['machine']} ({m['llvm_host_cpu']}: {simd}), "
        f"{m['cpu_count']} CPUs, {m['platform']}, Python {m['python']}, numpy {m['numpy']}, "
        f"numba {m['numba']}"
    )


def measured(
    records: list[dict[str, Any]], scale: float = 1.0, digits: int = 3
) -> dict[str, float]:
    """Mean wall time [s] of one episode per policy row, divided by ``scale``."""
    return {
        row: round(sec / n / scale, digits) for row, (n, sec) in row_times(records).items() if n
    }


def updated(
    old: EpisodeTimes,
    records: list[dict[str, Any]],
    when: str,
    machine: str,
    scale: float = 1.0,
    notes: tuple[str, ...] = (),
    probe_s: float | None = None,
) -> EpisodeTimes:
    """``old`` with the rows of ``records`` re-measured; the others are kept, and a note
    says so. ``notes`` replace the old ones; ``probe_s`` (this machine's probe time) replaces
    the old one when given."""
    new = measured(records, scale)
    kept = sorted(set(old.episode_s) - set(new))
    if kept:
        notes = (*notes, f"{', '.join(kept)}: not in this run, kept from {old.measured}.")
    source = (
        "pioneer reproduce: per policy, the mean wall time of one episode over its scenarios "
        "(the report's 'Where the time went')"
    )
    if scale != 1.0:
        source += f", divided by {scale:g} (a run that other work slowed that much)"
    return dataclasses.replace(
        old,
        episode_s={**old.episode_s, **new},
        measured=when,
        machine=machine,
        source=source,
        notes=notes,
        probe_s=old.probe_s if probe_s is None else probe_s,
    )


def relative_scale(records: list[dict[str, Any]], old: EpisodeTimes, row: str) -> float:
    """How much slower this run's ``row`` ran than ``old`` stores it: the scale that carries
    the run's other rows (run beside it, under the same load) to ``old``'s machine."""
    new = measured(records, digits=9)
    if row not in new or row not in old.episode_s:
        raise SystemExit(f"episode_times.py: --relative-to {row}: not in the run and the file")
    return new[row] / old.episode_s[row]


def round_robin(
    old: EpisodeTimes, rows: list[str], references: list[str], n: int
) -> list[dict[str, Any]]:
    """Records of ``rows`` timed in-process on a busy machine of the file's CPU model: each
    row's and each reference row's CPU time per episode, the rows taken in turn on the same
    ``n`` validation episodes per scenario (one BLAS thread), scaled by the references'
    stored times over their CPU times here (a 2-worker run's wall time against one process's
    CPU time)."""
    import time

    from pioneer.control.registry import build_policy
    from pioneer.eval.episode import run_episode
    from pioneer.seeds import validation_seed

    every = [*references, *rows]
    scenarios = ("hr-rl", "hl-rr")
    policies = {(sc, r): build_policy(r, sc) for sc in scenarios for r in every}
    cpu = dict.fromkeys(every, 0.0)
    for k in range(n):
        for sc in scenarios:
            seed = validation_seed("episode-times", sc, k)
            for r in every:
                t0 = time.process_time()
                run_episode(sc, policies[(sc, r)], seed)
                cpu[r] += (time.process_time() - t0) / (n * len(scenarios))
    factor = sum(old.of(r) for r in references) / sum(cpu[r] for r in references)
    return [{"policy": r, "wall_time_s": cpu[r] * factor} for r in rows]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("run", type=Path, help="the --out folder of a pioneer reproduce run")
    parser.add_argument(
        "--output", type=Path, default=EPISODE_TIMES, help="episode-times JSON (%(default)s)"
    )
    parser.add_argument("--scale", type=float, default=1.0, help="divide the times by this")
    parser.add_argument("--note", action="append", default=[], help="a note to store (repeat)")
    parser.add_argument("--rows", nargs="+", help="re-measure only these rows")
    parser.add_argument(
        "--relative-to",
        metavar="ROW",
        help="scale by this run's ROW against the file's (a busy run on the file's CPU model)",
    )
    parser.add_argument(
        "--round-robin",
        type=int,
        metavar="N",
        help="time --rows in-process in turn with --references on N episodes per scenario",
    )
    parser.add_argument("--references", nargs="+", default=["teacher", "teacher-no-density"])
    args = parser.parse_args(argv)
    if args.round_robin and not args.rows:
        parser.error("--round-robin needs --rows")
    if not args.scale > 0:
        parser.error("--scale must be > 0")
    episodes = args.run / "eval" / EPISODES_FILE
    records = read_records(episodes)
    if not records:
        parser.error(f"no episode records in {episodes}")
    old = load_episode_times(args.output)
    when = datetime.datetime.fromtimestamp(episodes.stat().st_mtime, datetime.UTC).date()
    scale, machine, notes = args.scale, machine_line(), tuple(args.note)
    if args.relative_to:
        scale = relative_scale(records, old, args.relative_to)
        notes = (
            *notes,
            f"{', '.join(args.rows or ['every row'])}: from a run on {when}, "
            f"scaled by its {args.relative_to} against this file's ({scale:.2f}×)",
        )
    if args.round_robin:
        records = round_robin(old, args.rows, args.references, args.round_robin)
        notes = (
            *notes,
            f"{', '.join(args.rows)}: CPU time on {args.round_robin} validation "
            f"episodes per scenario, taken in turn with {', '.join(args.references)} on a "
            "busy host of the file's CPU model, scaled by theirs to the file's times",
        )
    if args.rows:
        records = [r for r in records if r["policy"] in set(args.rows)]
    scaled_to_file = bool(args.relative_to or args.round_robin)  # in the file machine's terms
    probe = None if scaled_to_file else probe_seconds()  # None: the file's probe stays
    times = updated(old, records, when.isoformat(), machine, scale, notes, probe)
    if scaled_to_file:  # the file keeps its machine, date and speed
        times = dataclasses.replace(times, measured=old.measured, machine=old.machine)
    write_text_atomic(args.output, json.dumps(times.to_dict(), indent=2) + "\n")
    for row in sorted(measured(records)):
        print(f"{row:24s} {times.of(row):.3f} s")
    print(f"wrote {args.output} (measured {times.measured}, probe {times.probe_s:.5f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
