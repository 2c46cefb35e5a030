"""Metrics with 95 % intervals (Student t over seeds from three seeds on, Wilson score and t
over episodes below), and the paper-style tables."""

from __future__ import annotations

import csv
import io
import math
import statistics
import warnings

import numpy as np
import pytest
from scipy.stats import t as student_t

from pioneer.eval.metrics import METRICS, RANGES, RATES, mean_ci, summarize
from pioneer.eval.tables import PAPER, csv_table, interval_note, markdown_table, table_rows
from pioneer.stats import wilson_interval


def _rec(seed, trial, event, time_s, path, clear=0.5, close=0.0, scenario="hr-rl", pol="teacher"):
    return {
        "scenario": scenario,
        "policy": pol,
        "seed": seed,
        "trial": trial,
        "event": event,
        "time_s": time_s,
        "path_length_m": path,
        "min_gap_m": clear,
        "time_close_s": close,
        "steps": round(time_s * 10),
    }


# Three seeds of a hand-made evaluation (per-seed values worked out by hand below).
RECORDS = [
    _rec(0, 0, "success", 10.0, 4.0, 0.5, 1.0),
    _rec(0, 1, "success", 12.0, 5.0, 0.3, 2.0),
    _rec(0, 2, "collision", 3.0, 1.0, -0.1, 0.5),
    _rec(0, 3, "timeout", 30.0, 6.0, None, 0.0),  # no humans: no clearance
    _rec(1, 0, "success", 14.0, 6.0, 0.7, 0.0),
    _rec(1, 1, "collision", 2.0, 0.5, -0.2, 1.5),
    _rec(2, 0, "timeout", 30.0, 7.0, 1.0, 0.0),
    _rec(2, 1, "timeout", 30.0, 8.0, 1.2, 0.0),
]
PER_SEED = {
    "success_rate": [50.0, 50.0, 0.0],
    "collision_rate": [25.0, 50.0, 0.0],
    "timeout_rate": [25.0, 0.0, 100.0],
    "time_mean_s": [11.0, 14.0],  # seed 2 has no success: it has no TT
    "path_length_mean_m": [4.5, 6.0],
    "time_mean_all_s": [13.75, 8.0, 30.0],
    "path_length_mean_all_m": [4.0, 3.25, 7.5],
    "min_gap_m": [0.7 / 3, 0.25, 1.1],
    "time_close_s": [0.875, 0.75, 0.0],
}


def _reference(values):
    """Mean and t(0.975, n − 1)·sd/√n, written independently of the code under test."""
    n = len(values)
    if n == 1:
        return values[0], 0.0
    return statistics.fmean(values), student_t.ppf(0.975, n - 1) * statistics.stdev(values) / (
        math.sqrt(n)
    )


def test_summary_matches_the_hand_computed_per_seed_values():
    shuffled = [RECORDS[i] for i in np.random.default_rng(3).permutation(len(RECORDS))]
    other = [_rec(0, 0, "success", 9.0, 3.0, pol="goal")]
    summary = summarize(shuffled + other)
    assert set(summary) == {"hr-rl/teacher", "hr-rl/goal"}
    s = summary["hr-rl/teacher"]
    assert (s["scenario"], s["policy"], s["episodes"], s["seeds"]) == ("hr-rl", "teacher", 8, 3)
    assert set(METRICS) <= set(s)
    assert set(PER_SEED) == set(METRICS)
    assert s["interval"] == "seeds"
    for metric, values in PER_SEED.items():
        mean, ci = _reference(values)
        low, high = RANGES[metric]
        assert s[metric]["mean"] == pytest.approx(mean, rel=1e-12), metric
        assert s[metric]["ci95"] == pytest.approx(ci, rel=1e-12), metric
        assert s[metric]["lo"] == pytest.approx(max(low, mean - ci), rel=1e-12), metric
        assert s[metric]["hi"] == pytest.approx(min(high, mean + ci), rel=1e-12), metric
    # spot-check the interval against a number computed by hand: t(0.975, 2) = 4.302653
    assert s["success_rate"]["ci95"] == pytest.approx(4.302653 * 28.867513 / math.sqrt(3), 1e-6)
    # rates add up per seed, hence on average
    total = sum(s[k]["mean"] for k in ("success_rate", "collision_rate", "timeout_rate"))
    assert total == pytest.approx(100.0)
    g = summary["hr-rl/goal"]  # one seed, one episode: Wilson over episodes
    assert g["interval"] == "episodes"
    lo, hi = wilson_interval(1, 1)
    assert g["success_rate"]["mean"] == 100.0
    assert (g["success_rate"]["lo"], g["success_rate"]["hi"]) == (100 * lo, 100 * hi)
    assert g["time_mean_s"]["mean"] == 9.0
    assert g["time_mean_s"]["lo"] == g["time_mean_s"]["hi"] == 9.0  # one value: no interval


