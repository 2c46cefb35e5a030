"""The scenario registry: built-in scenarios by name, variants from scenario files
(``--scenarios FILE``, ``PIONEER_SCENARIOS``), pinning a run's scenario definitions."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pioneer.config import Config
from pioneer.errors import ConfigError, PioneerError, ScenarioError, expect
from pioneer.io import check_name, read_text_bounded
from pioneer.laser import LidarConfig
from pioneer.sim.humans import SocialForceConfig
from pioneer.sim.scenarios.layouts import (
    ElevatorLayout,
    HumanSide,
    StaticStudyLayout,
    elevator_scenario,
    static_study_scenario,
)
from pioneer.sim.scenarios.sampling import sample_state_counted
from pioneer.sim.scenarios.spec import ScenarioConfig
from pioneer.sim.world import SimConfig

# --------------------------------------------------------------------------------------------
# Registry and sampling


def _compact(side: HumanSide, name: str) -> ScenarioConfig:
    """The earlier default world (reproducible: the same states and observations, bit for
    bit — hence the earlier heading-first sector layout)."""
    sim = SimConfig(
        social_force=SocialForceConfig.preset("compact"),
        lidar=LidarConfig(sector_layout="heading_first"),
    )
    return elevator_scenario(ElevatorLayout.compact(side), sim=sim, name=name)


_REGISTRY: dict[str, Callable[[], ScenarioConfig]] = {
    "hr-rl": lambda: elevator_scenario(ElevatorLayout(human_side="right")),
    "hl-rr": lambda: elevator_scenario(ElevatorLayout(human_side="left")),
    "hr-rl-r03": lambda: elevator_scenario(
        ElevatorLayout(human_side="right", human_radius=0.3), name="hr-rl-r03"
    ),
    "hl-rr-r03": lambda: elevator_scenario(
        ElevatorLayout(human_side="left", human_radius=0.3), name="hl-rr-r03"
    ),
    "hr-rl-compact": lambda: _compact("right", "hr-rl-compact"),
    "hl-rr-compact": lambda: _compact("left", "hl-rr-compact"),
    "static": static_study_scenario,
}
_BUILTIN = frozenset(_REGISTRY)
# Variant → the built-in scenario whose learned parts it uses. The 0.3 m-body presets are the
# paper world with thinner people: they use its demonstrations, reward and students.
_BASES: dict[str, str] = {"hr-rl-r03": "hr-rl", "hl-rr-r03": "hl-rr"}
_SOURCES: dict[str, Path] = {}  # variant → the scenario file it was loaded from


def _key(name: str) -> str:
    """Registry key of a scenario name (case and surrounding blanks do not matter)."""
    return name.strip().lower()


def scenario_names() -> list[str]:
    """Names accepted by :func:`get_scenario`."""
    load_env_scenarios()
    return sorted(_REGISTRY)


def _check_new_name(where: str, name: str) -> None:
    """A variant's name: new, and safe as a file name (a PNG, a reward file is named after
    it): letters, digits, ``-``, ``_``, ``.``, no leading dot (:func:`pioneer.io.check_name`)."""
    try:
        check_name(where, name)
    except ConfigError as exc:
        raise ScenarioError(str(exc)) from None
    if _key(name) in _BUILTIN:
        raise ScenarioError(
            expect(where, f"a new non-empty name (not {sorted(_BUILTIN)})", name, "rename it")
        )


def _check_base(where: str, base: object) -> None:
    if base is not None and (not isinstance(base, str) or _key(base) not in _BUILTIN):
        raise ScenarioError(
            expect(f"{where}: base", f"one of {sorted(_BUILTIN)}", base, "fix the name")
        )


def register_scenario(
    name: str, factory: Callable[[], ScenarioConfig], base: str | None = None
) -> None:
    """Make a scenario variant available by ``name`` to :func:`get_scenario`, the Gymnasium
    env, the evaluation harness and DAgger (in-process; register it at import time of the
    script's top level, so spawned workers register it too).

    ``factory`` builds the config, e.g. ``lambda: elevator_scenario(ElevatorLayout(
    lobby_depth=2.8), name="hr-rl-deep")``; it is called once here to check it, and its start
    states for seeds 0–49 are drawn (a layout too tight to place every body is refused here,
    not halfway through an evaluation). Built-in names
    cannot be replaced. Learned parts keyed by scenario (the teacher's default reward, shipped
    students) exist only for the built-in ones: pass a reward file for a new name, or name a
    built-in ``base`` whose shipped demos and students the variant uses.
    """
    _check_new_name("scenario name", name)
    _check_base(f"scenario {name!r}", base)
    cfg = factory()
    if not isinstance(cfg, ScenarioConfig):
        raise ScenarioError(
            expect(
                f"scenario {name!r} factory", "a ScenarioConfig", type(cfg).__name__, "return one"
            )
        )
    check_placement(f"scenario {name!r}", cfg)
    _register(name, factory, base)
    _SOURCES.pop(_key(name), None)


def check_placement(where: str, cfg: ScenarioConfig, budget: float = math.inf) -> int:
    """Draw the start states of seeds 0–49: a layout too tight for some of them would stop an
    evaluation in the middle (≈ 1 ms per seed when it fits). Returns the draws they took in
    all (50 when every first draw placed every body), or stops early with the count so far
    once it exceeds ``budget``."""
    draws = 0
    for seed in range(PLACEMENT_CHECK_SEEDS):
        if draws > budget:
            break
        try:
            draws += sample_state_counted(cfg, np.random.default_rng(seed))[1]
        except ScenarioError as exc:
            raise ScenarioError(
                f"{where}: start state for seed {seed} (of {PLACEMENT_CHECK_SEEDS} checked): {exc}"
            ) from exc
    return draws


def _register(name: str, factory: Callable[[], ScenarioConfig], base: str | None) -> None:
    key = _key(name)
    _REGISTRY[key] = factory
    if base is not None:
        _BASES[key] = _key(base)
    elif key not in _BUILTIN:  # the built-in presets keep theirs
        _BASES.pop(key, None)


def scenario_source(name: str) -> Path | None:
    """The scenario file the variant ``name`` was loaded from (None: built in, or registered
    in code) — a run records its content hash."""
    key = _key(name)
    if key not in _REGISTRY:
        load_env_scenarios()
    return _SOURCES.get(key)


def scenario_base(name: str) -> str:
    """The built-in scenario whose learned parts (shipped demos → teacher reward, shipped
    students) serve ``name``: the ``base`` it was registered with, else ``name`` itself."""
    key = _key(name)
    if key not in _REGISTRY:
        load_env_scenarios()
    return _BASES.get(key, name)


SCENARIO_FILE_FORMAT = "pioneer.scenarios/1"
DEFAULT_SCENARIO = "hr-rl"  # what a command or an environment runs when not told (paper §V-A)
SCENARIOS_ENV = "PIONEER_SCENARIOS"  # scenario files (os.pathsep-separated) loaded on demand
_KINDS: dict[str, tuple[type[Config], Callable[..., ScenarioConfig]]] = {
    "elevator": (ElevatorLayout, elevator_scenario),
    "static": (StaticStudyLayout, static_study_scenario),
}
_ENV_LOADED: str | None = None  # the value of SCENARIOS_ENV whose files are registered
PLACEMENT_CHECK_SEEDS = 50  # start states drawn per variant when it is first used
MAX_SCENARIO_FILE_BYTES = 64 * 2**20  # a scenario file's size limit (≈ 300,000 variants)


def _scenario_factory(
    name: str, kind: str, layout: dict[str, Any], sim: dict[str, Any] | None
) -> Callable[[], ScenarioConfig]:
    layout_cls, build = _KINDS[kind]
    lay = layout_cls.from_dict(layout)
    sim_cfg = SimConfig.from_dict(sim) if sim is not None else None

    def factory() -> ScenarioConfig:
        return build(lay, sim=sim_cfg).replace(name=name)

    return factory


class _FileVariant:
    """The factory of a scenario file's variant, checked when it is first used — its layout,
    settings and the placement of its start states (:func:`check_placement`) — and kept: a
    file of many variants costs its parse, not a check of each (errors name the file and the
    variant)."""

    def __init__(self, where: str, name: str, kind: str, entry: dict[str, Any]) -> None:
        self.where, self.name, self.kind, self.entry = where, name, kind, entry
        self.config: ScenarioConfig | None = None

    def __call__(self) -> ScenarioConfig:
        if self.config is None:
            try:
                factory = _scenario_factory(
                    self.name, self.kind, self.entry[self.kind], self.entry.get("sim")
                )
                cfg = factory()
            except PioneerError as exc:
                raise ScenarioError(f"{self.where}: {exc}") from exc
            check_placement(self.where, cfg)
            self.config = cfg
        return self.config


def load_scenario_file(path: str | Path) -> list[str]:
    """Register the scenario variants of a JSON file; returns their names.

    The file (``format`` ``pioneer.scenarios/1``) maps names to a layout of a built-in family
    and, optionally, simulator settings::

        {"format": "pioneer.scenarios/1",
         "scenarios": {
           "hr-rl-deep": {"elevator": {"lobby_depth": 2.8}, "base": "hr-rl"},
           "static-wide": {"static": {"width": 5.0}, "sim": {"time_limit": 40.0}}}}

    ``elevator`` takes :class:`ElevatorLayout` fields, ``static`` :class:`StaticStudyLayout`
    fields, ``sim`` :class:`~pioneer.sim.world.SimConfig` fields; omitted fields keep their
    defaults. An optional ``"base": "hr-rl"`` lets the variant use that built-in scenario's
    shipped demos (the teacher's default reward) and shipped students. Episode seeds derive
    from the scenario *name*, so a variant evaluated twice under one name gets the same
    episodes. The file is read only if it is a regular UTF-8 file of at most
    :data:`MAX_SCENARIO_FILE_BYTES`, and every variant's name, family and base are checked
    here; a variant's layout and settings are checked when it is first used
    (:func:`get_scenario`), and it must place its bodies for the start-state seeds 0–49 (a
    layout that is too tight for some draws is refused then, before a run starts, rather than
    halfway through it).
    Put the file's path in the ``PIONEER_SCENARIOS`` environment variable (or pass
    ``pioneer --scenarios FILE``) so that worker processes register the variants too.
    """
    p = Path(path)
    fix = f"write a JSON object with 'format': {SCENARIO_FILE_FORMAT!r} and 'scenarios'"
    try:
        data = json.loads(read_text_bounded(p, "scenario file", MAX_SCENARIO_FILE_BYTES))
    except PioneerError as exc:
        raise ScenarioError(str(exc)) from None
    except json.JSONDecodeError as exc:
        raise ScenarioError(
            expect(f"scenario file {p}", "valid JSON", f"{exc.msg} at line {exc.lineno}", fix)
        ) from exc
    if not isinstance(data, dict) or data.get("format") != SCENARIO_FILE_FORMAT:
        got = data.get("format") if isinstance(data, dict) else type(data).__name__
        raise ScenarioError(expect(f"scenario file {p}: format", SCENARIO_FILE_FORMAT, got, fix))
    entries = data.get("scenarios")
    if not isinstance(entries, dict) or not entries:
        raise ScenarioError(
            expect(f"scenario file {p}: scenarios", "a non-empty object", entries, fix)
        )
    factories: dict[str, Callable[[], ScenarioConfig]] = {}
    bases: dict[str, str | None] = {}
    refused: list[str] = []  # every variant's error, reported together
    for name, entry in entries.items():
        try:
            factories[name], bases[name] = _load_variant(p, name, entry)
        except PioneerError as exc:
            refused.append(str(exc).removeprefix(f"scenario file {p}: "))
    if len(refused) == 1:
        raise ScenarioError(f"scenario file {p}: {refused[0]}")
    if refused:
        listing = " | ".join(refused)
        raise ScenarioError(f"scenario file {p}: {len(refused)} variants refused: {listing}")
    source = p.resolve()
    for name, factory in factories.items():  # all or nothing: register only a valid file
        _register(name, factory, bases[name])
        _SOURCES[_key(name)] = source
    return list(factories)


def _load_variant(
    p: Path, name: str, entry: Any
) -> tuple[Callable[[], ScenarioConfig], str | None]:
    """One variant of a scenario file, its name, family and base checked: its factory (which
    checks the rest when first called, :class:`_FileVariant`) and base. Errors name the file
    and the variant."""
    where = f"scenario file {p}: {name!r}"
    _check_new_name(where, name)
    kinds = sorted(set(entry) & set(_KINDS)) if isinstance(entry, dict) else []
    extra = sorted(set(entry) - set(_KINDS) - {"sim", "base"}) if isinstance(entry, dict) else []
    if len(kinds) != 1 or extra:
        raise ScenarioError(
            expect(
                where,
                f"exactly one of {sorted(_KINDS)} (plus optional 'sim' and 'base')",
                sorted(entry) if isinstance(entry, dict) else entry,
                'e.g. {"elevator": {"lobby_depth": 2.8}}',
            )
        )
    _check_base(where, entry.get("base"))
    return _FileVariant(where, name, kinds[0], entry), entry.get("base")


def load_env_scenarios() -> None:
    """Register the files named in ``PIONEER_SCENARIOS`` (once per value of the variable)."""
    global _ENV_LOADED
    value = os.environ.get(SCENARIOS_ENV, "")
    if value == _ENV_LOADED:
        return
    for item in value.split(os.pathsep):
        if item.strip():
            load_scenario_file(item.strip())
    _ENV_LOADED = value


def pin_scenario(name: str, recorded: dict[str, Any] | None, where: str) -> dict[str, Any]:
    """The full definition of ``name`` as plain JSON data; if ``recorded`` (the definition an
    output folder was made with) differs, raise :class:`ConfigError` naming the changed fields
    — a variant from a scenario file can change under an unchanged name."""
    mine: dict[str, Any] = json.loads(json.dumps(get_scenario(name).to_dict()))
    if recorded is not None and recorded != mine:
        diff = sorted(k for k in {*recorded, *mine} if recorded.get(k) != mine.get(k))
        raise ConfigError(
            expect(
                f"{where}: scenario {name!r}",
                f"the definition recorded there ({diff} differ)",
                "a changed definition",
                "restore the scenario file, or use a new --out directory",
            )
        )
    return mine


def get_scenario(name: str) -> ScenarioConfig:
    """A registered scenario by name (``hr-rl``, ``hl-rr``, ``static``, …, and the variants of
    the files in ``PIONEER_SCENARIOS``)."""
    key = _key(name)
    if key not in _REGISTRY:
        load_env_scenarios()
    if key not in _REGISTRY:
        raise ScenarioError(
            expect("scenario", f"one of {scenario_names()}", name, "pick a listed scenario name")
        )
    return _REGISTRY[key]()
