"""The shared DAgger round loop (``pioneer.imitation.rounds``) with a cheap fake method: who
drives each round, the aggregate and its order, resume (existing episodes and models kept,
only the missing collected or fitted, half-written files removed), refused settings that
write nothing, and collection in worker processes.

The fake "model" is one number: the mean of the aggregate's ``x`` plus the previous model's
value; an episode records the round, its index and the value of the model that drove it.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pioneer.errors import ConfigError, DataError
from pioneer.imitation import Collector, Fitted, RunFolder, Step, run_rounds, save_episode
from pioneer.io import write_text_atomic
from pioneer_testutils import assert_house_message, file_tree

SIZES = [3, 2, 2]  # round 0 (expert) and two later rounds
SETTINGS = {"seed": 0, "episodes": [3, 2], "rounds": 2}


def _model_value(path: str | None) -> float:
    return 0.0 if path is None else float(json.loads(Path(path).read_text())["value"])


def collect(args: tuple[int, int, str, str | None, float]) -> str:
    """The fake Collector function (top level: workers import it). ``delay`` makes later
    episodes finish first in a pool."""
    rnd, index, path, driver, delay = args
    time.sleep(delay)
    x = np.array([rnd, index, _model_value(driver)], dtype=np.float64)
    return save_episode(path, {"x": x, "steps": np.arange(index + 1)})


class Fake:
    """A :class:`pioneer.imitation.Method` of numbers; counts what it is asked to do."""

    def __init__(self, delay: float = 0.0) -> None:
        self.delay = delay
        self.tasks: list[tuple[int, int]] = []
        self.fits: list[int] = []

    def task(self, rnd: int, index: int, path: Path, driver: Path | None) -> Any:
        self.tasks.append((rnd, index))
        delay = self.delay * (3 - index)
        return (rnd, index, str(path), None if driver is None else str(driver), delay)

    def aggregate(self, episodes: Sequence[Mapping[str, Any]]) -> np.ndarray:
        return np.stack([e["x"] for e in episodes])

    def loss(self, model: float, data: np.ndarray) -> float:
        return float(np.mean(np.abs(data[:, 0] - model)))

    def fit(self, step: Step[np.ndarray, float]) -> tuple[float, dict[str, Any]]:
        self.fits.append(step.round)
        model = float(step.data[:, 0].mean() + step.data[:, 1].sum()) + (step.previous or 0.0)
        return model, {"round": step.round, "frames": len(step.data)}

    def save(self, model: float, path: Path, info: dict[str, Any]) -> None:
        write_text_atomic(path, json.dumps({"value": model, "info": info}))

    def load(self, path: Path) -> tuple[float, dict[str, Any]]:
        doc = json.loads(path.read_text())
        return float(doc["value"]), doc["info"]


def _folder(root: Path) -> RunFolder:
    return RunFolder(root, "model.json", "fake DAgger", defaults={"seed": 0}, free=("rounds",))


def _run(
    root: Path, method: Fake | None = None, workers: int = 1, settings: dict[str, Any] = SETTINGS
) -> list[Fitted[np.ndarray, float]]:
    folder = _folder(root)
    folder.prepare(settings)
    gen = run_rounds(folder, SIZES, method or Fake(), Collector(collect, None, workers))
    return list(gen)


@pytest.fixture
def reference(tmp_path: Path) -> tuple[Path, list[Fitted[np.ndarray, float]]]:
    root = tmp_path / "reference"
    return root, _run(root)


def _files(root: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
    }


def test_round_zero_is_the_experts_and_each_later_round_the_previous_model(reference):
    root, rounds = reference
    assert [r.step.round for r in rounds] == [0, 1, 2]
    assert all(r.fitted for r in rounds)
    for r, done in enumerate(rounds):
        drivers = {float(e["x"][2]) for e in done.step.episodes}
        assert drivers == {0.0 if r == 0 else rounds[r - 1].model}
        assert done.step.previous == (None if r == 0 else rounds[r - 1].model)
        assert _model_value(str(root / f"rounds/round-{r:02d}/model.json")) == done.model
    assert math.isnan(rounds[0].step.loss_new)
    # the previous model's loss on the new round only, not on the aggregate
    assert rounds[1].step.loss_new == pytest.approx(abs(1.0 - rounds[0].model))
    assert sorted(_files(root)) == [
        "config.json",
        *(f"rounds/round-{r:02d}/{f}" for r, n in enumerate(SIZES)
          for f in [*(f"ep-{i:03d}.npz" for i in range(n)), "model.json"]),
    ]  # fmt: skip
    assert json.loads((root / "config.json").read_text()) == SETTINGS


def test_the_aggregate_is_every_round_so_far_in_round_and_episode_order(reference):
    _, rounds = reference
    for done in rounds:
        rows = [(int(a), int(b)) for a, b, _ in done.step.data]
        assert rows == [(r, i) for r in range(done.step.round + 1) for i in range(SIZES[r])]
        assert [int(e["x"][1]) for e in done.step.episodes] == list(range(SIZES[done.step.round]))


@pytest.mark.slow
def test_workers_finishing_out_of_order_give_the_same_files(reference, tmp_path):
    """Two workers, later episodes finishing first: the same files, the same aggregate."""
    root, rounds = reference
    again = _run(tmp_path / "pool", Fake(delay=0.2), workers=2)
    assert _files(tmp_path / "pool") == _files(root)
    for a, b in zip(rounds, again, strict=True):
        np.testing.assert_array_equal(a.step.data, b.step.data)


def test_a_finished_run_reruns_without_collecting_or_fitting(reference):
    root, rounds = reference
    before = _files(root)
    method = Fake()
    again = _run(root, method)
    assert method.tasks == [] and method.fits == []
    assert not any(r.fitted for r in again)
    assert [(r.model, r.info) for r in again] == [(r.model, r.info) for r in rounds]
    assert _files(root) == before


def test_an_interrupted_run_collects_only_the_missing_and_ends_the_same(reference, tmp_path):
    root, _ = reference
    run = tmp_path / "run"
    for name, data in _files(root).items():
        (run / name).parent.mkdir(parents=True, exist_ok=True)
        (run / name).write_bytes(data)
    (run / "rounds/round-01/ep-001.npz").unlink()
    for r in (1, 2):
        (run / f"rounds/round-{r:02d}/model.json").unlink()
    for r in (2,):
        for p in (run / f"rounds/round-{r:02d}").glob("ep-*.npz"):
            p.unlink()
    partial = run / "rounds/round-02/.ep-000.npz.a1b2c3d4.npz"  # a killed write's leftover
    partial.write_bytes(b"half an episode")
    method = Fake()
    again = _run(run, method)
    assert method.tasks == [(1, 1), (2, 0), (2, 1)]
    assert method.fits == [1, 2]
    assert [r.fitted for r in again] == [False, True, True]
    assert not partial.exists()
    assert _files(run) == _files(root)


def test_other_settings_are_refused_in_one_line_and_nothing_is_written(reference):
    root, _ = reference
    before = file_tree(root)
    with pytest.raises(ConfigError) as err:
        _run(root, settings={**SETTINGS, "seed": 1, "episodes": (3, 2)})
    msg = str(err.value)
    assert "\n" not in msg
    assert_house_message(msg, "fake DAgger settings seed", "{'seed': 0}", "{'seed': 1}", "--out")
    assert "episodes" not in msg.split(": expected")[0]  # a tuple equals the stored list
    assert file_tree(root) == before


def test_a_corrupt_episode_file_is_reported_with_the_fix(reference):
    root, _ = reference
    (root / "rounds/round-01/ep-000.npz").write_bytes(b"not an npz")
    with pytest.raises(DataError) as err:
        _run(root)
    assert_house_message(str(err.value), "fake DAgger episode", "ep-000.npz", "delete that file")
