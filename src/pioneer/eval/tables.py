"""Tables laid out like the paper's, with the paper's numbers beside ours (Markdown and CSV),
and the tables of the social-navigation measures (docs/metrics.md) by group of columns."""

from __future__ import annotations

import csv
import dataclasses
import io
import math
from collections.abc import Mapping, Sequence
from typing import Any

from pioneer.eval.metrics import MEASURES

__all__ = [
    "GROUPS",
    "METRIC_SETS",
    "PAPER",
    "Column",
    "TableRow",
    "csv_table",
    "interval_note",
    "markdown_table",
    "measure_table",
    "table_rows",
]

# Paper values: (SR %, TT s, PL m) per (table, scenario, row label). Tables I–III. The
# paper's teacher and its ablations are the rows `teacher-paper*` (no soft margins, the stop
# fallback); our `teacher*` rows deviate from it (docs/teacher.md) and carry no paper value.
PAPER: dict[tuple[str, str, str], tuple[float, float, float]] = {
    ("I", "hr-rl", "teacher-paper"): (99.4, 12.24, 3.74),
    ("I", "hr-rl", "cvar-bf"): (72.8, 12.82, 4.65),
    ("I", "hr-rl", "crowdnav++"): (78.6, 17.52, 4.93),
    ("I", "hl-rr", "teacher-paper"): (99.6, 12.94, 3.88),
    ("I", "hl-rr", "cvar-bf"): (71.4, 12.82, 4.75),
    ("I", "hl-rr", "crowdnav++"): (64.8, 9.71, 4.63),
    ("II", "hr-rl", "teacher-paper-no-density"): (83.0, 13.61, 4.55),
    ("II", "hr-rl", "teacher-paper-no-goal"): (99.4, 15.70, 3.79),
    ("II", "hr-rl", "teacher-paper-no-obstacle"): (94.8, 11.64, 3.72),
    ("II", "hl-rr", "teacher-paper-no-density"): (79.8, 13.37, 4.54),
    ("II", "hl-rr", "teacher-paper-no-goal"): (99.4, 16.48, 3.92),
    ("II", "hl-rr", "teacher-paper-no-obstacle"): (98.8, 12.33, 3.86),
    ("III", "hr-rl", "student-mdn"): (98.0, 13.67, 4.62),
    ("III", "hr-rl", "student-mlp"): (95.8, 15.02, 6.49),
    ("III", "hl-rr", "student-mdn"): (100.0, 14.16, 4.70),
    ("III", "hl-rr", "student-mlp"): (98.8, 15.29, 4.78),
}

TableRow = dict[str, Any]


def _fmt(cell: Mapping[str, float], digits: int) -> str:
    """``mean ± half`` for a symmetric interval, ``mean [lo, hi]`` for an asymmetric one (a
    Wilson interval, or one clipped to its quantity's range), ``mean`` for none."""
    mean = cell.get("mean")
    if mean is None or not math.isfinite(mean):
        return "–"
    lo, hi = cell.get("lo", math.nan), cell.get("hi", math.nan)
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi - lo <= 0.0:
        return f"{mean:.{digits}f}"
    if abs((mean - lo) - (hi - mean)) < 0.5 * 10.0**-digits:
        return f"{mean:.{digits}f} ± {(hi - lo) / 2:.{digits}f}"
    return f"{mean:.{digits}f} [{lo:.{digits}f}, {hi:.{digits}f}]"


def interval_note(rows: Sequence[Mapping[str, Any]]) -> str:
    """One sentence saying over what the table's intervals were computed."""
    kinds = {(r["interval"], r["seeds"]) for r in rows}
    over_seeds = {n for k, n in kinds if k == "seeds"}
    over_episodes = {n for k, n in kinds if k == "episodes"}
    parts = []
    if over_seeds:
        n = "/".join(str(x) for x in sorted(over_seeds))
        parts.append(f"95 % CI over {n} seeds (Student t)")
    if over_episodes:
        n = "/".join(str(x) for x in sorted(over_episodes))
        parts.append(
            f"95 % CI over episodes ({n} seed{'s' if over_episodes != {1} else ''}, too few "
            f"for an interval over seeds: Wilson score for rates, Student t for times and "
            f"lengths)"
        )
    return (
        "Mean ± half-width, or mean [low, high] where the interval is asymmetric; "
        + "; ".join(parts)
        + "."
    )


