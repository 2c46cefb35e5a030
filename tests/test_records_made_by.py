"""Every ``episodes.jsonl`` any command writes names what made each record (``made_by``):
the evaluation's (``pioneer eval``, ``pioneer reproduce``), ``pioneer calibrate``'s and the
blind-sector study's. A module that starts writing such a file fails the first test until it
is listed here with a run of it in the second."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import pytest

import pioneer

SRC = Path(pioneer.__file__).parent
RECORDS = "episodes.jsonl"
# the modules that write an episodes.jsonl, and those that only read or name one
WRITERS = {
    "pioneer.eval.harness",
    "pioneer.experiments.calibration",
    "pioneer.experiments.blind_sector",
}
READERS = {  # cli.evaluation: its help
    "pioneer.eval.report",
    "pioneer.experiments.reproduce",
    "pioneer.experiments.reproduce_report",
    "pioneer.cli.evaluation",
}


def _docstrings(tree: ast.AST) -> set[int]:
    """The ids of the docstring nodes of ``tree``."""
    out = set()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        first = body[0] if isinstance(body, list) and body else None
        if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
            out.add(id(first.value))
    return out


def _naming_the_records_file() -> set[str]:
    """The modules whose code (not their docstrings or comments) names the records file."""
    found = set()
    for path in SRC.rglob("*.py"):
        tree = ast.parse(path.read_text())
        docs = _docstrings(tree)
        for node in ast.walk(tree):
            named = (
                isinstance(node, ast.Constant)
                and isinstance(node.value, str)
                and RECORDS in node.value
                and id(node) not in docs
            ) or (isinstance(node, ast.Name | ast.alias) and "EPISODES_FILE" in ast.dump(node))
            if named:
                rel = path.relative_to(SRC.parent).with_suffix("")
                found.add(".".join(rel.parts).removesuffix(".__init__"))
                break
    return found


def test_every_module_naming_the_records_file_is_known():
    assert _naming_the_records_file() <= WRITERS | READERS, (
        "a new module names episodes.jsonl: list it in WRITERS (and run it below) or READERS"
    )
    assert _naming_the_records_file() >= WRITERS


def _records(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def _check(records: list[dict]) -> None:
    assert records
    for r in records:
        made = r["made_by"]
        assert isinstance(made["policy"], str) and made["policy"]
        assert isinstance(made["params"], dict) and isinstance(made["files"], dict)


def _evaluation(out: Path) -> list[dict]:
    from pioneer.eval.harness import PolicySpec, evaluate

    evaluate(["hr-rl"], [PolicySpec.make("goal")], 1, 1, out, workers=1, progress=False)
    return _records(out / RECORDS)


def _calibration(out: Path) -> list[dict]:
    from pioneer.experiments.calibration import calibrate

    calibrate(["hr-rl"], 1, out, workers=1, progress=False, driver="goal")
    return _records(out / RECORDS)


def _blind_sector(out: Path) -> list[dict]:
    from pioneer.experiments.blind_sector import run_blind_sector_study

    run_blind_sector_study(out, ["hr-rl-compact"], 1, 270.0, ["obstacle"])
    return _records(out / RECORDS)


RUNS = {
    "pioneer.eval.harness": _evaluation,
    "pioneer.experiments.calibration": _calibration,
    "pioneer.experiments.blind_sector": _blind_sector,
}


def test_every_writer_is_run_below():
    assert set(RUNS) == WRITERS


@pytest.mark.parametrize("writer", sorted(RUNS))
def test_every_record_of_every_writer_names_what_made_it(tmp_path, writer):
    _check(RUNS[writer](tmp_path / "out"))
