"""A DAgger run on disk (``pioneer.imitation.store``): the layout, the settings check (one
line naming what differs, free settings, defaults for older runs), atomic episode files and
the count of what an interrupted run keeps."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pioneer.errors import ConfigError, DataError
from pioneer.imitation.store import RunFolder, check_settings, file_version, save_episode
from pioneer_testutils import assert_house_message, file_tree

SETTINGS = {"seed": 0, "net": {"hidden": (64, 64)}, "rounds": 2}


def _folder(root: Path) -> RunFolder:
    return RunFolder(root, "model.bin", "test", defaults={"lr": 0.001}, free=("rounds",))


def test_layout(tmp_path):
    f = _folder(tmp_path)
    assert f.episode_path(3, 7) == tmp_path / "rounds/round-03/ep-007.npz"
    assert f.model_path(12) == tmp_path / "rounds/round-12/model.bin"
    assert f.settings_path == tmp_path / "config.json"


def test_settings_are_recorded_and_a_rerun_must_match_them(tmp_path):
    f = _folder(tmp_path)
    f.check(SETTINGS)  # nothing there: anything goes
    f.prepare(SETTINGS)
    assert json.loads(f.settings_path.read_text()) == {**SETTINGS, "net": {"hidden": [64, 64]}}
    f.check({**SETTINGS, "rounds": 9})  # free
    f.check({**SETTINGS, "lr": 0.001})  # not in the file: its default
    before = file_tree(tmp_path)
    with pytest.raises(ConfigError) as err:
        f.prepare({**SETTINGS, "seed": 1, "lr": 0.01})
    msg = str(err.value)
    assert "\n" not in msg
    assert_house_message(msg, "test settings seed, lr", "{'seed': 0, 'lr': 0.001}", "--out")
    assert "received {'seed': 1, 'lr': 0.01}" in msg
    assert file_tree(tmp_path) == before


def test_a_setting_only_the_file_has_is_no_setting_any_more():
    check_settings("here", {"seed": 0, "gone": 1}, {"seed": 0}, "test")


def test_an_unreadable_settings_file_is_reported_with_the_fix(tmp_path):
    f = _folder(tmp_path)
    for text in ("{", "[1, 2]"):
        f.settings_path.write_text(text)
        with pytest.raises(DataError) as err:
            f.check(SETTINGS)
        assert_house_message(str(err.value), "config.json", "new --out")


def test_prepare_removes_what_killed_writes_left(tmp_path):
    f = _folder(tmp_path)
    save_episode(f.episode_path(0, 0), {"x": np.arange(3)})
    partial = f.round_dir(0) / ".ep-001.npz.k9J2xQ0a.npz"
    partial.write_bytes(b"half")
    f.prepare(SETTINGS)
    assert not partial.exists() and f.episode_path(0, 0).exists()


def test_episodes_are_written_whole_and_loaded_in_order(tmp_path):
    f = _folder(tmp_path)
    for i in (1, 0):
        assert save_episode(f.episode_path(2, i), {"x": np.full(2, i)}) == str(f.episode_path(2, i))
    assert [int(e["x"][0]) for e in f.load_round(2, 2)] == [0, 1]
    assert not list(tmp_path.rglob(".*"))
    with pytest.raises(DataError) as err:
        f.load_round(2, 3)
    assert_house_message(str(err.value), "test episode", "ep-002.npz")


def test_what_a_run_keeps_is_counted_from_the_disk(tmp_path):
    f = _folder(tmp_path)
    sizes = [2, 1, 1]
    for r, i in ((0, 0), (0, 1), (1, 0)):
        save_episode(f.episode_path(r, i), {"x": np.zeros(1)})
    f.model_path(0).write_bytes(b"m")
    assert f.missing(0, 2) == [] and f.missing(2, 1) == [0]
    assert f.on_disk(sizes) == (3, 1)
    assert f.kept(sizes) == f"3 of 4 episodes and 1 of 3 rounds kept in {tmp_path}"


def test_a_rewritten_file_has_a_new_version(tmp_path):
    p = tmp_path / "m.bin"
    p.write_bytes(b"one")
    first = file_version(p)
    p.write_bytes(b"three")
    assert file_version(p) != first and file_version(p)[0] == str(p)
