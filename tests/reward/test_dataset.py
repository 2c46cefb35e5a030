"""The demonstration dataset: construction, validation, merge/filter, npz round trip."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import pioneer_testutils as tu
from pioneer.errors import DataError
from pioneer.reward.dataset import FORMAT, Dataset
from pioneer.reward.features import feature_map
from pioneer.sim.lidar import observation_names

COLUMNS = ("episode", "step", "time", "obs", "action", "gamma", "pose", "scenario", "seed")
SHIPPED = Path(__file__).resolve().parents[2] / "src" / "pioneer" / "data" / "demos"


def make_columns(
    n: int,
    rng: np.random.Generator,
    n_episodes: int = 3,
    n_scenarios: int = 1,
    gamma: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Valid columns with canonical dtypes (ranges ≥ 0, angles in [−π, π])."""
    obs = np.empty((n, 29), dtype=np.float32)
    obs[:, :26] = rng.uniform(0.0, 5.0, (n, 26))
    obs[:, 26:] = rng.uniform(-math.pi, math.pi, (n, 3))
    episode = np.sort(rng.integers(0, n_episodes, n)).astype(np.int64)
    return {
        "episode": episode,
        "step": np.arange(n, dtype=np.int64),
        "time": np.arange(n, dtype=np.float64) * 0.1,
        "obs": obs,
        "action": rng.uniform(-1.0, 1.0, (n, 2)),
        "gamma": rng.uniform(-1.0, 1.0, n) if gamma is None else np.asarray(gamma, float),
        "pose": rng.normal(size=(n, 3)),
        "scenario": rng.integers(0, n_scenarios, n).astype(np.int64),
        "seed": episode + 7,
    }


def make_dataset(n: int, rng: np.random.Generator, scenarios=("hr-rl",), **kw: Any) -> Dataset:
    cols = make_columns(n, rng, n_scenarios=len(scenarios), **kw)
    return Dataset.from_rows(cols, scenarios=scenarios, meta={"source": "test", "notes": "x"})


def assert_same_rows(a: Dataset, b: Dataset) -> None:
    for k in COLUMNS:
        va, vb = getattr(a, k), getattr(b, k)
        assert va.dtype == vb.dtype, k
        np.testing.assert_array_equal(va, vb, err_msg=k)


def write_npz(path: Path, arrays: dict[str, np.ndarray], meta: dict[str, Any] | None) -> Path:
    """A dataset file written by hand, mirroring Dataset.save (no pickle)."""
    payload = dict(arrays)
    if meta is not None:
        payload["metadata"] = np.array(json.dumps(meta))
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **payload)
    return path


GOOD_META = {"format": FORMAT, "scenarios": ["hr-rl"]}


# --------------------------------------------------------------------------- construction
def test_from_rows_casts_to_canonical_dtypes(rng):
    cols = make_columns(6, rng)
    loose: dict[str, Any] = {
        "episode": cols["episode"].astype(np.int32).tolist(),
        "step": cols["step"].astype(np.int16),
        "time": cols["time"].astype(np.float32),
        "obs": cols["obs"].astype(np.float64),
        "action": cols["action"].tolist(),
        "gamma": [1, -1, 1, 1, -1, 1],  # Python ints
        "pose": cols["pose"].astype(np.float32),
        "scenario": [0] * 6,
        "seed": cols["seed"].astype(np.uint8),
    }
    d = Dataset.from_rows(loose, scenarios=["static"])
    expected = {
        "episode": np.int64,
        "step": np.int64,
        "time": np.float64,
        "obs": np.float32,
        "action": np.float64,
        "gamma": np.float64,
        "pose": np.float64,
        "scenario": np.int64,
        "seed": np.int64,
    }
    for k, dt in expected.items():
        assert getattr(d, k).dtype == dt, k
    assert len(d) == 6
    np.testing.assert_array_equal(d.gamma, [1.0, -1.0, 1.0, 1.0, -1.0, 1.0])
    np.testing.assert_array_equal(d.episode, cols["episode"])
    np.testing.assert_allclose(d.obs, cols["obs"])
    assert d.scenarios == ("static",)
    assert d.n_positive == 4 and d.n_negative == 2


def test_columns_gives_one_empty_list_per_field():
    cols = Dataset.columns()
    assert set(cols) == set(COLUMNS)
    assert all(v == [] for v in cols.values())


def test_from_rows_missing_column_is_named(rng):
    cols = make_columns(4, rng)
    del cols["pose"]
    with pytest.raises(DataError) as exc:
        Dataset.from_rows(cols, scenarios=["hr-rl"])
    tu.assert_house_message(str(exc.value), "pose")


