"""Writing evaluation summaries: ``summary.json``, ``summary.md`` and ``summary.csv``."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from pioneer.eval.tables import csv_table, markdown_table, table_rows
from pioneer.io import to_json, write_text_atomic

__all__ = ["write_summary"]


def write_summary(
    out_dir: str | Path,
    summary: Mapping[str, Mapping[str, Any]],
    tables: Sequence[tuple[str, str, Sequence[str], Sequence[str]]] | None = None,
) -> str:
    """Write the three summary files (atomically); returns the Markdown.

    ``tables`` lists (paper table id, title, scenarios, policies); by default one table of
    every scenario and policy in ``summary`` (paper numbers from Table I where they exist).
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
    write_text_atomic(out / "summary.json", to_json(summary, indent=2))
    write_text_atomic(out / "summary.md", md)
    write_text_atomic(out / "summary.csv", "".join(csv_parts))
    return md
