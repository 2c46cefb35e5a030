"""The safe/risky uncertainty analysis (``pioneer.eval.uncertainty``, paper Table IV) and the
per-frame series of students recorded by ``run_episode`` and the evaluation harness."""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pioneer.baselines.classic import GoalPolicy
from pioneer.envs.env import NavEnv
from pioneer.errors import DataError
from pioneer.eval.episode import EpisodeRecord, run_episode
from pioneer.eval.harness import EPISODES_FILE, PolicySpec, episode_seed, evaluate, read_records
from pioneer.eval.metrics import summarize
from pioneer.eval.uncertainty import PAPER_TABLE_IV, frame_arrays, safe_risky, table_iv_markdown
from pioneer.learn import MDN, StudentPolicy, make_student_policy, save_student
from pioneer.sim.scenarios import get_scenario, static_study_scenario
from pioneer.sim.world import SimConfig
from pioneer_testutils import assert_house_message

torch.set_num_threads(1)

PROP = settings(max_examples=80, deadline=None)
KEYS = ("clearance", "aleatoric", "epistemic")  # a test record's frame series
ARRAYS = ("distance", "aleatoric", "epistemic")  # frame_arrays' columns


# ------------------------------------------------------------------------------ oracle
def _oracle(records: Sequence[Mapping[str, Any]], threshold: float) -> dict[str, float]:
    """Counts, class means and pairwise AUROCs, frame by frame (no numpy)."""
    safe: list[tuple[float, float]] = []
    risky: list[tuple[float, float]] = []
    for rec in records:
        fr = rec.get("frames")
        if not fr:
            continue
        for c, a, e in zip(fr["clearance"], fr["aleatoric"], fr["epistemic"], strict=True):
            if a is None or e is None or not (math.isfinite(a) and math.isfinite(e)):
                continue
            (risky if c is not None and c <= threshold else safe).append((a, e))
    out: dict[str, float] = {"frames_safe": len(safe), "frames_risky": len(risky)}
    for j, name in enumerate(("aleatoric", "epistemic")):
        s = [x[j] for x in safe]
        r = [x[j] for x in risky]
        out[f"{name}_safe"] = sum(s) / len(s) if s else math.nan
        out[f"{name}_risky"] = sum(r) / len(r) if r else math.nan
        if s and r:
            wins = sum(1.0 if x > y else 0.5 if x == y else 0.0 for x in r for y in s)
            out[f"auroc_{name}"] = wins / (len(r) * len(s))
        else:
            out[f"auroc_{name}"] = math.nan
    return out


def _assert_matches(got: Mapping[str, Any], want: Mapping[str, float]) -> None:
    for key, value in want.items():
        if math.isnan(value):
            assert math.isnan(got[key]), key
        else:
            assert got[key] == pytest.approx(value, rel=1e-9, abs=1e-12), key


def _rec(clearance: list[Any], aleatoric: list[Any], epistemic: list[Any]) -> dict[str, Any]:
    return {
        "scenario": "hr-rl",
        "policy": "student-mdn",
        "seed": 0,
        "frames": {"clearance": clearance, "aleatoric": aleatoric, "epistemic": epistemic},
    }


# Few distinct values, so ties (in the uncertainties, and clearance == threshold) are common.
CLEARANCE = st.one_of(
    st.none(),
    st.just(math.inf),
    st.sampled_from([-0.2, 0.0, 0.5, 0.8, 0.81, 1.5]),
    st.floats(-0.5, 3.0),
)
UNC = st.one_of(
    st.sampled_from([0.0, 0.1, 0.2, 0.3]),
    st.floats(0.0, 1.0),
    st.none(),
    st.just(math.nan),
    st.just(math.inf),
)


@st.composite
def records(draw: st.DrawFn) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    for _ in range(draw(st.integers(0, 4))):
        kind = draw(st.sampled_from(["frames", "frames", "frames", "none", "missing"]))
        if kind == "missing":  # a rule-based policy: no frames key at all
            out.append({"scenario": "hr-rl", "policy": "goal", "seed": 0})
            continue
        if kind == "none":
            out.append({**_rec([], [], []), "frames": None})
            continue
        n = draw(st.integers(0, 12))
        out.append(
            _rec(
                draw(st.lists(CLEARANCE, min_size=n, max_size=n)),
                draw(st.lists(UNC, min_size=n, max_size=n)),
                draw(st.lists(UNC, min_size=n, max_size=n)),
            )
        )
    return out