def test_summary_counts(rng):
    g = np.array([1.0, 1.0, -1.0, 0.0, 0.5, -0.2])
    cols = make_columns(6, rng, gamma=g, n_scenarios=2)
    cols["scenario"] = np.array([0, 0, 1, 1, 1, 0])
    cols["episode"] = np.array([0, 0, 1, 1, 2, 2])
    d = Dataset.from_rows(cols, scenarios=["hr-rl", "hl-rr"])
    assert d.summary() == {
        "samples": 6,
        "positive": 3,
        "negative": 2,
        "episodes": 3,
        "scenarios": {"hr-rl": 3, "hl-rr": 3},
    }


# --------------------------------------------------------------------------- validation
def _corrupt(cols: dict[str, np.ndarray], case: str) -> None:
    if case == "nan_obs":
        cols["obs"][3, 5] = np.nan
    elif case == "inf_time":
        cols["time"][1] = np.inf
    elif case == "nan_gamma":
        cols["gamma"][2] = np.nan
    elif case == "gamma_high":
        cols["gamma"][2] = 1.5
    elif case == "gamma_low":
        cols["gamma"][4] = -1.01
    elif case == "negative_range":
        cols["obs"][4, 0] = -0.1
    elif case == "angle":
        cols["obs"][1, 28] = 4.0
    elif case == "scenario_index":
        cols["scenario"][3] = 1
    elif case == "nan_action":
        cols["action"][0, 1] = np.nan
    elif case == "nan_pose":
        cols["pose"][5, 2] = np.nan


ROW_CASES = [
    ("nan_obs", "obs[row 3]"),
    ("inf_time", "time[row 1]"),
    ("nan_gamma", "gamma[row 2]"),
    ("gamma_high", "gamma[row 2]"),
    ("gamma_low", "gamma[row 4]"),
    ("negative_range", "obs[row 4]"),
    ("angle", "obs[row 1]"),
    ("scenario_index", "scenario[row 3]"),
    ("nan_action", "action[row 0]"),
    ("nan_pose", "pose[row 5]"),
]


@pytest.mark.parametrize(("case", "needle"), ROW_CASES)
def test_from_rows_validation_names_field_and_row(rng, case, needle):
    cols = make_columns(8, rng)
    _corrupt(cols, case)
    with pytest.raises(DataError) as exc:
        Dataset.from_rows(cols, scenarios=["hr-rl"])
    tu.assert_house_message(str(exc.value), needle)


@pytest.mark.parametrize(
    ("field", "shape", "needle"),
    [
        ("obs", (8, 28), "obs"),
        ("action", (8, 3), "action"),
        ("pose", (7, 3), "pose"),
        ("time", (9,), "time"),
        ("episode", (8, 1), "episode"),
    ],
)
def test_from_rows_wrong_shape_is_named(rng, field, shape, needle):
    cols = make_columns(8, rng)
    cols[field] = np.zeros(shape)
    with pytest.raises(DataError) as exc:
        Dataset.from_rows(cols, scenarios=["hr-rl"])
    tu.assert_house_message(str(exc.value), needle, "shape")


def test_empty_dataset_is_refused(rng):
    cols = {k: v[:0] for k, v in make_columns(4, rng).items()}
    with pytest.raises(DataError) as exc:
        Dataset.from_rows(cols, scenarios=["hr-rl"])
    tu.assert_house_message(str(exc.value), "gamma")


def test_direct_construction_is_validated(rng):
    cols = make_columns(5, rng)
    cols["gamma"][0] = 3.0
    with pytest.raises(DataError, match=r"gamma\[row 0\]"):
        Dataset(**cols, scenarios=("hr-rl",))


# --------------------------------------------------------------------------- queries
def test_filter_by_gamma(rng):
    g = np.array([-1.0, -0.6, -0.2, 0.0, 0.3, 0.9, 1.0, -1.0])
    d = make_dataset(8, rng, gamma=g)
    pos = d.filter(min_gamma=0.0)
    np.testing.assert_array_equal(pos.gamma, [0.0, 0.3, 0.9, 1.0])
    np.testing.assert_array_equal(pos.step, [3, 4, 5, 6])
    assert pos.n_negative == 0 and pos.n_positive == 3
    neg = d.filter(max_gamma=-0.5)
    np.testing.assert_array_equal(neg.gamma, [-1.0, -0.6, -1.0])
    np.testing.assert_array_equal(neg.obs, d.obs[[0, 1, 7]])
    mid = d.filter(-0.6, 0.3)
    np.testing.assert_array_equal(mid.gamma, [-0.6, -0.2, 0.0, 0.3])
    assert len(d.filter()) == len(d)
    assert pos.meta == d.meta and pos.scenarios == d.scenarios


