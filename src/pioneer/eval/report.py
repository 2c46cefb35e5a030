"""Writing evaluation summaries: ``summary.json``, ``summary.md`` and ``summary.csv``."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from pioneer.eval.tables import (
    GROUP_TITLES,
    GROUPS,
    csv_table,
    markdown_table,
    measure_table,
    table_rows,
)
from pioneer.io import to_json, write_text_atomic

__all__ = ["write_summary"]


def write_summary(
    out_dir: str | Path,
    summary: Mapping[str, Mapping[str, Any]],
    tables: Sequence[tuple[str, str, Sequence[str], Sequence[str]]] | None = None,
) -> str:
    """Write the three summary files (atomically); returns the Markdown of the paper-style
    tables (``summary.md`` adds one table per group of social-navigation measures).

    ``tables`` lists (paper table id, title, scenarios, policies); by default one table of
    every scenario and policy in ``summary`` (paper numbers from Table I where they exist).
    ``summary.json`` holds every metric of :func:`pioneer.eval.metrics.summarize`, and
    ``summary.csv`` every one of them beside the paper's columns.
    """
    out = Path(out_dir)
    if tables is None:
        all_scen = sorted({v["scenario"] for v in summary.values()})
        all_pols = sorted({v["policy"] for v in summary.values()})
        tables = [("I", "Navigation performance", all_scen, all_pols)]
    md_parts: list[str] = []
    csv_parts: list[str] = []
    for table, title, scenarios, policies in tables:
        rows = table_rows(table, summary, scenarios, policies)
        md_parts.append(markdown_table(rows, title))
        csv = csv_table(rows, table)
        csv_parts.append(csv if not csv_parts else csv.split("\n", 1)[1])
    md = "\n".join(md_parts)
    scen = _in_order([sc for t in tables for sc in t[2]], (v["scenario"] for v in summary.values()))
    pols = _in_order([p for t in tables for p in t[3]], (v["policy"] for v in summary.values()))
    measures = "\n".join(measure_table(summary, scen, pols, [g], GROUP_TITLES[g]) for g in GROUPS)
    write_text_atomic(out / "summary.json", to_json(summary, indent=2))
    write_text_atomic(out / "summary.md", md + "\n" + measures)
    write_text_atomic(out / "summary.csv", "".join(csv_parts))
    return md


def _in_order(first: Sequence[str], every: Iterable[str]) -> list[str]:
    """``first`` without repeats, then the rest of ``every`` sorted."""
    head = list(dict.fromkeys(first))
    return head + sorted(set(every) - set(head))