# ------------------------------------------------------------------------------ safe_risky
@PROP
@given(records(), st.sampled_from([0.8, 0.5, 0.0]))
def test_safe_risky_matches_a_frame_by_frame_oracle(recs, threshold):
    got = safe_risky(recs, threshold=threshold)
    assert got["threshold_m"] == threshold
    assert isinstance(got["frames_safe"], int) and isinstance(got["frames_risky"], int)
    _assert_matches(got, _oracle(recs, threshold))


def test_safe_risky_by_hand():
    recs = [
        _rec([0.3, 1.0, None, 0.8], [0.4, 0.1, 0.2, 0.6], [0.5, 0.1, 0.3, 0.5]),
        {"scenario": "hr-rl", "policy": "goal", "seed": 1},  # no frames: skipped
        _rec([0.2, 2.0], [math.nan, 0.3], [0.9, None]),  # both frames dropped (NaN, None)
    ]
    got = safe_risky(recs)
    # Risky (<= 0.8 m): frames 0 and 3; safe: frame 1 and the no-human frame 2.
    assert (got["frames_safe"], got["frames_risky"]) == (2, 2)
    assert got["aleatoric_risky"] == pytest.approx(0.5)
    assert got["aleatoric_safe"] == pytest.approx(0.15)
    assert got["epistemic_risky"] == pytest.approx(0.5)
    assert got["epistemic_safe"] == pytest.approx(0.2)
    assert got["auroc_aleatoric"] == 1.0  # every risky frame above every safe one
    assert got["auroc_epistemic"] == 1.0
    # Reversed labels give 0; an uninformative score gives 0.5 (ties count ½).
    flipped = safe_risky([_rec([1.0, 0.1], [0.2, 0.1], [0.3, 0.3])])
    assert flipped["auroc_aleatoric"] == 0.0 and flipped["auroc_epistemic"] == 0.5


def test_no_human_in_range_counts_as_safe():
    got = safe_risky([_rec([None, None, math.inf], [0.1, 0.2, 0.3], [0.1, 0.1, 0.1])])
    assert (got["frames_safe"], got["frames_risky"]) == (3, 0)
    assert got["aleatoric_safe"] == pytest.approx(0.2)
    assert math.isnan(got["aleatoric_risky"]) and math.isnan(got["auroc_aleatoric"])


def test_frames_without_uncertainty_are_dropped():
    # An MLP student reports NaN (stored as None in JSON): nothing to analyse.
    got = safe_risky([_rec([0.1, 2.0], [None, math.nan], [None, math.nan])])
    assert (got["frames_safe"], got["frames_risky"]) == (0, 0)
    assert all(
        math.isnan(got[k])
        for k in got
        if k not in ("threshold_m", "measure", "frames_safe", "frames_risky")
    )
    arrays = frame_arrays([_rec([None, 0.5], [None, 0.1], [0.2, None])])
    np.testing.assert_array_equal(arrays["distance"], [math.inf, 0.5])
    np.testing.assert_array_equal(arrays["aleatoric"], [math.nan, 0.1])
    np.testing.assert_array_equal(arrays["epistemic"], [0.2, math.nan])


def test_empty_input():
    got = safe_risky([])
    assert (got["frames_safe"], got["frames_risky"]) == (0, 0)
    assert {k: v.size for k, v in frame_arrays([]).items()} == dict.fromkeys(ARRAYS, 0)


@pytest.mark.parametrize("short", KEYS)
def test_unequal_series_are_a_data_error(short):
    series = {k: [0.5, 0.5, 0.5] for k in KEYS}
    series[short] = [0.5, 0.5]
    rec = {**_rec(**series), "seed": 17}
    with pytest.raises(DataError) as err:
        safe_risky([rec])
    assert_house_message(str(err.value), "frames", "17")


def test_the_gap_measure_thresholds_the_gap_series():
    # the paper's clearance (centre → surface) is the gap + r_r: a 0.6 m gap is risky by the
    # gap, its 0.9 m clearance is safe
    rec = _rec([0.9, 1.5], [0.4, 0.1], [0.5, 0.2])  # r_r = 0.3 m
    rec["frames"]["gap"] = [0.6, 1.2]
    assert safe_risky([rec], 0.8)["frames_risky"] == 0  # by the clearance (the default)
    by_gap = safe_risky([rec], 0.8, "gap")
    assert by_gap["frames_risky"] == 1 and by_gap["measure"] == "gap"
    assert safe_risky([rec], 0.5, "gap")["frames_risky"] == 0
    np.testing.assert_array_equal(frame_arrays([rec], "gap")["distance"], [0.6, 1.2])


