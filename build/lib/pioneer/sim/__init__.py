"""The pure 2-D simulation core: geometry, robot, humans, LiDAR, scenarios and world step."""

from pioneer.sim.humans import ARRIVED, GONE, WALKING, SocialForceConfig
from pioneer.sim.lidar import (
    OBS_DIM,
    LidarConfig,
    cast_rays,
    observation_from_ranges,
    observation_from_scan,
    observation_names,
    resample_scan,
)
from pioneer.sim.robot import RobotConfig
from pioneer.sim.scenarios import (
    ElevatorLayout,
    HumanSpec,
    Region,
    ScenarioConfig,
    StaticStudyLayout,
    elevator_scenario,
    get_scenario,
    load_scenario_file,
    register_scenario,
    sample_state,
    scenario_names,
    static_study_scenario,
)
from pioneer.sim.world import SimConfig, State, World, goal_bearing, observe, scan, step

__all__ = [
    "ARRIVED",
    "GONE",
    "OBS_DIM",
    "WALKING",
    "ElevatorLayout",
    "HumanSpec",
    "LidarConfig",
    "Region",
    "RobotConfig",
    "ScenarioConfig",
    "SimConfig",
    "SocialForceConfig",
    "State",
    "StaticStudyLayout",
    "World",
    "cast_rays",
    "elevator_scenario",
    "get_scenario",
    "goal_bearing",
    "load_scenario_file",
    "observation_from_ranges",
    "observation_from_scan",
    "observation_names",
    "observe",
    "register_scenario",
    "resample_scan",
    "sample_state",
    "scan",
    "scenario_names",
    "static_study_scenario",
    "step",
]
