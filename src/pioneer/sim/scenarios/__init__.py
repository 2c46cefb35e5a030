"""Scenarios as data: elevator co-boarding (HR-RL, HL-RR) and the static study (paper §V-A, §V-B).

Coordinate frame: origin at the centre of the elevator door on the wall line, +y into the
cabin. A :class:`ScenarioConfig` holds walls, map bounds, sampling regions and the human
specifications; :func:`elevator_scenario` builds one from an :class:`ElevatorLayout`, so door
width, cabin size, radii and the number of boarding/exiting humans are configuration.
:func:`sample_state` draws an initial state from a seeded generator, rejecting overlaps.
"""

from pioneer.sim.scenarios.layouts import (
    ElevatorLayout,
    StaticStudyLayout,
    elevator_scenario,
    static_study_scenario,
)
from pioneer.sim.scenarios.registry import (
    DEFAULT_SCENARIO,
    SCENARIO_FILE_FORMAT,
    SCENARIOS_ENV,
    get_scenario,
    load_env_scenarios,
    load_scenario_file,
    pin_scenario,
    register_scenario,
    scenario_base,
    scenario_names,
    scenario_source,
)
from pioneer.sim.scenarios.sampling import sample_state
from pioneer.sim.scenarios.spec import HumanSpec, Region, ScenarioConfig

__all__ = [
    "DEFAULT_SCENARIO",
    "SCENARIOS_ENV",
    "SCENARIO_FILE_FORMAT",
    "ElevatorLayout",
    "HumanSpec",
    "Region",
    "ScenarioConfig",
    "StaticStudyLayout",
    "elevator_scenario",
    "get_scenario",
    "load_env_scenarios",
    "load_scenario_file",
    "pin_scenario",
    "register_scenario",
    "sample_state",
    "scenario_base",
    "scenario_names",
    "scenario_source",
    "static_study_scenario",
]
