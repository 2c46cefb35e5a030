"""Summaries of the social-navigation measures: rates of episodes with Wilson intervals,
means over all or only successful episodes, records without measures left out, tables."""

from __future__ import annotations

import csv
import io
import math
import statistics

import pytest
from scipy.stats import t as student_t

from pioneer.eval.metrics import MEASURE_LIST, MEASURES, RANGES, summarize
from pioneer.eval.report import metric_tables, summary_texts
from pioneer.eval.tables import GROUPS, METRIC_SETS, measure_table, table_rows
from pioneer.stats import wilson_interval


def _measures(**kw):
    base = {
        "shortest_path_m": 3.0,
        "spl": 0.0,
        "path_efficiency": None,
        "time_still_s": 0.0,
        "stalls": 0,
        "accel_mean_m_s2": 0.1,
        "accel_max_m_s2": 1.0,
        "jerk_mean_m_s3": 1.0,
        "jerk_max_m_s3": 10.0,
        "heading_change_rad": 1.0,
        "path_irregularity_rad_m": 0.2,
        "min_clearance_m": 0.5,
        "intimate_share": 0.0,
        "personal_share": 0.5,
        "social_share": 0.5,
        "space_compliance": 1.0,
        "min_ttc_s": None,
        "wall_hit": False,
        "person_hit": None,
        "person_role": None,
        "person_index": None,
        "blocked": None,
    }
    return {**base, **kw}


def _rec(seed, trial, event, measures=None, pol="teacher"):
    r = {
        "scenario": "hr-rl",
        "policy": pol,
        "seed": seed,
        "trial": trial,
        "event": event,
        "time_s": 10.0,
        "path_length_m": 4.0,
        "min_gap_m": 0.2,
        "time_close_s": 1.0,
        "steps": 100,
    }
    if measures is not None:
        r["measures"] = measures
    return r


HIT = {"person_hit": "robot-into-person", "person_role": "exiting", "person_index": 2}
RECORDS = [
    _rec(0, 0, "success", _measures(spl=0.9, path_efficiency=0.9, min_ttc_s=2.0)),
    _rec(0, 1, "success", _measures(spl=0.7, path_efficiency=0.7, heading_change_rad=3.0)),
    _rec(0, 2, "collision", _measures(wall_hit=True, **HIT, min_ttc_s=0.0)),
    _rec(0, 3, "collision", _measures(wall_hit=True)),
    _rec(0, 4, "collision", _measures(person_hit="person-into-robot", person_role="boarding")),
    _rec(
        0, 5, "timeout", _measures(stalls=2, time_still_s=12.0, intimate_share=0.25, blocked=True)
    ),
    _rec(0, 6, "timeout"),  # written before the measures: left out of them
]


def test_rates_by_kind_with_wilson_intervals_over_the_measured_episodes():
    s = summarize(RECORDS)["hr-rl/teacher"]
    assert s["episodes"] == 7 and s["measured"] == 6 and s["interval"] == "episodes"
    expected = {
        "wall_collision_rate": 2,
        "robot_into_person_rate": 1,
        "person_into_robot_rate": 1,
        "exiting_collision_rate": 1,
        "boarding_collision_rate": 1,
        "other_person_collision_rate": 0,
        "stall_rate": 1,
        "blocked_timeout_rate": 1,
    }
    for key, k in expected.items():
        lo, hi = wilson_interval(k, 6)
        assert s[key]["mean"] == pytest.approx(100 * k / 6), key
        assert (s[key]["lo"], s[key]["hi"]) == (pytest.approx(100 * lo), pytest.approx(100 * hi))
    # the event rates count every episode, measured or not
    assert s["collision_rate"]["mean"] == pytest.approx(300 / 7)


def test_the_shut_out_rate_leaves_out_records_measured_before_it():
    # a format-3 record written before `blocked` existed: its timeout may or may not have
    # been shut out, so the rate is over the records that say
    older = {k: v for k, v in _measures().items() if k != "blocked"}
    s = summarize([*RECORDS, _rec(0, 7, "timeout", older)])["hr-rl/teacher"]
    assert s["measured"] == 7 and s["blocked_timeout_rate"]["mean"] == pytest.approx(100 / 6)
    s = summarize([_rec(0, 0, "timeout", older)])["hr-rl/teacher"]
    assert math.isnan(s["blocked_timeout_rate"]["mean"])


