"""examples/who_hits_whom.py: the baselines' collision table from an evaluation's records."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from pioneer_testutils import run_cli

SCRIPT = Path(__file__).resolve().parents[2] / "examples" / "who_hits_whom.py"


def _script(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(SCRIPT), *argv], capture_output=True, text=True, check=False
    )


def test_go_to_goal_drives_into_the_exiting_passenger(tmp_path: Path) -> None:
    out = tmp_path / "why"
    res = run_cli(
        "eval", "--scenario", "hr-rl", "--policy", "goal", "--seeds", "1", "--trials", "2",
        "--seed-set", "validation", "--workers", "1", "--metrics", "all", "--out", str(out),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    table = _script(str(out))
    assert table.returncode == 0, table.stderr
    lines = table.stdout.splitlines()
    assert lines[0].startswith("| scenario | policy |") and len(lines) == 3
    cells = [c.strip() for c in lines[2].strip("|").split("|")]
    # go-to-goal ignores people: it collides, moving, with the passenger stepping out
    assert cells[:5] == ["hr-rl", "goal", "2", "0", "100"]
    assert cells[6] == "100 %" and cells[8] == "100 %"  # robot → person; the exiting person
    assert float(cells[11]) > 0.3  # it was driving at contact, not standing


def test_a_folder_without_records_is_one_clear_error(tmp_path: Path) -> None:
    res = _script(str(tmp_path))
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and "expected" in res.stderr and "fix:" in res.stderr
