"""``pioneer calibrate``: world statistics on validation seeds (docs/calibration.md)."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pioneer.cli import main
from pioneer.eval.harness import PolicySpec, episode_seed, made_by
from pioneer.experiments.calibration import BANDS, _humans_alone, _path_distance, calibrate
from pioneer.io import to_json
from pioneer.seeds import TRAINING_BASE, VALIDATION_BASE, training_seed, validation_seed
from pioneer.sim import get_scenario, sample_state

KEYS = (
    "teacher_path_length_m",
    "teacher_time_s",
    "teacher_risky_frame_share",
    "teacher_risky_frame_share_gap",
    "risky_at_start_share",
    "humans_alone_done_share",
    "careless_collision_share",
    "human_deflection_m",
)

coords = st.floats(-5.0, 5.0, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(
    points=st.lists(st.tuples(coords, coords), min_size=1, max_size=6),
    path=st.lists(st.tuples(coords, coords), min_size=1, max_size=6),
)
def test_path_distance_matches_a_dense_sampling_oracle(points, path):
    p, q = np.array(points), np.array(path)
    got = _path_distance(p, q)
    # Oracle: the polyline sampled densely (an upper bound within the sampling step).
    dense = [q[0]]
    for a, b in itertools.pairwise(q):
        dense.extend(a + np.linspace(0.0, 1.0, 2001)[1:, None] * (b - a))
    dense_arr = np.array(dense)
    oracle = np.linalg.norm(p[:, None] - dense_arr[None], axis=2).min(axis=1)
    step = max((np.linalg.norm(b - a) for a, b in itertools.pairwise(q)), default=0)
    assert np.all(got <= oracle + 1e-9)
    assert np.all(oracle - got <= step / 2000 + 1e-9)


def test_seed_kinds_are_disjoint():
    evaluation = {
        episode_seed(s, k, t) for s in ("hr-rl", "hl-rr") for k in range(5) for t in range(100)
    }
    validation = {
        validation_seed("calibrate", s, k) for s in ("hr-rl", "hl-rr") for k in range(500)
    }
    training = {training_seed(o, k) for o in (0, 100_000) for k in range(500)}
    assert max(evaluation) < VALIDATION_BASE <= min(validation)
    assert max(validation) < TRAINING_BASE <= min(training)
    assert len(validation) == 1000  # no repeats within a kind


def test_humans_alone_finish_in_the_paper_world():
    sc = get_scenario("hr-rl")
    for k in range(3):
        s0 = sample_state(sc, np.random.default_rng(validation_seed("calibrate", "hr-rl", k)))
        done, states = _humans_alone(sc.world(), s0, sc.sim.time_limit)
        assert done and states[-1].t[0] < sc.sim.time_limit


def test_calibrate_writes_every_statistic(tmp_path):
    res = calibrate(["hr-rl"], 2, tmp_path, workers=1, progress=False, driver="goal")
    data = json.loads((tmp_path / "calibration.json").read_text())
    assert data == json.loads(to_json(res))  # strict JSON: an undefined mean is null
    st_ = data["scenarios"]["hr-rl"]
    for key in KEYS:
        assert key in st_
    assert set(st_["within_band"]) == set(BANDS)
    assert 0.0 <= st_["teacher_risky_frame_share"] <= st_["teacher_risky_frame_share_gap"] <= 1.0
    assert data["driver"] == "goal" and data["paper"]["hr-rl"]["teacher_path_length_m"] == 3.74
    rows = [json.loads(r) for r in (tmp_path / "episodes.jsonl").read_text().splitlines()]
    assert len(rows) == 2 and all(r["seed"] >= VALIDATION_BASE for r in rows)
    # each row names its driver as the evaluation's records do
    assert all(r["made_by"] == made_by(PolicySpec.make("goal"), "hr-rl") for r in rows)


def test_calibrate_is_reproducible(tmp_path):
    a = calibrate(["hl-rr"], 1, None, workers=1, progress=False, driver="goal")
    b = calibrate(["hl-rr"], 1, None, workers=1, progress=False, driver="goal")
    for res in (a, b):
        res.pop("elapsed_s")
    assert a == b


@pytest.mark.parametrize(
    ("argv", "fragment"),
    [
        (["--scenario", "nowhere"], "scenario"),
        (["--episodes", "0"], "--episodes"),
        (["--driver", "nobody"], "policy"),
    ],
)
def test_calibrate_cli_refuses_bad_input_in_one_line(tmp_path, capsys, argv, fragment):
    code = main(["calibrate", "--out", str(tmp_path / "c"), "--workers", "1", *argv])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and fragment in err
    assert not (tmp_path / "c" / "calibration.json").exists()
