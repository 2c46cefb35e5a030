"""The blind-sector study (docs/student.md): the shipped student through the robot runtime
with a 270° scanner, on validation seeds; and its command."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from pioneer.cli import main
from pioneer.data import shipped_student
from pioneer.errors import ConfigError
from pioneer.experiments.blind_sector import run_blind_sector_study, scanner_message
from pioneer.io import file_sha256
from pioneer.seeds import VALIDATION_BASE, validation_seed


def test_study_runs_every_variant_on_validation_seeds(tmp_path):
    s = run_blind_sector_study(tmp_path, ["hr-rl-compact"], 2, 270.0, ["obstacle", "max_range"])
    got = s["hr-rl-compact"]
    assert list(got) == ["360°", "270° obstacle", "270° max_range"]
    for row in got.values():
        assert row["n"] == 2 == row["success"] + row["collision"] + row["timeout"]
        lo, hi = row["success_ci95"]
        assert 0.0 <= lo <= row["success_rate"] <= hi <= 1.0
    assert json.loads((tmp_path / "summary.json").read_text()) == s
    lines = [json.loads(x) for x in (tmp_path / "episodes.jsonl").read_text().splitlines()]
    assert len(lines) == 6
    want = [validation_seed("blind-sector", "hr-rl-compact", k) for k in range(2)]
    assert [r["seed"] for r in lines[:2]] == want
    assert all(VALIDATION_BASE <= r["seed"] < 2 * VALIDATION_BASE for r in lines)
    with pytest.raises(ConfigError):
        run_blind_sector_study(tmp_path, ["hr-rl-compact"], 1, 270.0, ["guess"])


def test_every_record_names_what_drove_it(tmp_path):
    """Like the evaluation's records: made_by with the parameters and the files' hashes."""
    run_blind_sector_study(tmp_path, ["hr-rl-compact"], 1, 270.0, ["obstacle", "max_range"])
    lines = [json.loads(x) for x in (tmp_path / "episodes.jsonl").read_text().splitlines()]
    made = [r["made_by"] for r in lines]
    assert {m["policy"] for m in made} == {"pioneer.experiments.blind_sector:ScannerPolicy"}
    assert [m["params"]["fov_rad"] for m in made] == pytest.approx(
        [2 * math.pi, math.radians(270), math.radians(270)]
    )
    assert [m["params"]["runtime"]["unseen"] for m in made] == ["obstacle", "obstacle", "max_range"]
    student = shipped_student("hr-rl-compact")
    onnx = tmp_path / "hr-rl-compact.onnx"
    for m in made:
        assert m["files"] == {
            "checkpoint": {"path": str(student), "sha256": file_sha256(student)},
            "model": {"path": str(onnx), "sha256": file_sha256(onnx)},
        }


def test_scanner_message_fields_of_view():
    beams = np.arange(72, dtype=float) * 0.05 + 0.1
    beams[0] = 5.0
    r, amin, inc = scanner_message(beams, 2 * math.pi, 5.0)
    assert (amin, r.size) == (0.0, 72) and r[0] == np.inf and inc == pytest.approx(math.pi / 36)
    r, amin, inc = scanner_message(beams, math.radians(90), 5.0)
    assert r.size == 19 and amin == pytest.approx(-math.radians(45))
    np.testing.assert_array_equal(r[10:], beams[1:10])
    with pytest.raises(ConfigError):
        scanner_message(beams, 0.0, 5.0)


def test_cli_study_blind_sector(tmp_path, capsys):
    argv = ["study", "blind-sector", "--out", str(tmp_path), "--scenario", "hl-rr-compact"]
    assert main([*argv, "--episodes", "1", "--rules", "nearest"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert [json.loads(x)["variant"] for x in lines] == ["360°", "270° nearest"]
    with pytest.raises(SystemExit) as bad:  # a parse error: one line, exit 2
        main([*argv, "--rules", "guess"])
    assert bad.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--rules" in err and "obstacle" in err