def test_success_only_and_all_episode_variants_differ():
    s = summarize(RECORDS)["hr-rl/teacher"]
    assert s["time_mean_s"]["mean"] == pytest.approx(12.5)  # successes only
    assert s["time_mean_all_s"]["mean"] == pytest.approx((13.75 + 8.0 + 30.0) / 3)
    assert s["path_length_mean_m"]["mean"] == pytest.approx(5.25)
    assert s["path_length_mean_all_m"]["mean"] == pytest.approx((4.0 + 3.25 + 7.5) / 3)


def test_no_success_at_all_gives_nan_without_warnings():
    recs = [_rec(s, t, "collision", 2.0 + t, 1.0) for s in range(3) for t in range(2)]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s = summarize(recs)["hr-rl/teacher"]
        rows = table_rows("I", {"hr-rl/teacher": s}, ["hr-rl"], ["teacher"])
        md = markdown_table(rows, "T")
        text = csv_table(rows, "I")
    assert s["success_rate"] == {"mean": 0.0, "ci95": 0.0, "lo": 0.0, "hi": 0.0}
    assert s["collision_rate"] == {"mean": 100.0, "ci95": 0.0, "lo": 100.0, "hi": 100.0}
    for k in ("time_mean_s", "path_length_mean_m"):
        assert math.isnan(s[k]["mean"]) and math.isnan(s[k]["ci95"])
    assert s["time_mean_all_s"]["mean"] == pytest.approx(2.5)
    cells = md.strip().splitlines()[-1].split(" | ")
    assert cells[3] == "–" and cells[4] == "–"  # TT and PL
    row = next(csv.DictReader(io.StringIO(text)))
    assert row["tt_s"] == "nan"


def test_mean_ci_ignores_missing_and_infinite_values():
    for empty in ([], [None, math.inf, float("nan")]):
        mean, ci = mean_ci(empty)
        assert math.isnan(mean) and math.isnan(ci)
    assert mean_ci([2.5]) == (2.5, 0.0)
    mean, ci = mean_ci([1.0, None, 2.0, math.inf, 6.0])
    ref = _reference([1.0, 2.0, 6.0])
    assert (mean, ci) == (pytest.approx(ref[0]), pytest.approx(ref[1]))
    _, ci90 = mean_ci([1.0, 2.0, 6.0], level=0.9)
    assert ci90 == pytest.approx(student_t.ppf(0.95, 2) * statistics.stdev([1, 2, 6]) / 3**0.5)
    assert ci90 < ci


# --------------------------------------------------------------------------------------------
# tables


def test_paper_numbers_are_the_papers():
    assert PAPER[("I", "hr-rl", "teacher-paper")] == (99.4, 12.24, 3.74)
    assert PAPER[("I", "hl-rr", "teacher-paper")] == (99.6, 12.94, 3.88)
    assert PAPER[("II", "hr-rl", "teacher-paper-no-density")] == (83.0, 13.61, 4.55)
    assert ("I", "hr-rl", "teacher") not in PAPER  # ours deviates: no paper value beside it
    assert PAPER[("III", "hl-rr", "student-mdn")] == (100.0, 14.16, 4.70)


def _table_inputs():
    recs = [{**r, "policy": "teacher-paper"} for r in RECORDS] + [
        _rec(s, 0, "success", 8.0, 3.0, pol="goal") for s in range(2)
    ]
    summary = summarize(recs)
    rows = table_rows("I", summary, ["hr-rl", "hl-rr"], ["teacher-paper", "goal", "cvar-bf"])
    return summary, rows


def test_table_rows_keep_the_requested_order_and_skip_missing_entries():
    summary, rows = _table_inputs()
    assert [(r["scenario"], r["method"]) for r in rows] == [
        ("hr-rl", "teacher-paper"),
        ("hr-rl", "goal"),
    ]
    assert rows[0]["paper"] == (99.4, 12.24, 3.74)
    assert rows[1]["paper"] is None
    assert rows[0]["sr"] == summary["hr-rl/teacher-paper"]["success_rate"]
    assert rows[0]["episodes"] == 8


def test_markdown_table_shows_the_paper_numbers_beside_ours():
    summary, rows = _table_inputs()
    md = markdown_table(rows, "Table I")
    lines = md.strip().splitlines()
    assert lines[0] == "**Table I**"
    assert lines[4].startswith("| Scenario | Method | SR")
    assert len(lines) == 6 + len(rows)
    teacher = next(x for x in lines if "| teacher-paper |" in x)
    s = summary["hr-rl/teacher-paper"]
    assert "| HR-RL |" in teacher
    assert "99.4 / 12.24 / 3.74" in teacher
    # 3 seeds: t over seeds; 33.3 ± 71.7 would leave 0–100 %, so it is printed clipped
    assert "| 33.3 [0.0, 100.0] |" in teacher
    mc = s["min_gap_m"]  # may be negative: never clipped, printed ± as over seeds
    assert f"| {mc['mean']:.2f} ± {mc['ci95']:.2f} |" in teacher
    assert "| 12.50 [0.00, " in teacher  # TT over 2 seeds with successes, clipped at 0
    assert teacher.rstrip(" |").endswith("8")  # episodes
    goal = next(x for x in lines if "| goal |" in x)
    lo, _ = wilson_interval(2, 2)  # 2 seeds: Wilson over the 2 episodes
    assert f"| 100.0 [{100 * lo:.1f}, 100.0] |" in goal
    assert "| 8.00 |" in goal  # two equal times: a zero-width interval is not printed
    assert "| – |" in goal  # no paper numbers for this row
    assert lines[2] == interval_note(rows)
    assert "over 3 seeds (Student t)" in lines[2] and "Wilson" in lines[2]


