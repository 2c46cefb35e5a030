"""``pioneer study static``: the synthetic static study (paper §V-A, Fig. 3) end to end."""

from __future__ import annotations

import json

import pytest
from PIL import Image

from pioneer.cli import main


def _json(capsys) -> dict:
    return json.loads(capsys.readouterr().out)


@pytest.mark.slow
def test_study_static_writes_the_figure(tmp_path, capsys):
    out = tmp_path / "study"
    assert main(["study", "static", "--out", str(out)]) == 0
    summary = _json(capsys)
    png = out / "static_study.png"
    assert png.is_file() and summary["figure"] == str(png)
    with Image.open(png) as im:
        assert im.format == "PNG" and im.size[0] > 300
    print(
        f"\nstatic study near the human: positives only {summary['reward_near_human_pos_only']:.4f}"
        f", positives + negatives {summary['reward_near_human_pos_neg']:.4f}"
    )
    assert summary["reward_near_human_pos_neg"] < summary["reward_near_human_pos_only"]
    assert len(summary["teacher_events"]) == 6
    assert summary["teacher_events"].count("collision") == 0
