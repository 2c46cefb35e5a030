"""Every baseline and student passes the teacher's episode-level checks in the harness:
the same records serially and in parallel (bit for bit, per-frame uncertainty included), and
a rerun resumes without running anything."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from pioneer.eval.harness import EPISODES_FILE, PolicySpec, evaluate

TIMING = {"wall_time_s", "decision_ms"}
POLICIES = ["cvar-bf", "dwa", "sfm", "crowdnav++", "student-mdn", "student-mlp", "student-shield"]


def _untimed(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    rows = [{k: v for k, v in r.items() if k not in TIMING} for r in records]
    return sorted(rows, key=lambda r: (r["scenario"], r["policy"], r["seed"], r["trial"]))


@pytest.mark.parametrize("name", POLICIES)
def test_serial_parallel_and_resume(name: str, tmp_path: Path) -> None:
    spec = [PolicySpec.make(name)]
    serial = evaluate(["hr-rl"], spec, 1, 2, tmp_path / "serial", workers=1, progress=False)
    parallel = evaluate(["hr-rl"], spec, 1, 2, tmp_path / "parallel", workers=2, progress=False)
    assert len(serial) == 2
    assert _untimed(parallel) == _untimed(serial)
    before = (tmp_path / "serial" / EPISODES_FILE).read_text()
    again: list[dict[str, Any]] = []
    evaluate(
        ["hr-rl"],
        spec,
        1,
        2,
        tmp_path / "serial",
        workers=1,
        progress=False,
        on_record=again.append,
    )
    assert again == []
    assert (tmp_path / "serial" / EPISODES_FILE).read_text() == before
    if name.startswith("student"):
        assert all(len(r["frames"]["epistemic"]) == r["steps"] for r in serial)