def test_records_without_the_asked_series_are_one_data_error():
    with pytest.raises(DataError) as err:
        safe_risky([_rec([0.5], [0.1], [0.1])], 0.8, "gap")
    assert_house_message(str(err.value), "'gap' series", "new --out")
    with pytest.raises(DataError):
        frame_arrays([], "nope")


# ------------------------------------------------------------------------------ table IV
def _cells(line: str) -> list[str]:
    assert line.startswith("|") and line.endswith("|"), line
    return [c.strip() for c in line[1:-1].split("|")]


def test_table_iv_puts_ours_beside_the_papers():
    ours = safe_risky([_rec([0.3, 1.0, 1.2], [0.4, 0.1, 0.2], [0.5, 0.25, 0.35])])
    md = table_iv_markdown({"hr-rl": ours, "static": ours}, ["hr-rl", "hl-rr", "static"])
    assert md.endswith("\n")
    lines = md.strip().splitlines()
    header = _cells(lines[0])
    assert header[0] == "Scenario" and header[-2:] == ["AUROC epi.", "AUROC ale."]
    assert set(lines[1]) <= set("|-") and len(_cells(lines[1])) == len(header)
    rows = [_cells(line) for line in lines[2:]]
    assert all(len(r) == len(header) for r in rows)
    # hr-rl: ours and the paper's; hl-rr: no result, no rows; static: no paper row.
    assert [r[:2] for r in rows] == [["hr-rl", "ours"], ["", "paper"], ["static", "ours"]]
    # Epi./Ale. safe, Epi./Ale. risky, frames, AUROCs (the paper reports no AUROC).
    assert rows[0][-7:] == ["0.300", "0.150", "0.500", "0.400", "2 / 1", "1.000", "1.000"]
    p = PAPER_TABLE_IV["hr-rl"]
    assert rows[1][-7:] == [
        f"{p['epistemic_safe']:.3f}",
        f"{p['aleatoric_safe']:.3f}",
        f"{p['epistemic_risky']:.3f}",
        f"{p['aleatoric_risky']:.3f}",
        "62,374 / 5,467",
        "–",
        "–",
    ]
    assert rows[1][-7:-3] == ["0.290", "0.310", "0.382", "0.407"]
    assert rows[2][-7:] == rows[0][-7:]


def test_table_iv_shows_a_dash_for_missing_values():
    only_safe = safe_risky([_rec([2.0, 3.0], [0.1, 0.2], [0.1, 0.2])])
    rows = [
        _cells(line)
        for line in table_iv_markdown({"hl-rr": only_safe}, ["hl-rr"]).strip().splitlines()[2:]
    ]
    assert rows[0][:2] == ["hl-rr", "ours"]
    assert rows[0][-7:] == ["0.150", "0.150", "–", "–", "2 / 0", "–", "–"]
    assert rows[1][:2] == ["", "paper"]
    assert rows[1][-7:-2] == ["0.342", "0.270", "0.523", "0.426", "67,806 / 3,245"]


