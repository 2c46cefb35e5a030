"""Writing evaluation summaries: ``summary.json``, ``summary.md`` and ``summary.csv``; the
tables a command prints (``--metrics``); and :func:`summarize_run`, which re-summarises a run
folder from its records alone (``pioneer summarize``)."""

from __future__ import annotations

import sys
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from pioneer.errors import DataError, expect
from pioneer.eval.tables import (
    GROUP_TITLES,
    GROUPS,
    METRIC_SETS,
    csv_table,
    markdown_table,
    measure_table,
    table_rows,
)
from pioneer.io import to_json, write_text_atomic

__all__ = [
    "TableSpec",
    "metric_tables",
    "success_rates",
    "summarize_run",
    "summary_texts",
    "write_summary",
]

# (paper table id, title, scenarios, policies)
TableSpec = tuple[str, str, Sequence[str], Sequence[str]]


def _default_tables(summary: Mapping[str, Mapping[str, Any]]) -> list[TableSpec]:
    """One table of every scenario and policy (paper numbers from Table I where they exist)."""
    all_scen = sorted({v["scenario"] for v in summary.values()})
    all_pols = sorted({v["policy"] for v in summary.values()})
    return [("I", "Navigation performance", all_scen, all_pols)]


def summary_texts(
    summary: Mapping[str, Mapping[str, Any]], tables: Sequence[TableSpec] | None = None
) -> tuple[dict[str, str], str]:
    """The three files' texts (``{"summary.json": …, "summary.md": …, "summary.csv": …}``) and
    the Markdown of the paper-style tables; see :func:`write_summary`."""
    tables = list(tables) if tables is not None else _default_tables(summary)
    md_parts: list[str] = []
    csv_parts: list[str] = []
    for table, title, scenarios, policies in tables:
        rows = table_rows(table, summary, scenarios, policies)
        md_parts.append(markdown_table(rows, title))
        csv = csv_table(rows, table)
        csv_parts.append(csv if not csv_parts else csv.split("\n", 1)[1])
    md = "\n".join(md_parts)
    scen, pols = _order(summary, tables)
    measures = "\n".join(measure_table(summary, scen, pols, [g], GROUP_TITLES[g]) for g in GROUPS)
    texts = {
        "summary.json": to_json(summary, indent=2),
        "summary.md": md + "\n" + measures,
        "summary.csv": "".join(csv_parts),
    }
    return texts, md


def write_summary(
    out_dir: str | Path,
    summary: Mapping[str, Mapping[str, Any]],
    tables: Sequence[TableSpec] | None = None,
) -> str:
    """Write the three summary files (each atomically, all computed before the first is
    written); returns the Markdown of the paper-style tables (``summary.md`` adds one table
    per group of social-navigation measures).

    ``tables`` lists (paper table id, title, scenarios, policies); by default one table of
    every scenario and policy in ``summary`` (paper numbers from Table I where they exist).
    ``summary.json`` holds every metric of :func:`pioneer.eval.metrics.summarize`, and
    ``summary.csv`` every one of them beside the paper's columns.
    """
    out = Path(out_dir)
    texts, md = summary_texts(summary, tables)
    for name, text in texts.items():
        write_text_atomic(out / name, text)
    return md


def _order(
    summary: Mapping[str, Mapping[str, Any]], tables: Sequence[TableSpec]
) -> tuple[list[str], list[str]]:
    """Scenarios and policies in the tables' order, then the rest of ``summary`` sorted."""
    scen = _in_order([sc for t in tables for sc in t[2]], (v["scenario"] for v in summary.values()))
    pols = _in_order([p for t in tables for p in t[3]], (v["policy"] for v in summary.values()))
    return scen, pols


def _in_order(first: Sequence[str], every: Iterable[str]) -> list[str]:
    """``first`` without repeats, then the rest of ``every`` sorted."""
    head = list(dict.fromkeys(first))
    return head + sorted(set(every) - set(head))


def metric_tables(
    summary: Mapping[str, Mapping[str, Any]],
    metrics: str = "paper",
    tables: Sequence[TableSpec] | None = None,
) -> str:
    """The Markdown tables of the column groups ``metrics`` selects
    (:data:`pioneer.eval.tables.METRIC_SETS`: ``paper`` — the paper's table and collisions by
    kind; ``social`` — efficiency, smoothness, social distances and collisions by kind;
    ``all``)."""
    if metrics not in METRIC_SETS:
        raise DataError(expect("--metrics", f"one of {sorted(METRIC_SETS)}", metrics, "pick one"))
    tables = list(tables) if tables is not None else _default_tables(summary)
    scen, pols = _order(summary, tables)
    parts = []
    for group in METRIC_SETS[metrics]:
        if group == "paper":
            parts += [
                markdown_table(table_rows(t, summary, sc, po), title) for t, title, sc, po in tables
            ]
        else:
            parts.append(measure_table(summary, scen, pols, [group], GROUP_TITLES[group]))
    return "\n".join(parts)