def table_rows(
    table: str,
    summary: Mapping[str, Mapping[str, Any]],
    scenarios: Sequence[str],
    policies: Sequence[str],
) -> list[TableRow]:
    """One row per (scenario, policy) present in ``summary``, with our and the paper's values."""
    rows: list[TableRow] = []
    for sc in scenarios:
        for pol in policies:
            s = summary.get(f"{sc}/{pol}")
            if s is None:
                continue
            paper = PAPER.get((table, sc, pol))
            rows.append(
                {
                    "scenario": sc,
                    "method": pol,
                    "episodes": s["episodes"],
                    "seeds": s["seeds"],
                    "interval": s.get("interval", "seeds"),
                    "sr": s["success_rate"],
                    "tt": s["time_mean_s"],
                    "pl": s["path_length_mean_m"],
                    "collision": s["collision_rate"],
                    "timeout": s["timeout_rate"],
                    "min_clear": s["min_gap_m"],
                    "paper": paper,
                    "entry": s,  # every metric of the row (the CSV's measure columns)
                }
            )
    return rows


def markdown_table(rows: Sequence[TableRow], title: str) -> str:
    """A Markdown table: SR, TT, PL with 95 % intervals (:func:`interval_note` says over what)
    next to the paper's values."""
    head = [
        "Scenario",
        "Method",
        "SR ↑ (%)",
        "TT ↓ (s)",
        "PL ↓ (m)",
        "paper SR / TT / PL",
        "collisions (%)",
        "timeouts (%)",
        "min gap (m)",
        "episodes",
    ]
    out = [f"**{title}**", ""]
    if rows:
        out += [interval_note(rows), ""]
    out += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        p = r["paper"]
        cells = [
            r["scenario"].upper(),
            r["method"],
            _fmt(r["sr"], 1),
            _fmt(r["tt"], 2),
            _fmt(r["pl"], 2),
            f"{p[0]:.1f} / {p[1]:.2f} / {p[2]:.2f}" if p else "–",
            _fmt(r["collision"], 1),
            _fmt(r["timeout"], 1),
            _fmt(r["min_clear"], 2),
            str(r["episodes"]),
        ]
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


def csv_table(rows: Sequence[TableRow], table: str) -> str:
    """CSV with one line per row: our means, CI half-widths and the paper's values."""
    buf = io.StringIO()
    w = csv.writer(buf)
    extra = [f"{k}{part}" for k in MEASURES for part in ("", "_ci95", "_lo", "_hi")]
    w.writerow(
        [
            "table",
            "scenario",
            "method",
            "episodes",
            "sr",
            "sr_ci95",
            "sr_lo",
            "sr_hi",
            "interval",
            "tt_s",
            "tt_ci95",
            "pl_m",
            "pl_ci95",
            "collision_rate",
            "timeout_rate",
            "min_gap_m",
            "paper_sr",
            "paper_tt_s",
            "paper_pl_m",
            "measured",
            *extra,
        ]
    )
    for r in rows:
        p = r["paper"] or (None, None, None)
        w.writerow(
            [
                table,
                r["scenario"],
                r["method"],
                r["episodes"],
                r["sr"]["mean"],
                r["sr"]["ci95"],
                r["sr"].get("lo"),
                r["sr"].get("hi"),
                r["interval"],
                r["tt"]["mean"],
                r["tt"]["ci95"],
                r["pl"]["mean"],
                r["pl"]["ci95"],
                r["collision"]["mean"],
                r["timeout"]["mean"],
                r["min_clear"]["mean"],
                *p,
                r["entry"].get("measured", ""),
                *_measure_cells(r["entry"]),
            ]
        )
    return buf.getvalue()


def _measure_cells(entry: Mapping[str, Any]) -> list[Any]:
    """mean, ci95, lo, hi of every measure (empty where the entry has none)."""
    cells: list[Any] = []
    for k in MEASURES:
        cell = entry.get(k) or {}
        cells += [cell.get(part, "") for part in ("mean", "ci95", "lo", "hi")]
    return cells


@dataclasses.dataclass(frozen=True)
class Column:
    """A column of a measure table: the summary key, its header and how it is printed."""

    key: str
    head: str
    digits: int
    scale: float = 1.0  # shares of time [0, 1] are printed in %