def test_means_over_all_or_only_the_successful_episodes():
    s = summarize(RECORDS)["hr-rl/teacher"]
    assert s["spl"]["mean"] == pytest.approx((0.9 + 0.7) / 6)  # failures score 0
    assert s["path_efficiency"]["mean"] == pytest.approx(0.8)  # successes only
    assert s["heading_change_rad"]["mean"] == pytest.approx(2.0)  # successes only
    assert s["time_still_s"]["mean"] == pytest.approx(2.0)
    assert s["intimate_share"]["mean"] == pytest.approx(0.25 / 6)
    assert s["min_ttc_s"]["mean"] == pytest.approx(1.0)  # the two finite ones
    vals = [0.9, 0.7, 0.0, 0.0, 0.0, 0.0]
    half = student_t.ppf(0.975, 5) * statistics.stdev(vals) / math.sqrt(6)
    assert s["spl"]["ci95"] == pytest.approx(half)
    assert s["spl"]["lo"] == 0.0  # clipped to SPL's range


def test_over_seeds_each_seed_is_one_value():
    recs = [
        _rec(seed, t, "success", _measures(spl=0.5 + 0.1 * seed, path_efficiency=0.9))
        for seed in range(3)
        for t in range(2)
    ]
    recs.append(_rec(2, 2, "collision", _measures(**HIT)))
    s = summarize(recs)["hr-rl/teacher"]
    assert s["interval"] == "seeds"
    per_seed = [0.5, 0.6, 0.7 * 2 / 3]
    assert s["spl"]["mean"] == pytest.approx(statistics.fmean(per_seed))
    assert s["robot_into_person_rate"]["mean"] == pytest.approx(100 / 9)  # 0, 0, 1/3 per seed


def test_a_group_without_measures_gives_nan_and_every_range_holds():
    s = summarize([_rec(0, 0, "success"), _rec(0, 1, "timeout")])["hr-rl/teacher"]
    assert s["measured"] == 0
    for key in MEASURES:
        assert math.isnan(s[key]["mean"]), key
    s = summarize(RECORDS)["hr-rl/teacher"]
    for key in MEASURES:
        low, high = RANGES[key]
        cell = s[key]
        assert low <= cell["lo"] <= cell["mean"] <= cell["hi"] <= high, key
    assert {m.key for m in MEASURE_LIST} == set(MEASURES)


def test_measure_tables_show_each_group_with_its_intervals():
    summary = summarize([*RECORDS, _rec(0, 0, "success", _measures(spl=1.0), pol="goal")])
    md = measure_table(summary, ["hr-rl"], ["teacher", "goal"], ["efficiency"], "Efficiency")
    lines = md.strip().splitlines()
    assert lines[0] == "**Efficiency**"
    assert "1 episode(s) were recorded before these measures" in md
    head = next(x for x in lines if x.startswith("| Scenario"))
    assert [c.head for c in GROUPS["efficiency"]] == head.split(" | ")[2:-1]
    teacher = next(x for x in lines if "| teacher |" in x)
    assert teacher.startswith("| HR-RL | teacher | 0.267 [0.000, ")
    assert teacher.endswith("| 6 |")
    goal = next(x for x in lines if "| goal |" in x)
    assert "| 1.000 |" in goal  # one episode: no interval
    social = measure_table(summary, ["hr-rl"], ["teacher"], ["social"], "S")
    share = summary["hr-rl/teacher"]["intimate_share"]["mean"]
    assert f"{100 * share:.1f}" in social  # shares of time printed in %


def test_the_csv_carries_every_measure_and_the_markdown_every_group():
    summary = summarize(RECORDS)
    texts, _ = summary_texts(summary)
    row = next(csv.DictReader(io.StringIO(texts["summary.csv"])))
    for key in MEASURES:
        assert float(row[key]) == pytest.approx(summary["hr-rl/teacher"][key]["mean"])
        assert row[f"{key}_lo"] != "" and row[f"{key}_hi"] != ""
    assert row["measured"] == "6"
    for title in ("Collisions by kind", "Efficiency", "Smoothness", "Social distances"):
        assert f"**{title}" in texts["summary.md"]
    rows = table_rows("I", summary, ["hr-rl"], ["teacher"])
    assert rows[0]["entry"] is summary["hr-rl/teacher"]


def test_metric_sets():
    summary = summarize(RECORDS)
    assert METRIC_SETS["paper"] == ("paper", "collisions")
    paper = metric_tables(summary, "paper")
    assert "SR ↑" in paper and "robot → person" in paper and "SPL" not in paper
    social = metric_tables(summary, "social")
    assert "SR ↑" not in social and "SPL" in social and "min TTC" in social
    everything = metric_tables(summary, "all")
    assert all(x in everything for x in ("SR ↑", "SPL", "min TTC", "irregularity"))
