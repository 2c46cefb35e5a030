"""DAgger: distil the privileged teacher into a LiDAR-only student (paper §IV-B).

Round 0 collects ``teacher_episodes`` episodes driven by the teacher; each of the following
``rounds`` collects ``episodes_per_round`` episodes driven by the latest student, and the
teacher labels every state the student visits (Ross et al., AISTATS 2011, with β = 0 after
round 0). All labelled frames are aggregated and the student is retrained after every round.

Labels are the teacher's smoothed command u_t = α u* + (1 − α) u_{t−1}, u_{t−1} the command
applied (a frame's label is what the teacher would send had it been driving).

The round loop, the episode files and the resume are :mod:`pioneer.imitation` (shared with
CrowdNav++'s imitation warm start). Output directory (everything written atomically; a rerun
of the same command resumes; one run writes to it at a time, :func:`pioneer.io.run_lock`;
every input, the reward file included, is checked before the folder is created or changed)::

    DIR/config.json                      the DaggerConfig and the SHA-256 of the --reward file
                                         (a rerun must match both)
    DIR/scenario.json                    the scenario's full config (a rerun must match it)
                                         (a pattern such as ``general-*``: every match's)
    DIR/reward.npz                       the teacher's density reward (a pattern: reward-BASE.npz)
    DIR/rounds/round-RR/ep-EEE.npz       one labelled episode (obs, action, gap, …)
    DIR/rounds/round-RR/student.safetensors   the student trained after round RR
    DIR/curves.csv, DIR/curves.png       loss and student success per round
    DIR/selection.csv                    with ``select_episodes`` > 0: every round's student
                                         on the same validation episodes
    DIR/student.safetensors              the final student: the last round's (the paper's
                                         §V-B.2), or with ``select_episodes`` > 0 the round
                                         whose student succeeds most often on validation
                                         episodes (Ross et al., 2011, Algorithm 3.1: "return
                                         the best policy on validation"; ties: the later)

Episode seeds are training seeds (:func:`pioneer.seeds.dagger_seed` of scenario, seed, round,
episode), disjoint by construction from evaluation, validation and demonstration seeds. The
selection's episodes are validation seeds of their own purpose (``"dagger-select"``), the same
for every round and every DAgger seed, so no evaluation episode chooses a student and the
harness's validation episodes (``--seed-set validation``) stay unseen by the choice.

``--scenario`` may be a pattern (``general-*``): each episode then runs in one of the matching
scenarios, drawn by its seed, and the teacher plans with the reward of that scenario's base —
one student for many worlds (docs/student.md).

Retraining: round 0 trains a fresh network for ``epochs_initial`` epochs; later rounds go on
from the previous weights for ``epochs_per_round`` epochs over the whole aggregate (warm start).
The input/output standardisation is fitted on round 0's frames, with the fresh network, and
kept: re-fitting it under trained weights would move the network's function before training.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import math
import typing
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from pioneer.imitation.rounds import Collector, Step, run_rounds
from pioneer.imitation.rounds import one_thread as _worker_init
from pioneer.imitation.store import RunFolder
from pioneer.interrupt import kept
from pioneer.io import (
    atomic_path,
    file_sha256,
    run_lock,
    write_text_atomic,
)
from pioneer.laser import mirror_observation
from pioneer.learn.collect import CollectTask, DriveTask, clear_cache, collect_episode
from pioneer.learn.collect import collect_task as _collect_task
from pioneer.learn.collect import drive_task as _drive_task
from pioneer.learn.dagger_config import DaggerConfig
from pioneer.learn.dagger_folder import (
    FINAL_FILE,
    check_inputs,
    prepare,
    round_sizes,
    run_folder,
    scenario_set,
)
from pioneer.learn.models import (
    MDN,
    Student,
    build_student,
    load_student,
    read_checkpoint_meta,
    save_student,
)
from pioneer.learn.training import train_student
from pioneer.parallel import worker_count
from pioneer.progress import progress_bar
from pioneer.seeds import dagger_seed, validation_seed

__all__ = ["DaggerConfig", "DaggerResult", "collect_episode", "run_dagger", "scenario_set"]

SELECTION_FILE = "selection.csv"
SELECT_PURPOSE = "dagger-select"  # the validation seeds of the choice among rounds
QUANTILES = (0.5, 0.9, 0.95, 0.99)


@dataclasses.dataclass(frozen=True)
class DaggerResult:
    """Where the run wrote its outputs, and its per-round curve."""

    out: Path
    student: Path
    curves: list[dict[str, Any]]
    chosen: int  # the round whose student is ``student``
    selection: list[dict[str, Any]]  # every round's validation row (empty: no selection)


# ------------------------------------------------------------------------------ the method
# inputs, teacher labels, how often each frame counts in training (near_repeat) and, with
# target="scores", the weighted targets: commands (N, k, 2) and weights (N, k)
Data = tuple[
    NDArray[np.float32],
    NDArray[np.float32],
    NDArray[np.int64],
    tuple[NDArray[np.float32], NDArray[np.float32]] | None,
]


def score_weights(scores: NDArray[np.floating], temperature: float) -> NDArray[np.float32]:
    """softmax(score / τ) over each frame's candidates ``(N, k)``; −∞ (a candidate the teacher
    could not choose) weighs 0. Every frame has at least one finite score (the fallback's)."""
    z = np.asarray(scores, dtype=np.float64) / temperature
    z = z - z.max(axis=-1, keepdims=True)
    e = np.exp(z)
    out: NDArray[np.float32] = (e / e.sum(axis=-1, keepdims=True)).astype(np.float32)
    return out


def _episode_scenario(cfg: DaggerConfig, names: list[str], rnd: int, i: int) -> str:
    """The scenario of episode ``i`` of round ``rnd``: drawn from the run's set by its seed."""
    return names[dagger_seed(cfg.scenario, cfg.seed, rnd, i) % len(names)]


def _quantiles(model: Student, obs: NDArray[np.float32]) -> dict[str, dict[str, float]]:
    if not isinstance(model, MDN):
        return {}
    with torch.inference_mode():
        ale, epi = model.uncertainty(torch.as_tensor(obs))
    return {
        name: {str(q): float(np.quantile(v.numpy(), q)) for q in QUANTILES}
        for name, v in (("aleatoric", ale), ("epistemic", epi))
    }


def _curve_row(step: Step[Data, Student], history: list[float]) -> dict[str, Any]:
    rnd, eps = step.round, step.episodes
    events = [str(e["event"]) for e in eps]
    return {
        "round": rnd,
        "driver": "teacher" if rnd == 0 else "student",
        "episodes": len(eps),
        "frames_total": int(step.data[0].shape[0]),
        "success_rate": events.count("success") / len(events),
        "collision_rate": events.count("collision") / len(events),
        "mean_time_s": float(np.mean([float(e["time_s"]) for e in eps])),
        "loss_new_data": step.loss_new,
        "train_loss": history[-1] if history else math.nan,
    }


def _mirrored(episode: Mapping[str, Any]) -> dict[str, Any]:
    """The episode of the mirror-image world (x → −x): observations mirrored
    (:func:`pioneer.laser.mirror_observation`), the commands' ω negated, the gaps the same."""
    flip = np.array([1.0, -1.0])
    out = {
        **episode,
        "obs": mirror_observation(np.asarray(episode["obs"])),
        "applied": np.asarray(episode["applied"], dtype=np.float64) * flip,
        "action": np.asarray(episode["action"], dtype=np.float64) * flip,
    }
    if "target_commands" in episode:  # episodes collected before the scores were kept lack it
        out["target_commands"] = np.asarray(episode["target_commands"], dtype=np.float64) * flip
    return out


@dataclasses.dataclass(frozen=True)
class _Students:
    """DAgger's parts for the students (:class:`pioneer.imitation.rounds.Method`): episodes
    labelled by the teacher (:func:`~pioneer.learn.collect.collect_episode`); round 0 trains
    a fresh network, later rounds go on training the previous one on the whole aggregate."""

    cfg: DaggerConfig
    rewards: dict[str, Path]  # the teacher's reward file per scenario

    def task(self, rnd: int, index: int, path: Path, driver: Path | None) -> CollectTask:
        cfg = self.cfg
        name = _episode_scenario(cfg, sorted(self.rewards), rnd, index)
        seed = dagger_seed(cfg.scenario, cfg.seed, rnd, index)
        ckpt = None if driver is None else str(driver)
        return (
            name,
            str(self.rewards[name]),
            ckpt,
            seed,
            str(path),
            cfg.label_prev,
            cfg.margins,
            cfg.assume,
            cfg.patience,
        )

    def aggregate(self, episodes: Sequence[Mapping[str, Any]]) -> Data:
        """Inputs (the observation, and o_{t−1} or u_{t−1} for a student that reads them:
        :meth:`~pioneer.deploy.runtime.StudentInputs.of_episode`) and labels of every frame."""
        cfg = self.cfg
        if cfg.mirror:
            episodes = [*episodes, *map(_mirrored, episodes)]
        x = [cfg.student.inputs.of_episode(e["obs"], e["applied"]) for e in episodes]
        gap = np.concatenate([np.asarray(e["gap"], dtype=np.float64) for e in episodes])
        repeat = np.where(gap < cfg.near_gap, cfg.near_repeat, 1).astype(np.int64)
        labels = np.concatenate([e["action"] for e in episodes]).astype(np.float32)
        targets = None
        if cfg.target == "scores":
            commands = np.concatenate([e["target_commands"] for e in episodes])
            scores = np.concatenate([e["target_scores"] for e in episodes])
            targets = commands.astype(np.float32), score_weights(scores, cfg.score_temperature)
        return np.concatenate(x), labels, repeat, targets

    def loss(self, model: Student, data: Data) -> float:
        """``model``'s loss on frames it was not trained on (eval mode: dropout off)."""
        x, y, _, targets = data
        with torch.inference_mode():
            if targets is not None:
                c, w = (torch.as_tensor(a) for a in targets)
                return float(model.target_loss(torch.as_tensor(x), c, w))
            return float(model.loss(torch.as_tensor(x), torch.as_tensor(y)))

    def fit(self, step: Step[Data, Student]) -> tuple[Student, dict[str, Any]]:
        cfg, rnd = self.cfg, step.round
        model = step.previous
        fresh = model is None
        if model is None:
            model = build_student(cfg.student, seed=cfg.seed)
        epochs = cfg.epochs_initial if rnd == 0 else cfg.epochs_per_round
        x, y, repeat, targets = step.data
        x_fit, y_fit = x, y
        if (repeat != 1).any():  # near frames repeated (near_gap, near_repeat)
            x_fit, y_fit = np.repeat(x, repeat, axis=0), np.repeat(y, repeat, axis=0)
            if targets is not None:
                targets = (np.repeat(targets[0], repeat, 0), np.repeat(targets[1], repeat, 0))
        history: list[float] = []
        if epochs > 0:
            # The normalisation is fitted once, for the fresh network: re-fitting it under
            # warm-started weights would shift every input and output of a trained network.
            history = train_student(
                model, x_fit, y_fit, epochs=epochs, batch=cfg.batch, lr=cfg.lr, seed=cfg.seed + rnd,
                fit_normalizer=fresh, targets=targets,
            )  # fmt: skip
        info = {
            "scenario": cfg.scenario,
            "source": "dagger",
            "round": rnd,
            "dagger": cfg.to_dict(),
            "frames": int(x.shape[0]),
            "loss_history": history,
            "uncertainty_quantiles": _quantiles(model, x),
            "curve_row": _curve_row(step, history),
        }
        return model, info

    def save(self, model: Student, path: Path, info: dict[str, Any]) -> None:
        save_student(model, path, info)

    def load(self, path: Path) -> tuple[Student, dict[str, Any]]:
        info = read_checkpoint_meta(path)["info"]
        return load_student(path), dict(info) if isinstance(info, dict) else {}


# ------------------------------------------------------------------------------ driver
def _write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    """``rows`` (dicts with the same keys, the first's order) as a CSV file, atomically."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]))
    w.writeheader()
    w.writerows(rows)
    write_text_atomic(path, buf.getvalue())


def _write_curves(out: Path, rows: list[dict[str, Any]]) -> None:
    if not rows:
        return
    _write_csv(out / "curves.csv", rows)
    from pioneer.viz.student import plot_dagger_curves

    plot_dagger_curves(rows, out / "curves.png")


def run_dagger(
    config: DaggerConfig,
    out_dir: str | Path,
    workers: int | None = None,
    reward: str | Path | None = None,
    progress: bool = True,
    on_round: Callable[[dict[str, Any]], None] | None = None,
) -> DaggerResult:
    """Run (or resume) DAgger; returns the final student's path and the per-round curve.

    ``reward``: the teacher's density-reward file; default the reward fitted on the shipped
    demonstrations of the scenario (saved to ``DIR/reward.npz``).
    """
    out = Path(out_dir)
    names = check_inputs(config, out, reward)
    with run_lock(out):
        return _run(config, out, workers, prepare(config, out, reward, names), progress, on_round)


def _run(
    cfg: DaggerConfig,
    out: Path,
    workers: int | None,
    rewards: dict[str, Path],
    progress: bool,
    on_round: Callable[[dict[str, Any]], None] | None,
) -> DaggerResult:
    n_workers = worker_count(workers)
    # Train on one thread: float32 sums depend on the thread count, and the weights must not
    # depend on --workers or the machine (the networks are small; threads gain little).
    torch.set_num_threads(1)
    clear_cache()
    folder, sizes = run_folder(out), round_sizes(cfg)
    curves: list[dict[str, Any]] = []
    bar = progress_bar(
        total=cfg.total_episodes,
        initial=folder.on_disk(sizes)[0],
        desc="DAgger episodes",
        unit="ep",
        enabled=progress,
    )

    def start(rnd: int, todo: int) -> None:
        bar.set_postfix(round=rnd, driver="teacher" if rnd == 0 else "student")

    collector = Collector(_collect_task, _worker_init, n_workers)
    rounds = run_rounds(
        folder, sizes, _Students(cfg, rewards), collector, start, lambda: bar.update(1)
    )
    # closing: a stop between two rounds ends the collection's pool at once
    with kept(lambda: folder.kept(sizes)), bar, contextlib.closing(rounds):
        for done in rounds:
            history = [float(v) for v in done.info.get("loss_history", [])]
            curves.append(_curve_row(done.step, history))
            _write_curves(out, curves)
            if on_round is not None:
                on_round(curves[-1])
    chosen, selection = _select(cfg, folder, sorted(rewards), n_workers, progress)
    final = out / FINAL_FILE
    with atomic_path(final) as tmp:
        tmp.write_bytes(folder.model_path(chosen).read_bytes())
    return DaggerResult(out, final, curves, chosen, selection)


# ------------------------------------------------------------------------------ selection
def _drive_tasks(cfg: DaggerConfig, names: list[str], checkpoint: Path) -> list[DriveTask]:
    """The selection's episodes for one round's student: validation seeds of their own
    purpose, the scenario of each drawn from the run's set by its seed."""
    seeds = [validation_seed(SELECT_PURPOSE, cfg.scenario, k) for k in range(cfg.select_episodes)]
    return [(k, names[s % len(names)], str(checkpoint), s) for k, s in enumerate(seeds)]


def _selection_row(rnd: int, digest: str, results: list[tuple[int, str, float]]) -> dict[str, Any]:
    events = [event for _, event, _ in results]
    n = len(events)
    return {
        "round": rnd,
        "episodes": n,
        "success_rate": events.count("success") / n,
        "collision_rate": events.count("collision") / n,
        "timeout_rate": events.count("timeout") / n,
        "mean_time_s": float(np.mean([t for _, _, t in results])),
        "student_sha256": digest,
    }


def _stored_selection(out: Path, cfg: DaggerConfig) -> dict[int, dict[str, Any]]:
    """The rows of ``DIR/selection.csv`` a resumed run can keep: those of the same number of
    episodes (their student is matched by its digest when used)."""
    p = out / SELECTION_FILE
    if not p.exists():
        return {}
    with open(p, newline="") as fh:
        rows = list(csv.DictReader(fh))
    kept: dict[int, dict[str, Any]] = {}
    for r in rows:
        if int(r["episodes"]) != cfg.select_episodes:
            continue
        row: dict[str, Any] = {k: float(v) for k, v in r.items() if k.endswith(("_rate", "_s"))}
        row = {"round": int(r["round"]), "episodes": int(r["episodes"]), **row}
        kept[row["round"]] = {**row, "student_sha256": r["student_sha256"]}
    return kept


def _select(
    cfg: DaggerConfig, folder: RunFolder, names: list[str], n_workers: int, progress: bool
) -> tuple[int, list[dict[str, Any]]]:
    """The round whose student becomes the run's: the last one, or with ``select_episodes``
    the one that succeeds most often on the same validation episodes (ties: the later round,
    trained on more data). Rows are written round by round and kept by a resumed run while
    their student is the same file (its SHA-256)."""
    if cfg.select_episodes == 0:
        return cfg.rounds, []
    out = folder.root
    stored = _stored_selection(out, cfg)
    digests = [file_sha256(folder.model_path(r)) for r in range(cfg.rounds + 1)]
    todo = [r for r, d in enumerate(digests) if stored.get(r, {}).get("student_sha256") != d]
    rows = {r: stored[r] for r in range(cfg.rounds + 1) if r not in todo}
    bar = progress_bar(
        total=len(todo) * cfg.select_episodes,
        desc="each round's student on validation",
        unit="ep",
        enabled=progress and bool(todo),
    )
    if todo:
        with bar, Collector(_drive_task, _worker_init, n_workers).open() as drive:
            for rnd in todo:
                results: list[tuple[int, str, float]] = []
                for res in drive(_drive_tasks(cfg, names, folder.model_path(rnd))):
                    results.append(typing.cast(tuple[int, str, float], res))
                    bar.update(1)
                rows[rnd] = _selection_row(rnd, digests[rnd], sorted(results))
                _write_csv(out / SELECTION_FILE, [rows[r] for r in sorted(rows)])
    ordered = [rows[r] for r in range(cfg.rounds + 1)]
    chosen = max(range(len(ordered)), key=lambda r: (ordered[r]["success_rate"], r))
    _write_csv(
        out / SELECTION_FILE, [{**row, "chosen": int(row["round"] == chosen)} for row in ordered]
    )
    return chosen, ordered