def test_filter_to_nothing_is_refused(rng):
    d = make_dataset(5, rng, gamma=np.full(5, -1.0))
    with pytest.raises(DataError, match="at least one sample"):
        d.filter(min_gamma=0.0)


def test_select_keeps_rows_in_order(rng):
    d = make_dataset(10, rng)
    mask = np.zeros(10, bool)
    mask[[1, 4, 9]] = True
    s = d.select(mask)
    for k in COLUMNS:
        np.testing.assert_array_equal(getattr(s, k), getattr(d, k)[mask])


# --------------------------------------------------------------------------- merge
def test_merge_keeps_episodes_distinct_and_unions_scenarios(rng):
    a = make_dataset(12, rng, scenarios=("hr-rl",), n_episodes=3)
    b = make_dataset(9, rng, scenarios=("hl-rr", "hr-rl"), n_episodes=2)
    c = make_dataset(5, rng, scenarios=("static",), n_episodes=2)
    m = Dataset.merge([a, b, c])
    assert len(m) == len(a) + len(b) + len(c)
    assert m.scenarios == ("hr-rl", "hl-rr", "static")
    parts = [a, b, c]
    starts = np.cumsum([0, *[len(p) for p in parts]])
    ids = [set(m.episode[s:e].tolist()) for s, e in itertools.pairwise(starts)]
    # no episode id shared between parts; within a part the grouping is unchanged
    assert not (ids[0] & ids[1]) and not (ids[0] & ids[2]) and not (ids[1] & ids[2])
    for p, s in zip(parts, starts, strict=False):
        mp = m.episode[s : s + len(p)]
        assert len(set(zip(p.episode.tolist(), mp.tolist(), strict=True))) == len(set(mp.tolist()))
        # every row keeps its scenario *name*
        names_before = [p.scenarios[i] for i in p.scenario]
        names_after = [m.scenarios[i] for i in m.scenario[s : s + len(p)]]
        assert names_before == names_after
        np.testing.assert_array_equal(m.obs[s : s + len(p)], p.obs)
        np.testing.assert_array_equal(m.gamma[s : s + len(p)], p.gamma)
    assert m.summary()["episodes"] == sum(p.summary()["episodes"] for p in parts)
    assert m.meta["source"] == "merge" and m.meta["parts"] == ["test"] * 3


def test_merge_with_itself_doubles_the_episodes(rng):
    a = make_dataset(10, rng, n_episodes=4)
    m = Dataset.merge([a, a])
    n_ep = np.unique(a.episode).size
    assert np.unique(m.episode).size == 2 * n_ep
    assert m.scenarios == a.scenarios


def test_merge_of_nothing_is_refused():
    with pytest.raises(DataError) as exc:
        Dataset.merge([])
    tu.assert_house_message(str(exc.value), "merge")


@settings(max_examples=30, deadline=None)
@given(
    st.lists(
        st.lists(st.integers(0, 50), min_size=1, max_size=6),  # episode ids of each part
        min_size=1,
        max_size=4,
    ),
    st.integers(0, 2**32 - 1),
)
def test_merge_property_episode_ids_distinct(episode_lists, seed):
    rng = np.random.default_rng(seed)
    parts = []
    for eps in episode_lists:
        cols = make_columns(len(eps), rng)
        cols["episode"] = np.asarray(eps, dtype=np.int64)
        parts.append(Dataset.from_rows(cols, scenarios=["hr-rl"]))
    m = Dataset.merge(parts)
    offset = 0
    seen: set[int] = set()
    for p in parts:
        mp = m.episode[offset : offset + len(p)]
        # one-to-one map of the part's ids to the merged ids
        pairs = set(zip(p.episode.tolist(), mp.tolist(), strict=True))
        assert len(pairs) == len(set(p.episode.tolist())) == len(set(mp.tolist()))
        assert not (seen & set(mp.tolist()))
        seen |= set(mp.tolist())
        offset += len(p)


