"""Drawing: raster frames, GIFs and trajectory plots, all written atomically."""

from __future__ import annotations

import os

import numpy as np
import pytest
from PIL import Image

from pioneer.baselines.classic import GoalPolicy
from pioneer.eval import run_episode
from pioneer.io import atomic_path
from pioneer.sim import get_scenario, sample_state, scan, step
from pioneer.viz import plot_trajectory, render_frame, save_gif
from pioneer.viz.frames import HUMAN, ROBOT


@pytest.fixture(scope="module")
def scene():
    cfg = get_scenario("hr-rl")
    world = cfg.world()
    state = sample_state(cfg, np.random.default_rng(0))
    return world, state


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_render_frame_shape_and_content(scene):
    world, state = scene
    frame = render_frame(world, state)
    assert frame.dtype == np.uint8
    assert frame.ndim == 3 and frame.shape[2] == 3
    assert max(frame.shape[:2]) == pytest.approx(480, abs=1)
    colours = {tuple(c) for c in frame.reshape(-1, 3)[::7]}
    assert ROBOT in colours
    assert HUMAN in colours


def test_render_frame_size_rays_trail_and_batch_index(scene):
    world, state = scene
    ranges = scan(world, state)[0]
    trail = np.array([[0.0, -1.0], [0.1, -0.8], [0.2, -0.5]])
    small = render_frame(world, state, ranges=ranges, size=200, trail=trail)
    assert small.dtype == np.uint8
    assert max(small.shape[:2]) == pytest.approx(200, abs=1)
    plain = render_frame(world, state, size=200)
    assert not np.array_equal(small, plain)  # rays and trail were drawn
    batch = state.repeat(2)
    batch.robot[1, :2] = [1.5, -1.0]
    a = render_frame(world, batch, index=0)
    b = render_frame(world, batch, index=1)
    assert not np.array_equal(a, b)
    np.testing.assert_array_equal(a, render_frame(world, state))


def test_save_gif_writes_atomically(scene, tmp_path):
    world, state = scene
    frames = []
    for _ in range(4):
        frames.append(render_frame(world, state, size=160))
        state = step(world, state, [0.5, 0.3])
    path = tmp_path / "anim.gif"
    save_gif(frames, path, fps=10)
    assert sorted(os.listdir(tmp_path)) == ["anim.gif"]  # no temporary files left behind
    with Image.open(path) as im:
        assert im.format == "GIF"
        assert im.n_frames == 4
        assert im.size == (frames[0].shape[1], frames[0].shape[0])
    assert os.stat(path).st_mode & 0o777 == 0o666 & ~_current_umask()


def test_save_gif_creates_missing_folders(scene, tmp_path):
    world, state = scene
    path = tmp_path / "a" / "b" / "one.gif"
    save_gif([render_frame(world, state, size=100)], path)
    assert path.is_file()
    with Image.open(path) as im:
        assert im.n_frames == 1


def test_save_gif_empty_raises_without_creating_file(tmp_path):
    path = tmp_path / "empty.gif"
    with pytest.raises(ValueError, match="expected at least one frame"):
        save_gif([], path)
    assert not path.exists()
    assert os.listdir(tmp_path) == []


def test_failed_save_keeps_old_file_and_leaves_no_temp(scene, tmp_path):
    world, state = scene
    path = tmp_path / "keep.gif"
    save_gif([render_frame(world, state, size=100)], path)
    before = path.read_bytes()
    with pytest.raises(TypeError):
        save_gif([np.zeros((10, 10, 3), dtype=object)], path)
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["keep.gif"]


def test_atomic_path_cleans_up_on_error(tmp_path):
    target = tmp_path / "data.bin"
    target.write_bytes(b"old")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        assert tmp.parent == tmp_path
        assert tmp != target
        tmp.write_bytes(b"half-written")
        raise RuntimeError("crash")
    assert target.read_bytes() == b"old"
    assert os.listdir(tmp_path) == ["data.bin"]
    with atomic_path(target) as tmp:
        tmp.write_bytes(b"new")
        assert target.read_bytes() == b"old"  # not visible until the block succeeds
    assert target.read_bytes() == b"new"
    assert os.listdir(tmp_path) == ["data.bin"]


def test_plot_trajectory_writes_png(tmp_path):
    _, traj = run_episode("static", GoalPolicy(), seed=0, record=True)
    path = tmp_path / "plots" / "traj.png"
    plot_trajectory(traj.world, traj.states, path, title="static")
    assert os.listdir(path.parent) == ["traj.png"]
    with Image.open(path) as im:
        assert im.format == "PNG"
        assert im.size[0] > 100 and im.size[1] > 100