# The columns of each group (docs/metrics.md); ↑: higher is better, ↓: lower is better.
GROUPS: dict[str, tuple[Column, ...]] = {
    "collisions": (
        Column("collision_rate", "all ↓ (%)", 1),
        Column("wall_collision_rate", "wall ↓ (%)", 1),
        Column("robot_into_person_rate", "robot → person ↓ (%)", 1),
        Column("person_into_robot_rate", "person → robot ↓ (%)", 1),
        Column("exiting_collision_rate", "exiting person ↓ (%)", 1),
        Column("boarding_collision_rate", "boarding person ↓ (%)", 1),
        Column("other_person_collision_rate", "other person ↓ (%)", 1),
    ),
    "efficiency": (
        Column("spl", "SPL ↑", 3),
        Column("path_efficiency", "path eff. ↑", 3),
        Column("time_still_s", "still ↓ (s)", 2),
        Column("stall_rate", "stalled ↓ (%)", 1),
        Column("blocked_timeout_rate", "shut out ↓ (%)", 1),
    ),
    "smoothness": (
        Column("accel_mean_m_s2", "mean abs(a) ↓ (m/s²)", 3),
        Column("accel_max_m_s2", "max abs(a) ↓ (m/s²)", 2),
        Column("jerk_mean_m_s3", "mean abs(jerk) ↓ (m/s³)", 2),
        Column("jerk_max_m_s3", "max abs(jerk) ↓ (m/s³)", 1),
        Column("heading_change_rad", "heading change ↓ (rad)", 2),
        Column("path_irregularity_rad_m", "irregularity ↓ (rad/m)", 3),
    ),
    "social": (
        Column("min_gap_m", "min gap ↑ (m)", 2),
        Column("min_clearance_m", "min clearance ↑ (m)", 2),
        Column("intimate_share", "intimate ↓ (% time)", 1, 100.0),
        Column("personal_share", "personal (% time)", 1, 100.0),
        Column("social_share", "social (% time)", 1, 100.0),
        Column("space_compliance", "space compliance ↑ (%)", 1, 100.0),
        Column("min_ttc_s", "min TTC ↑ (s)", 2),
    ),
}
GROUP_TITLES = {
    "collisions": "Collisions by kind (% of episodes)",
    "efficiency": "Efficiency",
    "smoothness": "Smoothness",
    "social": "Social distances",
}
# What ``pioneer eval --metrics`` prints: "paper" is the paper's table (SR, TT, PL, …).
METRIC_SETS: dict[str, tuple[str, ...]] = {
    "paper": ("paper", "collisions"),
    "social": ("efficiency", "smoothness", "social", "collisions"),
    "all": ("paper", "collisions", "efficiency", "smoothness", "social"),
}


def _scaled(cell: Mapping[str, float], scale: float) -> dict[str, float]:
    return {k: v * scale if isinstance(v, int | float) else v for k, v in cell.items()}


def measure_table(
    summary: Mapping[str, Mapping[str, Any]],
    scenarios: Sequence[str],
    policies: Sequence[str],
    groups: Sequence[str],
    title: str,
) -> str:
    """A Markdown table of the columns of ``groups`` (:data:`GROUPS`), one row per (scenario,
    policy) in ``summary``, each cell with its 95 % interval (:func:`interval_note`)."""
    cols = [c for g in groups for c in GROUPS[g]]
    entries = [
        (sc, pol, summary[f"{sc}/{pol}"])
        for sc in scenarios
        for pol in policies
        if f"{sc}/{pol}" in summary
    ]
    head = ["Scenario", "Method", *(c.head for c in cols), "episodes measured"]
    out = [f"**{title}**", ""]
    if entries:
        out += [interval_note([e for _, _, e in entries]), ""]
    unmeasured = sum(
        int(e["episodes"]) - int(e.get("measured", e["episodes"])) for *_, e in entries
    )
    if unmeasured:
        out += [
            f"{unmeasured} episode(s) were recorded before these measures (record format < 3): "
            "their cells are left out (– where a row has none); re-run the evaluation into a "
            "new --out to measure them.",
            "",
        ]
    out += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for sc, pol, e in entries:
        cells = [sc.upper(), pol]
        cells += [_fmt(_scaled(e.get(c.key, {}), c.scale), c.digits) for c in cols]
        cells.append(str(e.get("measured", e["episodes"])))
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"