# --------------------------------------------------------------------------- I/O
def test_save_load_round_trip(tmp_path, rng):
    d = make_dataset(20, rng, scenarios=("hr-rl", "static"))
    p = tmp_path / "sub" / "demos.npz"
    d.save(p)
    e = Dataset.load(p)
    assert_same_rows(d, e)
    assert e.scenarios == d.scenarios
    assert e.meta["source"] == "test" and e.meta["notes"] == "x"
    assert e.meta["feature_names"] == observation_names()
    assert e.meta["action_names"] == ["v", "omega"]
    assert set(e.meta["units"]) >= {"time", "obs", "action", "pose", "gamma"}
    assert e.meta["n_samples"] == 20
    assert (e.meta["n_positive"], e.meta["n_negative"]) == (d.n_positive, d.n_negative)
    # a second round trip is a fixed point
    e.save(tmp_path / "again.npz")
    f = Dataset.load(tmp_path / "again.npz")
    assert_same_rows(d, f)
    assert f.meta == e.meta
    assert sorted(x.name for x in tmp_path.rglob("*")) == ["again.npz", "demos.npz", "sub"]


def test_saved_file_is_self_describing_without_pickle(tmp_path, rng):
    d = make_dataset(7, rng)
    p = tmp_path / "d.npz"
    d.save(p)
    with np.load(p, allow_pickle=False) as f:
        assert set(f.files) == {*COLUMNS, "metadata"}
        meta = json.loads(str(f["metadata"]))
        assert f["obs"].dtype == np.float32
    assert meta["format"] == FORMAT
    assert meta["scenarios"] == ["hr-rl"]


def test_saved_counts_describe_the_saved_rows(tmp_path, rng):
    d = make_dataset(12, rng, gamma=np.tile([1.0, -1.0], 6))
    d.save(tmp_path / "a.npz")
    pos = Dataset.load(tmp_path / "a.npz").filter(min_gamma=0.0)
    pos.save(tmp_path / "b.npz")
    meta = Dataset.load(tmp_path / "b.npz").meta
    assert (meta["n_samples"], meta["n_positive"], meta["n_negative"]) == (6, 6, 0)


def _arrays(rng: np.random.Generator, n: int = 8) -> dict[str, np.ndarray]:
    return make_columns(n, rng)


BAD_FILES = [
    ("nan_gamma", "gamma"),
    ("gamma_out_of_range", "gamma"),
    ("nan_obs", "obs"),
    ("obs_shape", "obs"),
    ("action_shape", "action"),
    ("pose_rows", "pose"),
    ("no_samples", "gamma"),
    ("missing_column", "seed"),
    ("int_as_float", "episode"),
    ("scenario_index", "scenario"),
]


@pytest.mark.parametrize(("case", "needle"), BAD_FILES)
def test_load_refuses_bad_files_naming_the_field(tmp_path, rng, case, needle):
    a = _arrays(rng)
    if case == "nan_gamma":
        a["gamma"][6] = np.nan
        needle = "gamma[row 6]"
    elif case == "gamma_out_of_range":
        a["gamma"][3] = -2.0
        needle = "gamma[row 3]"
    elif case == "nan_obs":
        a["obs"][2, 0] = np.nan
        needle = "obs[row 2]"
    elif case == "obs_shape":
        a["obs"] = a["obs"][:, :20]
    elif case == "action_shape":
        a["action"] = a["action"][:, :1]
    elif case == "pose_rows":
        a["pose"] = a["pose"][:5]
    elif case == "no_samples":
        a = {k: v[:0] for k, v in a.items()}
    elif case == "missing_column":
        del a["seed"]
    elif case == "int_as_float":
        a["episode"] = a["episode"].astype(np.float64)
    elif case == "scenario_index":
        a["scenario"][5] = 4
        needle = "scenario[row 5]"
    p = write_npz(tmp_path / f"{case}.npz", a, GOOD_META)
    with pytest.raises(DataError) as exc:
        Dataset.load(p)
    tu.assert_house_message(str(exc.value), needle)


def test_load_accepts_a_hand_written_valid_file(tmp_path, rng):
    a = _arrays(rng)
    e = Dataset.load(write_npz(tmp_path / "ok.npz", a, {**GOOD_META, "source": "hand"}))
    assert len(e) == 8 and e.meta["source"] == "hand"
    np.testing.assert_array_equal(e.gamma, a["gamma"])


@pytest.mark.parametrize(
    ("meta", "needle"),
    [
        (None, "metadata"),
        ({"format": "pioneer.demos/0", "scenarios": ["hr-rl"]}, "format"),
        ({"scenarios": ["hr-rl"]}, "format"),
    ],
)
def test_load_refuses_bad_metadata(tmp_path, rng, meta, needle):
    p = write_npz(tmp_path / "m.npz", _arrays(rng), meta)
    with pytest.raises(DataError) as exc:
        Dataset.load(p)
    tu.assert_house_message(str(exc.value), needle)