def summarize_run(run_dir: str | Path, metrics: str = "paper") -> dict[str, dict[str, Any]]:
    """Re-summarise the run folder ``run_dir`` from its ``episodes.jsonl`` alone and rewrite
    its ``summary.json``, ``summary.md`` and ``summary.csv`` (the tables of ``pioneer eval``);
    returns the summary. The records file is only read. A folder without records, or records
    that cannot be read, raise :class:`DataError` before anything is written. Records written
    before the social-navigation measures (format < 3) leave those columns empty: one note on
    stderr says how many; asked for the social measures (``metrics`` "social" or "all") of a
    run none of whose records holds them, it refuses (:class:`DataError`, nothing written).
    """
    from pioneer.eval.harness import EPISODES_FILE
    from pioneer.eval.records import parse_records, seed_sets, warn_duplicates
    from pioneer.io import run_lock

    run = Path(run_dir)
    fix = "name a folder written by pioneer eval (it holds episodes.jsonl)"
    if not run.is_dir():
        raise DataError(expect("run folder", "an existing folder", str(run), fix))
    path = run / EPISODES_FILE
    if not path.is_file():
        nested = run / "eval" / EPISODES_FILE
        if nested.is_file():  # a `pioneer reproduce` folder: its evaluation is in eval/
            fix = f"name its evaluation folder, {run / 'eval'}"
        raise DataError(expect(f"{run}", f"a run folder with {EPISODES_FILE}", "none", fix))
    with run_lock(run, instead="summarize a copy of the folder"):
        records, whole, duplicates = parse_records(path)
        found = seed_sets(records)
        if len(found) > 1:  # pioneer eval never mixes them in one folder
            raise DataError(
                expect(
                    f"{path}: records",
                    "episodes of one seed set, as pioneer eval writes a folder",
                    f"{' and '.join(found)} episodes",
                    "move one seed set's records (their seed_set field) to a folder of their own",
                )
            )
        warn_duplicates(path, duplicates)
        if path.stat().st_size > sum(len(line.encode()) + 1 for line in whole):
            print(f"pioneer: warning: {path}: an unfinished last line ignored", file=sys.stderr)
        summary = _summarize_records(path, records, metrics)
        write_summary(run, summary)
    old = sum(1 for r in records if not isinstance(r.get("measures"), Mapping))
    if old:
        print(
            f"pioneer: note: {old} of {len(records)} episodes in {path} were recorded before the "
            "social-navigation measures (record format < 3): their measure columns are empty; "
            "re-run the evaluation into a new --out to measure them",
            file=sys.stderr,
        )
    return summary


def _summarize_records(
    path: Path, records: Sequence[Mapping[str, Any]], metrics: str
) -> dict[str, dict[str, Any]]:
    """The summary of a run's ``records`` (read from ``path``); refused without records, and
    for the social measures of records that hold none."""
    from pioneer.eval.metrics import summarize

    if not records:
        raise DataError(
            expect(str(path), "at least one episode record", 0, "run pioneer eval into it first")
        )
    old = sum(1 for r in records if not isinstance(r.get("measures"), Mapping))
    if old == len(records) and metrics in ("social", "all"):
        from pioneer.eval.episode import RECORD_FORMAT

        formats = sorted({int(r.get("format", 1)) for r in records})
        raise DataError(
            expect(
                f"{path}: records",
                f"format {RECORD_FORMAT} (with the social-navigation measures)",
                f"format {', '.join(map(str, formats))} only",
                "re-run the evaluation into a new --out to measure them, or use --metrics paper",
            )
        )
    return summarize(records)


def success_rates(folder: str | Path, seed_set: str = "validation") -> dict[str, float]:
    """Each scenario's share of successful episodes (0–1) in the evaluation folder ``folder``
    (its ``episodes.jsonl``, read only), which must hold one policy's episodes of ``seed_set``:
    e.g. the teacher's success on every training layout, for the fine-tuning's curriculum."""
    from pioneer.eval.harness import EPISODES_FILE
    from pioneer.eval.records import check_seed_set, parse_records

    p = Path(folder) / EPISODES_FILE
    records = parse_records(p)[0] if p.is_file() else []
    if not records:
        raise DataError(
            expect(
                str(folder),
                "a `pioneer eval` output folder with episodes",
                "none" if not p.parent.is_dir() else f"no {EPISODES_FILE} records",
                "evaluate the policy there first (pioneer eval --out …)",
            )
        )
    check_seed_set(p, records, seed_set)
    policies = sorted({str(r["policy"]) for r in records})
    if len(policies) != 1:
        raise DataError(
            expect(
                f"{p}: policies",
                "one policy's episodes",
                ", ".join(policies),
                "evaluate that policy alone into its own --out",
            )
        )
    won: dict[str, list[bool]] = {}
    for r in records:
        won.setdefault(str(r["scenario"]), []).append(r["event"] == "success")
    return {name: sum(w) / len(w) for name, w in sorted(won.items())}