# ------------------------------------------------------------------------------ recording
@pytest.fixture(scope="module")
def ckpt(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An untrained MDN (the recording does not care what it learnt)."""
    return save_student(MDN(seed=0), tmp_path_factory.mktemp("unc") / "mdn.safetensors")


def _student(ckpt: Path) -> StudentPolicy:
    return make_student_policy(ckpt)


def test_run_episode_records_one_frame_per_step(ckpt):
    pol = _student(ckpt)
    rec, _ = run_episode("hr-rl", pol, seed=4)
    assert rec.frames is not None and set(rec.frames) == {*KEYS, "gap"}
    assert all(len(v) == rec.steps for v in rec.frames.values())
    _, info = NavEnv("hr-rl").reset(seed=4)
    assert rec.frames["gap"][0] == info["min_gap"]  # the state of the first decision
    r_r = get_scenario("hr-rl").sim.robot.radius
    assert rec.frames["clearance"] == [g + r_r for g in rec.frames["gap"]]
    assert rec.frames["aleatoric"] == [a for a, _ in pol.uncertainty]
    assert rec.frames["epistemic"] == [e for _, e in pol.uncertainty]

    d = rec.to_dict()
    assert json.loads(json.dumps(d)) == d  # JSON-able
    for key in KEYS:
        assert d["frames"][key] == [float(f"{x:.6g}") for x in rec.frames[key]]


def test_frames_of_later_steps_are_the_clearance_before_each_decision(ckpt):
    pol = _student(ckpt)
    rec, traj = run_episode("hr-rl", pol, seed=6, record=True)
    assert rec.frames is not None and traj is not None
    assert len(traj.states) == rec.steps + 1
    # Frame t is the gap of the state the t-th command was chosen in.
    for t in range(rec.steps):
        assert rec.frames["gap"][t] == float(traj.states[t].gap[0])


def test_no_human_gives_none_clearance_in_json_and_safe_frames(ckpt):
    empty = dataclasses.replace(
        static_study_scenario(sim=SimConfig(time_limit=1.0)), humans=(), name="empty"
    )
    rec, _ = run_episode(empty, _student(ckpt), seed=0)
    assert rec.frames is not None and rec.frames["clearance"] == [math.inf] * rec.steps
    d = rec.to_dict()
    assert d["min_gap_m"] is None and d["frames"]["clearance"] == [None] * rec.steps
    got = safe_risky([d])
    assert (got["frames_safe"], got["frames_risky"]) == (rec.steps, 0)


def test_policies_without_uncertainty_record_no_frames():
    rec, _ = run_episode("static", GoalPolicy(), seed=1)
    assert rec.frames is None and "frames" not in rec.to_dict()

    class Forgetful(GoalPolicy):
        """Reports uncertainty, but not one pair per step: not recorded."""

        def __init__(self) -> None:
            super().__init__()
            self.uncertainty: list[tuple[float, float]] = []

    rec, _ = run_episode("static", Forgetful(), seed=1)
    assert rec.frames is None and "frames" not in rec.to_dict()


def test_records_keep_frames_through_the_harness(ckpt, tmp_path):
    student = PolicySpec.make("student-mdn", checkpoint=str(ckpt))
    goal = PolicySpec.make("goal")
    recs = evaluate(["hr-rl"], [student, goal], 1, 2, tmp_path, workers=1, progress=False)
    assert len(recs) == 4
    back = read_records(tmp_path / EPISODES_FILE)
    assert back == json.loads(json.dumps(recs))
    by_policy = {p: [r for r in back if r["policy"] == p] for p in ("student-mdn", "goal")}
    for r in by_policy["student-mdn"]:
        assert set(r["frames"]) == {*KEYS, "gap"}
        assert all(len(v) == r["steps"] for v in r["frames"].values())
        _, info = NavEnv("hr-rl").reset(seed=episode_seed("hr-rl", 0, r["trial"]))
        assert r["frames"]["gap"][0] == float(f"{info['min_gap']:.6g}")
    assert all("frames" not in r for r in by_policy["goal"])
    got = safe_risky(back)
    assert got["frames_safe"] + got["frames_risky"] == sum(
        r["steps"] for r in by_policy["student-mdn"]
    )
    _assert_matches(got, _oracle(back, 0.8))
    # The metrics ignore the frames.
    stripped = [{k: v for k, v in r.items() if k != "frames"} for r in back]
    assert json.dumps(summarize(back), sort_keys=True) == json.dumps(
        summarize(stripped), sort_keys=True
    )


# ------------------------------------------------------------------------------ metrics
def test_summarize_ignores_frames():
    base = {
        "scenario": "hr-rl",
        "policy": "student-mdn",
        "event": "success",
        "time_s": 10.0,
        "path_length_m": 4.0,
        "min_gap_m": 0.5,
        "time_close_s": 1.0,
        "steps": 3,
    }
    frames = {"clearance": [0.5, None, 1.0], "aleatoric": [0.1, 0.2, None], "epistemic": [0.1] * 3}
    recs = [
        {**base, "seed": 0, "trial": 0, "frames": frames},
        {**base, "seed": 1, "trial": 0, "event": "collision", "frames": frames},
        {**base, "seed": 1, "trial": 1, "policy": "goal"},  # no frames
    ]
    stripped = [{k: v for k, v in r.items() if k != "frames"} for r in recs]
    with_frames = summarize(recs)
    assert set(with_frames) == {"hr-rl/goal", "hr-rl/student-mdn"}
    assert json.dumps(with_frames, sort_keys=True) == json.dumps(
        summarize(stripped), sort_keys=True
    )
    assert with_frames["hr-rl/student-mdn"]["success_rate"]["mean"] == 50.0


def test_episode_record_without_frames_round_trips():
    rec = EpisodeRecord("hr-rl", "goal", 0, "timeout", 30.0, 5.0, math.inf, 0.0, 300)
    d = rec.to_dict()
    assert "frames" not in d and d["min_gap_m"] is None
    with_frames = dataclasses.replace(
        rec, frames={"clearance": [math.inf, 0.1234567], "aleatoric": [math.nan, 1.0]}
    )
    assert with_frames.to_dict()["frames"] == {
        "clearance": [None, 0.123457],
        "aleatoric": [None, 1.0],
    }
