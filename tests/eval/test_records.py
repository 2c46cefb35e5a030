"""Records of an older layout read back in the current one (values untouched)."""

from __future__ import annotations

import json

import pytest

from pioneer.errors import DataError
from pioneer.eval.episode import RECORD_FORMAT, EpisodeRecord
from pioneer.eval.records import read_records, upgrade_record
from pioneer_testutils import assert_house_message

V1 = {
    "scenario": "hr-rl",
    "policy": "student-mdn",
    "seed": 3,
    "trial": 0,
    "event": "success",
    "min_clearance_m": 0.12,
    "min_wall_clearance_m": 0.4,
    "frames": {"clearance": [0.5, 0.2], "surface": [0.8, 0.5], "aleatoric": [0.1, 0.2]},
}


def test_a_layout_1_record_gets_the_current_names_and_the_same_values():
    got = upgrade_record(dict(V1))
    assert got["min_gap_m"] == 0.12 and got["min_wall_gap_m"] == 0.4
    assert "min_clearance_m" not in got and "min_wall_clearance_m" not in got
    assert got["frames"] == {"gap": [0.5, 0.2], "clearance": [0.8, 0.5], "aleatoric": [0.1, 0.2]}
    assert upgrade_record(got) == got  # idempotent


def test_a_current_record_is_read_back_as_written(tmp_path):
    fields = {f: None for f in EpisodeRecord.__dataclass_fields__}
    rec = EpisodeRecord(
        **{
            **fields,
            "scenario": "hr-rl",
            "policy": "teacher",
            "seed": 1,
            "event": "success",
            "time_s": 12.0,
            "path_length_m": 3.7,
            "min_gap_m": 0.02,
            "time_close_s": 9.0,
            "steps": 120,
            "collided_with": None,
            "min_wall_gap_m": 0.3,
            "frames": None,
            "format": RECORD_FORMAT,
        }
    ).to_dict()
    rec["trial"] = 0
    p = tmp_path / "episodes.jsonl"
    p.write_text(json.dumps(V1) + "\n" + json.dumps(rec) + "\n")
    old, new = read_records(p)
    assert new == rec and new["format"] == RECORD_FORMAT
    assert old["min_gap_m"] == V1["min_clearance_m"]


def test_a_record_of_a_newer_layout_is_refused():
    with pytest.raises(DataError) as err:
        upgrade_record({**V1, "format": RECORD_FORMAT + 1})
    assert_house_message(str(err.value), "record format", "newer")


def test_older_records_keep_their_layout_version_and_gain_no_measures():
    v1 = upgrade_record(dict(V1))
    assert v1["format"] == 2 and "measures" not in v1 and "series" not in v1
    v2 = {**v1, "time_s": 3.0}
    assert upgrade_record(v2) is v2  # layout 2: nothing to rename
    assert RECORD_FORMAT == 3


def _line(**changes: object) -> str:
    rec = {"scenario": "general-0001", "policy": "teacher", "seed": 0, "trial": 0}
    rec |= {"event": "success", "time_s": 9.0, "path_length_m": 3.0, "min_gap_m": 0.4}
    return json.dumps({**rec, "format": 2, "seed_set": "validation", **changes}) + "\n"


def test_success_rates_are_each_scenarios_share_of_successes_read_only(tmp_path):
    from pioneer.eval.report import success_rates

    lines = [_line(trial=t, event="success" if t else "collision") for t in range(4)]
    lines += [_line(scenario="general-0002", trial=t) for t in range(2)]
    (tmp_path / "episodes.jsonl").write_text("".join(lines) + lines[0][:20])  # a torn tail
    before = (tmp_path / "episodes.jsonl").read_bytes()
    assert success_rates(tmp_path) == {"general-0001": 0.75, "general-0002": 1.0}
    assert (tmp_path / "episodes.jsonl").read_bytes() == before  # an input: never rewritten


@pytest.mark.parametrize(
    ("lines", "needle"),
    [
        ([], "no episodes.jsonl records"),
        ([_line(seed_set="evaluation")], "validation"),  # never choose on evaluation seeds
        ([_line(), _line(policy="goal")], "one policy"),
    ],
)
def test_success_rates_refuse_a_folder_that_is_not_one_policys_validation_episodes(
    tmp_path, lines, needle
):
    from pioneer.eval.report import success_rates

    (tmp_path / "episodes.jsonl").write_text("".join(lines))
    with pytest.raises(Exception, match=needle) as info:
        success_rates(tmp_path)
    assert_house_message(str(info.value))
