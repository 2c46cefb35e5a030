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


def test_the_parent_process_does_not_import_torch(tmp_path: Path) -> None:
    """Torch policies are built in the workers; the parent only checks their names (a parent
    holding torch would cost ≈ 250 MB for nothing)."""
    import subprocess
    import sys

    code = f"""
import sys
from pioneer.eval.harness import PolicySpec, evaluate
if __name__ == "__main__":
    recs = evaluate(["hr-rl"], [PolicySpec.make("student-mdn")], 1, 1, {str(tmp_path)!r},
                    workers=2, progress=False)
    assert len(recs) == 1 and "frames" in recs[0]
    assert "torch" not in sys.modules, "the parent imported torch"
    print("ok")
"""
    script = tmp_path / "parent.py"
    script.write_text(code)
    proc = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, check=False, timeout=300
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip().endswith("ok")


def test_unknown_policy_names_are_refused_before_anything_runs(tmp_path: Path) -> None:
    from pioneer.errors import ConfigError

    with pytest.raises(ConfigError, match="student-cnn"):
        evaluate(["hr-rl"], [PolicySpec.make("student-cnn")], 1, 1, tmp_path, workers=1)
    assert not (tmp_path / EPISODES_FILE).exists()
