"""Who ran into whom: the collisions of an evaluation, row by row (docs/baselines.md).

    python examples/who_hits_whom.py runs/why-baselines

reads ``runs/why-baselines/episodes.jsonl`` (written by ``pioneer eval … --metrics all``) and
prints one Markdown row per scenario and policy: success and collision rates, the shares of
the collisions with a wall, where the robot moved toward the person (robot → person) or stood or
moved away (person → robot), with the exiting or a boarding person, the median time of contact
(the episode's end) and the median robot speed over the last 0.5 s before it, from the
records' per-state positions (``series``). The classification itself is the records' own
(``measures``: ``wall_hit``, ``person_hit``, ``person_role``; docs/metrics.md).
"""

from __future__ import annotations

import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from pioneer.eval.records import read_records

LAST_S = 0.5  # [s] the window of the robot's speed before contact


def _speed_before_end(rec: dict[str, Any]) -> float:
    """Mean robot speed [m/s] over the last ``LAST_S`` of the episode (the step length from the
    record: its time over its states, one series entry per state)."""
    x = np.asarray(rec["series"]["x"], dtype=float)
    y = np.asarray(rec["series"]["y"], dtype=float)
    if len(x) < 2:
        return float("nan")
    dt = float(rec["time_s"]) / (len(x) - 1)
    k = min(round(LAST_S / dt), len(x) - 1)
    return float(np.hypot(x[-1] - x[-1 - k], y[-1] - y[-1 - k]) / (k * dt))


def _share(part: int, whole: int) -> str:
    return f"{100.0 * part / whole:.0f} %" if whole else "–"


def rows(records: list[dict[str, Any]]) -> list[str]:
    """The Markdown rows, one per (scenario, policy)."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = defaultdict(list)
    for rec in records:
        groups[(rec["scenario"], rec["policy"])].append(rec)
    out = []
    for (scenario, policy), recs in sorted(groups.items()):
        hits = [r for r in recs if r["event"] == "collision"]
        m = [r.get("measures") or {} for r in hits]
        n = len(hits)
        wall = sum(1 for q in m if q.get("wall_hit"))
        robot_first = sum(1 for q in m if q.get("person_hit") == "robot-into-person")
        person_first = sum(1 for q in m if q.get("person_hit") == "person-into-robot")
        exiting = sum(1 for q in m if q.get("person_role") == "exiting")
        boarding = sum(1 for q in m if q.get("person_role") == "boarding")
        speeds = [_speed_before_end(r) for r in hits if r.get("series")]
        t = f"{np.median([r['time_s'] for r in hits]):.1f}" if hits else "–"
        v = f"{np.median(speeds):.2f}" if speeds else "–"
        sr = sum(1 for r in recs if r["event"] == "success")
        out.append(
            f"| {scenario} | {policy} | {len(recs)} | {100.0 * sr / len(recs):.0f} | "
            f"{100.0 * n / len(recs):.0f} | {_share(wall, n)} | {_share(robot_first, n)} | "
            f"{_share(person_first, n)} | {_share(exiting, n)} | {_share(boarding, n)} | "
            f"{t} | {v} |"
        )
    return out


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: python examples/who_hits_whom.py RUN_DIR", file=sys.stderr)
        return 2
    path = Path(argv[0]) / "episodes.jsonl"
    if not path.is_file():
        print(
            f"who_hits_whom: expected an evaluation folder with episodes.jsonl, received "
            f"{argv[0]}; fix: pass the --out of `pioneer eval … --metrics all`",
            file=sys.stderr,
        )
        return 2
    print(
        "| scenario | policy | episodes | SR % | collisions % | wall | robot → person | "
        "person → robot | exiting | boarding | median time of contact (s) | robot speed over "
        "the last 0.5 s (median, m/s) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for row in rows(read_records(path)):
        print(row)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