def test_csv_table_has_our_values_and_the_papers():
    summary, rows = _table_inputs()
    parsed = list(csv.DictReader(io.StringIO(csv_table(rows, "I"))))
    assert len(parsed) == 2
    t, g = parsed
    s = summary["hr-rl/teacher-paper"]
    assert (t["table"], t["scenario"], t["method"], t["episodes"]) == (
        "I",
        "hr-rl",
        "teacher-paper",
        "8",
    )
    assert float(t["sr"]) == s["success_rate"]["mean"]
    assert float(t["sr_ci95"]) == s["success_rate"]["ci95"]
    assert float(t["tt_s"]) == s["time_mean_s"]["mean"]
    assert float(t["pl_m"]) == s["path_length_mean_m"]["mean"]
    assert float(t["collision_rate"]) == s["collision_rate"]["mean"]
    assert (float(t["paper_sr"]), float(t["paper_tt_s"]), float(t["paper_pl_m"])) == (
        99.4,
        12.24,
        3.74,
    )
    assert g["method"] == "goal"
    assert g["paper_sr"] == g["paper_tt_s"] == g["paper_pl_m"] == ""


def _events(n_seeds, trials, rng):
    """Random records: events, times and clearances of ``n_seeds`` × ``trials`` episodes."""
    events = rng.choice(["success", "collision", "timeout"], size=(n_seeds, trials))
    return [
        _rec(
            seed,
            t,
            str(events[seed, t]),
            float(rng.uniform(5, 30)),
            float(rng.uniform(2, 9)),
            float(rng.uniform(-0.3, 2.0)),
            float(rng.uniform(0, 3)),
        )
        for seed in range(n_seeds)
        for t in range(trials)
    ]


@pytest.mark.parametrize("n_seeds", [1, 2])
def test_fewer_than_three_seeds_give_intervals_over_episodes(n_seeds):
    """Two seeds would give t(0.975, 1) = 12.7: the interval is over the episodes instead,
    Wilson for the rates and Student t for the times (written here independently)."""
    recs = _events(n_seeds, 10, np.random.default_rng(n_seeds))
    s = summarize(recs)["hr-rl/teacher"]
    assert s["interval"] == "episodes" and s["seeds"] == n_seeds
    for metric, event in zip(RATES, ("success", "collision", "timeout"), strict=True):
        k = sum(r["event"] == event for r in recs)
        lo, hi = wilson_interval(k, len(recs))
        assert s[metric]["mean"] == pytest.approx(100 * k / len(recs))
        assert (s[metric]["lo"], s[metric]["hi"]) == (
            pytest.approx(100 * lo),
            pytest.approx(100 * hi),
        )
    times = [r["time_s"] for r in recs if r["event"] == "success"]
    mean, half = _reference(times)
    assert s["time_mean_s"]["mean"] == pytest.approx(mean)
    assert s["time_mean_s"]["ci95"] == pytest.approx(half)


@pytest.mark.parametrize("n_seeds", [1, 2, 3, 5])
@pytest.mark.parametrize("trials", [1, 2, 5])
def test_no_interval_exceeds_its_quantitys_range(n_seeds, trials):
    rng = np.random.default_rng(100 * n_seeds + trials)
    for _ in range(20):
        s = summarize(_events(n_seeds, trials, rng))["hr-rl/teacher"]
        for metric in METRICS:
            low, high = RANGES[metric]
            cell = s[metric]
            if math.isfinite(cell["mean"]):
                assert low <= cell["lo"] <= cell["mean"] <= cell["hi"] <= high, (metric, cell)


def test_the_table_says_over_what_its_intervals_are():
    two = summarize(_events(2, 10, np.random.default_rng(0)))
    rows = table_rows("I", two, ["hr-rl"], ["teacher"])
    note = interval_note(rows)
    assert "over episodes (2 seeds" in note and "Wilson" in note and "over 2 seeds" not in note
    five = summarize(_events(5, 4, np.random.default_rng(0)))
    note = interval_note(table_rows("I", five, ["hr-rl"], ["teacher"]))
    assert "over 5 seeds (Student t)" in note and "Wilson" not in note
