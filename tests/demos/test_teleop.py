"""Keyboard teleoperation: the pure controller, labelling, and a headless pygame session.

The session tests run pygame with the dummy video driver and drive it by posting KEYDOWN
events between ticks, so every run is deterministic and needs no display.
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest
from PIL import Image

from pioneer.cli import main
from pioneer.demos.generate import NEGATIVE_WINDOW, negative_frames
from pioneer.demos.teleop import (
    TeleopController,
    TeleopSession,
    TeleopUnavailableError,
    label_episode,
)
from pioneer.errors import ConfigError, DataError, PioneerError
from pioneer.reward.dataset import Dataset

DT = 0.1
OMEGA_MAX = 0.4 * math.pi


# ---------------------------------------------------------------------------------- pure parts
def test_controller_without_pygame(monkeypatch):
    monkeypatch.setitem(sys.modules, "pygame", None)  # any `import pygame` now fails
    c = TeleopController()
    assert (c.v, c.omega) == (0.0, 0.0)
    for _ in range(3):
        assert c.press("up") is None
    assert c.v == 0.3  # stays on the 0.1 grid
    for _ in range(20):
        c.press("up")
    assert c.v == 0.8
    c.press("down")
    assert c.v == 0.7
    for _ in range(20):
        c.press("down")
    assert c.v == 0.0
    c.press("left")
    assert c.omega == 0.2
    for _ in range(20):
        c.press("left")
    assert c.omega == pytest.approx(OMEGA_MAX)
    for _ in range(40):
        c.press("right")
    assert c.omega == pytest.approx(-OMEGA_MAX)
    c.press("up")
    c.press("space")
    np.testing.assert_array_equal(c.command, [0.0, 0.0])
    assert not c.marking_negative
    c.press("n")
    assert c.negative and c.marking_negative
    c.press("n")  # N toggles
    assert not c.negative
    c.press("b")
    assert c.span_open and c.marking_negative
    c.press("b")
    assert not c.span_open
    assert c.press("r") == "restart"
    assert c.press("escape") == "quit"
    assert c.press("x") is None
    c.press("up")
    c.press("left")
    c.press("n")
    c.press("b")
    c.new_episode()
    assert (c.v, c.omega, c.negative, c.span_open) == (0.0, 0.0, False, False)


def _frames(n: int, span: tuple[int, int] = (0, 0)) -> list[dict[str, Any]]:
    return [{"step": k, "time": round(k * DT, 9), "span": span[0] <= k < span[1]} for k in range(n)]


def test_label_episode_rules():
    # default +1
    np.testing.assert_array_equal(label_episode(_frames(5), "success", False, DT), np.ones(5))
    # N: the whole episode
    np.testing.assert_array_equal(label_episode(_frames(5), "restart", True, DT), -np.ones(5))
    # B span: frames recorded while the span was open
    g = label_episode(_frames(8, span=(2, 5)), "timeout", False, DT)
    np.testing.assert_array_equal(g, [1, 1, -1, -1, -1, 1, 1, 1])
    # collision: exactly the frames negative_frames selects (the last 1.0 s)
    frames = _frames(25)
    g = label_episode(frames, "collision", False, DT)
    last = negative_frames(frames, DT)
    assert len(last) == round(NEGATIVE_WINDOW / DT) == 10
    np.testing.assert_array_equal(g, [1.0] * 15 + [-1.0] * 10)
    # the window only adds negatives; a span before it stays negative
    g = label_episode(_frames(25, span=(0, 2)), "collision", False, DT)
    np.testing.assert_array_equal(g, [-1.0] * 2 + [1.0] * 13 + [-1.0] * 10)
    # no collision window without a collision
    np.testing.assert_array_equal(label_episode(frames, "quit", False, DT), np.ones(25))


def test_missing_pygame_is_a_one_line_cli_error(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "pygame", None)
    with pytest.raises(TeleopUnavailableError, match=r"pioneer-nav\[teleop\]") as info:
        TeleopSession("static", tmp_path / "d.npz")
    assert isinstance(info.value, ImportError) and isinstance(info.value, PioneerError)
    assert main(["teleop", "--scenario", "static", "--out", str(tmp_path / "d.npz")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pip install 'pioneer-nav[teleop]'" in err[0]
    assert not (tmp_path / "d.npz").exists()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="DISPLAY is X11's / Wayland's")
def test_no_display_is_a_one_line_cli_error(monkeypatch, tmp_path, capsys):
    """Without a display (and no SDL_VIDEODRIVER asking for a headless one) teleop refuses at
    once: SDL would otherwise fall back to a driver without a window and record a robot
    nobody can see."""
    for var in ("DISPLAY", "WAYLAND_DISPLAY", "SDL_VIDEODRIVER"):
        monkeypatch.delenv(var, raising=False)
    assert main(["teleop", "--scenario", "static", "--out", str(tmp_path / "d.npz")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "display" in err[0] and "fix:" in err[0]
    assert not any(tmp_path.iterdir())


def test_a_fallback_to_a_driver_without_a_window_is_refused(monkeypatch, tmp_path):
    """A display variable that names no usable display: SDL falls back to its offscreen
    driver, which teleop refuses unless SDL_VIDEODRIVER asked for it."""
    pygame = pytest.importorskip("pygame")
    monkeypatch.delenv("SDL_VIDEODRIVER", raising=False)
    monkeypatch.setenv("DISPLAY", ":99")
    monkeypatch.setattr(pygame.display, "init", lambda: None)
    monkeypatch.setattr(pygame.display, "get_driver", lambda: "offscreen")
    with pytest.raises(PioneerError, match="offscreen"):
        TeleopSession("static", tmp_path / "d.npz")
    assert not any(tmp_path.iterdir())


# ---------------------------------------------------------------------------------- sessions
@pytest.fixture
def pg(monkeypatch) -> Any:
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    monkeypatch.setenv("SDL_AUDIODRIVER", "dummy")
    monkeypatch.setenv("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    import pygame

    return pygame


@pytest.fixture
def make_session(pg, tmp_path) -> Iterator[Callable[..., TeleopSession]]:
    sessions: list[TeleopSession] = []

    def make(scenario: str = "static", **kw: Any) -> TeleopSession:
        kw.setdefault("realtime", False)
        s = TeleopSession(scenario, kw.pop("out", tmp_path / "demos.npz"), **kw)
        sessions.append(s)
        return s

    yield make
    for s in sessions:
        s.close()


def press(pg: Any, *keys: str) -> None:
    """Post one KEYDOWN event per key name (pygame's K_<name> constants)."""
    for k in keys:
        code = getattr(pg, "K_ESCAPE" if k == "escape" else f"K_{k.upper() if len(k) > 1 else k}")
        pg.event.post(pg.event.Event(pg.KEYDOWN, key=code))


def ticks(s: TeleopSession, n: int) -> None:
    for _ in range(n):
        assert s.tick()


def drive_to_collision(pg: Any, s: TeleopSession, limit: int = 200) -> None:
    """Full speed straight ahead: in "static" the robot starts below the human, facing it."""
    saved = s.episodes_saved
    press(pg, *["up"] * 8)
    for _ in range(limit):
        s.tick()
        if s.episodes_saved > saved:
            return
    raise AssertionError("no collision")


def test_up_presses_raise_v_and_are_recorded(pg, make_session):
    s = make_session()
    press(pg, "up", "up", "up")
    assert s.tick()
    assert s.controller.v == 0.3
    np.testing.assert_allclose(s.frames[-1]["action"], [0.3, 0.0])
    press(pg, "left", "down")
    assert s.tick()
    np.testing.assert_allclose(s.frames[-1]["action"], [0.2, 0.2])
    assert len(s.frames) == 2
    assert s.time == pytest.approx(0.2)
    assert "v 0.2 m/s" in s.status_line() and "NEGATIVE" not in s.status_line()


def test_collision_labels_last_second_and_saves_each_episode(pg, make_session, tmp_path):
    out = tmp_path / "demos.npz"
    s = make_session(out=out)
    drive_to_collision(pg, s)
    assert s.events == ["collision"]
    assert out.is_file()
    d = Dataset.load(out)
    assert d.scenarios == ("static",)
    assert np.unique(d.episode).tolist() == [0]
    np.testing.assert_array_equal(d.step, np.arange(len(d)))
    t_collision = d.time[-1] + DT
    expect = np.where(d.time >= t_collision - NEGATIVE_WINDOW - 1e-9, -1.0, 1.0)
    np.testing.assert_array_equal(d.gamma, expect)
    assert d.n_negative == 10 and d.n_positive >= 5
    np.testing.assert_allclose(d.action[:, 0], 0.8)
    assert d.meta["source"] == "teleop"
    assert d.meta["teleop_episodes"][0]["event"] == "collision"

    # the next episode starts stopped, with a new seed, and is appended to the same file
    assert s.controller.v == 0.0 and s.frames == []
    drive_to_collision(pg, s)
    d2 = Dataset.load(out)
    assert np.unique(d2.episode).tolist() == [0, 1]
    first = d2.episode == 0
    np.testing.assert_array_equal(d2.gamma[first], d.gamma)
    np.testing.assert_array_equal(d2.obs[first], d.obs)
    assert d2.seed[first][0] == 0 and d2.seed[~first][0] == 1
    assert [e["event"] for e in d2.meta["teleop_episodes"]] == ["collision", "collision"]


def test_n_marks_the_whole_episode_negative(pg, make_session, tmp_path):
    s = make_session()
    press(pg, "n")
    drive_to_collision(pg, s)
    d = Dataset.load(tmp_path / "demos.npz")
    assert len(d) > 10 and np.all(d.gamma == -1.0)
    assert not s.controller.negative  # marks are per episode


def test_b_span_labels_frames_between_presses(pg, make_session, tmp_path):
    s = make_session()
    ticks(s, 3)
    press(pg, "b")
    ticks(s, 4)
    assert "NEGATIVE (span)" in s.status_line()
    press(pg, "b")
    ticks(s, 3)
    press(pg, "r")  # restart: the unfinished episode is saved, the new one starts
    assert s.tick()
    d = Dataset.load(tmp_path / "demos.npz")
    np.testing.assert_array_equal(d.gamma, [1, 1, 1, -1, -1, -1, -1, 1, 1, 1])
    assert d.meta["teleop_episodes"][0]["event"] == "restart"
    assert len(s.frames) == 1 and s.episodes_started == 2


def test_open_span_runs_to_the_collision(pg, make_session, tmp_path):
    s = make_session()
    ticks(s, 2)
    press(pg, "b")
    drive_to_collision(pg, s)
    d = Dataset.load(tmp_path / "demos.npz")
    np.testing.assert_array_equal(d.gamma, [1.0, 1.0] + [-1.0] * (len(d) - 2))


def test_restart_without_frames_saves_nothing(pg, make_session, tmp_path):
    s = make_session()
    press(pg, "r")
    assert s.tick()
    assert not (tmp_path / "demos.npz").exists()
    assert s.episodes_saved == 0 and s.episodes_started == 2


@pytest.mark.parametrize("how", ["escape", "close"])
def test_quit_mid_episode_keeps_the_frames(pg, make_session, tmp_path, how):
    s = make_session()
    press(pg, "up")
    ticks(s, 5)
    if how == "escape":
        press(pg, "escape")
    else:
        pg.event.post(pg.event.Event(pg.QUIT))
    assert not s.tick()
    assert s.done
    d = Dataset.load(tmp_path / "demos.npz")
    assert len(d) == 5 and np.all(d.gamma == 1.0)
    assert d.meta["teleop_episodes"][0]["event"] == "quit"
    s.close()  # idempotent: nothing saved twice
    assert len(Dataset.load(tmp_path / "demos.npz")) == 5
    assert s.summary()["frames"] == 5


def test_run_until_escape_returns_summary(pg, make_session):
    s = make_session()
    press(pg, "n", "escape")
    summary = s.run()
    assert summary["episodes"] == 0 and summary["file"] is None  # no frame was recorded


def test_close_saves_the_unfinished_episode(pg, make_session, tmp_path):
    s = make_session()
    ticks(s, 4)
    s.close()
    assert len(Dataset.load(tmp_path / "demos.npz")) == 4


def test_max_episodes_and_appending_to_an_existing_file(pg, make_session, tmp_path):
    out = tmp_path / "demos.npz"
    s = make_session(out=out, max_episodes=1)
    press(pg, *["up"] * 8)
    n = 0
    while s.tick():
        n += 1
        assert n < 200
    assert s.done and s.events == ["collision"]
    first = Dataset.load(out)
    s2 = make_session(out=out, seed=7)
    ticks(s2, 3)
    s2.close()
    d = Dataset.load(out)
    assert len(d) == len(first) + 3
    assert np.unique(d.episode).tolist() == [0, 1]
    np.testing.assert_array_equal(d.gamma[: len(first)], first.gamma)
    assert d.seed[-1] == 7
    assert [e["event"] for e in d.meta["teleop_episodes"]] == ["collision", "quit"]


def test_appending_to_a_scripted_dataset_keeps_its_rows(pg, make_session, tmp_path):
    out = tmp_path / "demos.npz"
    s = make_session(out=out)
    ticks(s, 3)
    s.close()
    base = Dataset.load(out)
    scripted = Dataset.from_rows(
        {k: getattr(base, k) for k in Dataset.columns()},
        scenarios=["static"],
        meta={"source": "scripted"},
    )
    scripted.save(out)
    s2 = make_session(out=out)
    ticks(s2, 2)
    s2.close()
    d = Dataset.load(out)
    assert len(d) == 5
    assert d.meta["source"] == "merge" and d.meta["parts"] == ["scripted", "teleop"]
    s3 = make_session(out=out)
    ticks(s3, 1)
    s3.close()
    d = Dataset.load(out)
    assert len(d) == 6 and np.unique(d.episode).tolist() == [0, 1, 2]
    assert d.meta["parts"] == ["scripted", "teleop"]
    assert [e["event"] for e in d.meta["teleop_episodes"]] == ["quit", "quit"]


def test_bad_arguments_fail_before_the_window(pg, tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(DataError, match=r"bad\.npz"):
        TeleopSession("static", bad, realtime=False)
    assert bad.read_bytes() == b"not a zip"
    with pytest.raises(ConfigError, match="max_episodes"):
        TeleopSession("static", tmp_path / "d.npz", max_episodes=0)
    with pytest.raises(ConfigError, match="scenario"):
        TeleopSession("nope", tmp_path / "d.npz")


def test_window_shows_scene_and_status(pg, make_session, tmp_path):
    s = make_session("hr-rl")
    press(pg, "up", "left", "n")
    ticks(s, 3)
    assert "NEGATIVE (episode)" in s.status_line()
    assert "ω +0.20" in s.status_line()
    png = tmp_path / "shot.png"
    s.screenshot(png)
    with Image.open(png) as im:
        assert im.format == "PNG"
        w, h = im.size
        arr = np.asarray(im.convert("RGB"))
    assert w >= 600 and h > 400
    assert len(np.unique(arr.reshape(-1, 3), axis=0)) > 10  # something was drawn


def test_cli_teleop_prints_json_summary(pg, monkeypatch, tmp_path, capsys):
    original = TeleopSession.tick

    def scripted_tick(self: TeleopSession) -> bool:
        if not self.frames and self.episodes_saved == 0:
            self.realtime = False
            press(pg, *["up"] * 8)
        return original(self)

    monkeypatch.setattr(TeleopSession, "tick", scripted_tick)
    out = tmp_path / "cli.npz"
    argv = ["teleop", "--scenario", "static", "--out", str(out), "--max-episodes", "1"]
    assert main([*argv, "--seed", "3"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["episodes"] == 1 and summary["events"] == ["collision"]
    assert summary["file"]["negative"] == 10
    d = Dataset.load(out)
    assert np.all(d.seed == 3)


def test_cli_teleop_bad_max_episodes(tmp_path, capsys):
    argv = ["teleop", "--scenario", "static", "--out", str(tmp_path / "x.npz")]
    assert main([*argv, "--max-episodes", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "max_episodes" in err[0]
