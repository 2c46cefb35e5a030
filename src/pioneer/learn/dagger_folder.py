"""A DAgger run's folder (:mod:`pioneer.learn.dagger` lists its files): the settings a resume
must match, the scenarios' definitions, the teacher's reward per scenario, and every check of
the inputs against them before anything is written."""

from __future__ import annotations

import fnmatch
import json
from pathlib import Path
from typing import Any

from pioneer.config import MAX_EPISODES, check_count
from pioneer.data import base_scenario
from pioneer.errors import ConfigError, expect
from pioneer.imitation.store import RunFolder
from pioneer.io import file_sha256, inside, output_dir_kind, to_json, write_text_atomic
from pioneer.learn.dagger_config import DaggerConfig

__all__ = [
    "FINAL_FILE",
    "REWARD_KEY",
    "SCENARIO_FILE",
    "check_inputs",
    "prepare",
    "round_sizes",
    "run_folder",
    "run_settings",
    "scenario_set",
]

SCENARIO_FILE = "scenario.json"
FINAL_FILE = "student.safetensors"


def run_folder(out: Path) -> RunFolder:
    """The run's episodes, rounds' students and settings (an older run's settings file is
    read in today's layout, options added since at their defaults; a rerun may change the
    number of rounds and of selection episodes)."""
    return RunFolder(
        out, FINAL_FILE, "DAgger", upgrade=_current_layout, free=("rounds", "select_episodes")
    )


def _current_layout(stored: dict[str, Any]) -> dict[str, Any]:
    """Stored settings in today's layout: the DaggerConfig (:meth:`DaggerConfig.from_dict`)
    and the reward's hash (none in a run stored before it was recorded, or of the default
    reward)."""
    config = {k: v for k, v in stored.items() if k != REWARD_KEY}
    return {**DaggerConfig.from_dict(config).to_dict(), REWARD_KEY: stored.get(REWARD_KEY)}


REWARD_KEY = "reward_sha256"  # the settings' key of the --reward file's hash


def run_settings(cfg: DaggerConfig, reward: str | Path | None) -> dict[str, Any]:
    """What a run is made with and a resume must match: the DaggerConfig and the SHA-256 of
    the teacher's ``reward`` file (None: the default, fitted on the shipped demos and kept in
    the run folder) — the remaining episodes are never labelled under another reward."""
    return {**cfg.to_dict(), REWARD_KEY: file_sha256(reward) if reward is not None else None}


def round_sizes(cfg: DaggerConfig) -> list[int]:
    """Episodes of each round."""
    return [cfg.episodes_in(r) for r in range(cfg.rounds + 1)]


def scenario_set(pattern: str) -> list[str]:
    """The scenarios a run draws its episodes from: ``pattern`` itself, or — with ``*``, ``?``
    or ``[`` in it — every registered scenario whose name matches (e.g. ``general-*`` for the
    layouts of ``pioneer sample-layouts``), sorted."""
    from pioneer.sim.scenarios import get_scenario, scenario_names

    if not any(ch in pattern for ch in "*?["):
        get_scenario(pattern)  # fail early on an unknown scenario
        return [pattern]
    names = sorted(n for n in scenario_names() if fnmatch.fnmatchcase(n, pattern))
    if not names:
        raise ConfigError(
            expect(
                "DAgger --scenario pattern",
                "a pattern matching registered scenarios",
                pattern,
                "load the variants with `pioneer --scenarios FILE distill …`",
            )
        )
    return names


def _check_scenario(out: Path, names: list[str]) -> dict[str, Any] | None:
    """The scenarios' full definitions to record, if ``out`` has none yet; a resumed run must
    see the same ones (reads only)."""
    from pioneer.sim.scenarios import pin_scenario

    p = out / SCENARIO_FILE
    recorded = json.loads(p.read_text()) if p.exists() else None
    if len(names) == 1:  # one scenario: its definition (as every run before patterns)
        mine = pin_scenario(names[0], recorded, str(out))
    else:
        old = recorded.get("scenarios", {}) if isinstance(recorded, dict) else {}
        if recorded is not None and sorted(old) != names:
            raise ConfigError(
                expect(
                    f"{out}: scenarios",
                    f"the {len(old)} of the run already there",
                    f"{len(names)} matching now",
                    "load the same scenario file to resume, or use a new --out directory",
                )
            )
        mine = {"scenarios": {n: pin_scenario(n, old.get(n), str(out)) for n in names}}
    return mine if recorded is None else None


def check_inputs(cfg: DaggerConfig, out: Path, reward: str | Path | None) -> list[str]:
    """The run's scenarios, after checking every input against them and ``out`` (reads only,
    so a refused run leaves the file system as it was): the reward file loads and fits each
    scenario, or the default reward each needs can be fitted (on its base's shipped demos);
    a resumed run has the same settings and scenario definitions."""
    from pioneer.reward.density import DensityReward
    from pioneer.reward.recipe import check_reward_fits, default_reward

    check_count(
        "DAgger episodes (--teacher-episodes + --rounds × --episodes-per-round)",
        cfg.total_episodes,
        MAX_EPISODES,
        "ask for fewer rounds or episodes",
    )
    names = scenario_set(cfg.scenario)
    output_dir_kind(out)
    folder = run_folder(out)
    folder.check(run_settings(cfg, reward))
    folder.check_episodes(round_sizes(cfg))  # a corrupt episode is refused before any new one
    _check_scenario(out, names)
    if reward is not None:
        model = DensityReward.load(reward)
        for name in names:
            check_reward_fits(model, name, str(reward))
    else:
        for name, path in _default_reward_paths(out, names).items():
            if not path.exists():
                default_reward(base_scenario(name))  # cached: _prepare saves this very fit
    return names


def _default_reward_paths(out: Path, names: list[str]) -> dict[str, Path]:
    """Where the default reward of each scenario's base is kept: ``DIR/reward.npz`` for one
    scenario, ``DIR/reward-BASE.npz`` for a pattern."""
    return {
        name: inside(out, "reward.npz" if len(names) == 1 else f"reward-{base_scenario(name)}.npz")
        for name in names
    }


def prepare(
    cfg: DaggerConfig, out: Path, reward: str | Path | None, names: list[str]
) -> dict[str, Path]:
    """Record the run's settings and scenarios in ``out`` (holding its lock; checked by
    :func:`check_inputs`) and return the teacher's reward file per scenario: ``reward`` for
    all, else the one fitted on the shipped demos of the scenario's base
    (:func:`_default_reward_paths`)."""
    folder = run_folder(out)
    settings = run_settings(cfg, reward)
    folder.check(settings)  # again, holding the lock
    scenarios = _check_scenario(out, names)
    folder.prepare(settings)  # a killed worker's half-written episode goes
    if scenarios is not None:
        write_text_atomic(out / SCENARIO_FILE, to_json(scenarios, indent=1) + "\n")
    if reward is not None:
        return dict.fromkeys(names, Path(reward))
    from pioneer.reward.recipe import default_reward

    paths = _default_reward_paths(out, names)
    for name, path in paths.items():
        if not path.exists():
            default_reward(base_scenario(name)).save(path)
    return paths