def test_load_refuses_truncated_file(tmp_path, rng):
    p = tmp_path / "t.npz"
    make_dataset(50, rng).save(p)
    raw = p.read_bytes()
    p.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(DataError) as exc:
        Dataset.load(p)
    tu.assert_house_message(str(exc.value), "truncated")


@pytest.mark.parametrize(
    ("content", "name"), [(b"", "empty.npz"), (b"not a zip at all", "junk.npz")]
)
def test_load_refuses_non_npz(tmp_path, content, name):
    p = tmp_path / name
    p.write_bytes(content)
    with pytest.raises(DataError) as exc:
        Dataset.load(p)
    tu.assert_house_message(str(exc.value), name)


def test_load_missing_file(tmp_path):
    with pytest.raises(DataError) as exc:
        Dataset.load(tmp_path / "nope.npz")
    tu.assert_house_message(str(exc.value), "nope.npz")


def test_load_refuses_corrupted_compressed_bytes(tmp_path, rng):
    p = tmp_path / "c.npz"
    make_dataset(200, rng).save(p)
    raw = bytearray(p.read_bytes())
    for i in range(100, 164):  # inside the first compressed member
        raw[i] ^= 0xFF
    p.write_bytes(bytes(raw))
    with pytest.raises(DataError):
        Dataset.load(p)


# --------------------------------------------------------------------------- shipped data
@pytest.mark.parametrize(
    ("name", "n_pos", "n_neg"),
    [("hr-rl", 732, 170), ("hl-rr", 662, 194), ("static", 446, 337)],
)
def test_shipped_datasets_load_with_the_documented_counts(name, n_pos, n_neg):
    d = Dataset.load(SHIPPED / f"{name}.npz")
    assert (d.n_positive, d.n_negative, len(d)) == (n_pos, n_neg, n_pos + n_neg)
    assert d.scenarios == (name,)
    assert set(np.unique(d.gamma).tolist()) == {-1.0, 1.0}
    assert d.obs.dtype == np.float32 and d.obs.shape == (len(d), 29)
    assert d.meta["source"] == ("scripted" if name == "static" else "rules-only teacher")
    # every episode is one sign only and its steps are consecutive
    for e in np.unique(d.episode):
        m = d.episode == e
        assert np.unique(d.gamma[m]).size == 1
        np.testing.assert_array_equal(np.diff(d.step[m]), 1)


def _readme_rows() -> dict[str, list[str]]:
    """The statistics table of the shipped demos' README, by file stem."""
    rows = {}
    for line in (SHIPPED / "README.md").read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells and cells[0].startswith("`") and cells[0].endswith(".npz`"):
            rows[cells[0].strip("`").removesuffix(".npz")] = cells[1:]
    return rows


@pytest.mark.parametrize("name", ["hr-rl", "hl-rr", "static"])
def test_shipped_datasets_match_their_readme(name):
    """The README's table is the files' own statistics (counts, kept positive episodes and
    their mean time, path length and closest approach), to its printed digits."""
    row = _readme_rows()[name]
    d = Dataset.load(SHIPPED / f"{name}.npz")
    ep = d.meta["positive_episodes"]
    assert [int(row[0]), int(row[1]), int(row[2])] == [d.n_positive, d.n_negative, ep["episodes"]]
    assert float(row[3]) == pytest.approx(ep["time_mean_s"], abs=0.005)
    assert float(row[4]) == pytest.approx(ep["path_length_mean_m"], abs=0.005)
    assert float(row[5]) == pytest.approx(ep["min_gap_mean_m"], abs=0.0005)
    # and the statistics are those of the kept episodes in the file
    pos = d.select(d.gamma > 0)
    assert np.unique(pos.episode).size == ep["episodes"]
    if name != "static":
        sel = d.meta["selection"]
        assert (
            ep["time_mean_s"] <= sel["max_time_s"] and ep["path_length_mean_m"] <= sel["max_path_m"]
        )


# --------------------------------------------------------------------------- feature maps
def test_feature_maps(rng):
    d = make_dataset(6, rng)
    xy = feature_map("xy")
    np.testing.assert_array_equal(xy.from_dataset(d), d.pose[:, :2])
    assert xy.names == ("x", "y")
    oa = feature_map("obs_action")
    z = oa.from_dataset(d)
    assert z.shape == (6, 31) and z.dtype == np.float64
    np.testing.assert_array_equal(z[:, :29], d.obs.astype(np.float64))
    np.testing.assert_array_equal(z[:, 29:], d.action)
    assert len(oa.names) == 31 and oa.names[-2:] == ("v", "omega")
    with pytest.raises(DataError) as exc:
        feature_map("pixels")
    tu.assert_house_message(str(exc.value), "pixels")
