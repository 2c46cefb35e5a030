"""Typed frozen configs: defaults, validation, unknown keys, dict round trips."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest

from pioneer.config import Config, check_nonnegative, check_positive, check_range
from pioneer.errors import (
    CommandError,
    ConfigError,
    DataError,
    PioneerError,
    ScenarioError,
    expect,
)
from pioneer.reward.crowdnav import CrowdNavRewardConfig as RewardConfig
from pioneer.sim import ElevatorLayout, LidarConfig, RobotConfig, SimConfig, SocialForceConfig
from pioneer_testutils import assert_house_message


def test_error_hierarchy():
    for cls in (ConfigError, ScenarioError, CommandError, DataError):
        assert issubclass(cls, PioneerError)
        assert issubclass(cls, ValueError)
    assert issubclass(ScenarioError, ConfigError)


def test_expect_format():
    msg = expect("a.b", "a number > 0", -1, "set b > 0")
    assert msg == "a.b: expected a number > 0, received -1; fix: set b > 0"
    assert_house_message(msg, "a.b")


def test_from_dict_unknown_key_names_it():
    with pytest.raises(ConfigError) as exc:
        SimConfig.from_dict({"dt": 0.1, "time_limt": 30.0})
    assert_house_message(str(exc.value), "time_limt", "SimConfig")


def test_from_dict_unknown_nested_key_names_it():
    with pytest.raises(ConfigError) as exc:
        SimConfig.from_dict({"robot": {"radius": 0.3, "wheel_base": 0.5}})
    assert_house_message(str(exc.value), "wheel_base", "RobotConfig")


def test_from_dict_not_a_mapping():
    with pytest.raises(ConfigError) as exc:
        SimConfig.from_dict([("dt", 0.1)])  # type: ignore[arg-type]
    assert_house_message(str(exc.value), "SimConfig")


def test_from_dict_nested_and_defaults():
    cfg = SimConfig.from_dict({"dt": 0.05, "robot": {"radius": 0.25}, "lidar": {"n_beams": 36}})
    assert cfg.dt == 0.05
    assert isinstance(cfg.robot, RobotConfig)
    assert cfg.robot.radius == 0.25
    assert cfg.robot.v_max == 0.8  # default kept
    assert cfg.lidar.n_beams == 36
    assert cfg.social_force == SocialForceConfig()


@pytest.mark.parametrize(
    "cfg",
    [
        SimConfig(),
        ElevatorLayout(),
        LidarConfig(noise_std=0.1),
        RewardConfig(),
        SocialForceConfig(),
    ],
)
def test_round_trip_through_json(cfg):
    data = json.loads(json.dumps(cfg.to_dict()))
    assert type(cfg).from_dict(data) == cfg


def test_tuples_become_lists_and_back():
    lay = ElevatorLayout(v_pref_choices=(0.4, 0.5))
    d = lay.to_dict()
    assert d["v_pref_choices"] == [0.4, 0.5]
    again = ElevatorLayout.from_dict(d)
    assert again.v_pref_choices == (0.4, 0.5)
    assert isinstance(again.boarding_delay, tuple)


def test_configs_are_frozen_and_replace_validates():
    cfg = SimConfig()
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.dt = 0.2  # type: ignore[misc]
    faster = cfg.replace(dt=0.05)
    assert faster.dt == 0.05 and cfg.dt == 0.1
    with pytest.raises(ConfigError) as exc:
        cfg.replace(dtt=0.05)
    assert_house_message(str(exc.value), "dtt")
    with pytest.raises(ConfigError) as exc:
        cfg.replace(dt=-1.0)
    assert_house_message(str(exc.value), "dt")


@pytest.mark.parametrize(
    ("cls", "kwargs", "field"),
    [
        (SimConfig, {"dt": 0.0}, "dt"),
        (SimConfig, {"time_limit": math.inf}, "time_limit"),
        (SimConfig, {"goal_tolerance": math.nan}, "goal_tolerance"),
        (RobotConfig, {"v_min": -0.1}, "v_min"),
        (RobotConfig, {"omega_max": 0.0}, "omega_max"),
        (LidarConfig, {"noise_std": -1.0}, "noise_std"),
        (SocialForceConfig, {"b_wall": -0.2}, "b_wall"),
        (ElevatorLayout, {"lobby_depth": 0.0}, "lobby_depth"),
    ],
)
def test_invalid_values_are_rejected(cls, kwargs, field):
    with pytest.raises(ConfigError) as exc:
        cls(**kwargs)
    assert_house_message(str(exc.value), field)


def test_check_helpers():
    check_positive("X", "a", 1)
    check_nonnegative("X", "a", 0.0)
    check_range("X", "a", 0.0, 0.0)
    for bad in (0, -1.0, math.nan, math.inf, "1"):
        with pytest.raises(ConfigError):
            check_positive("X", "a", bad)  # type: ignore[arg-type]
    with pytest.raises(ConfigError):
        check_nonnegative("X", "a", -1e-12)
    with pytest.raises(ConfigError) as exc:
        check_range("X", "a", 1.0, 0.0)
    assert_house_message(str(exc.value), "X.a")


def test_base_config_is_a_frozen_dataclass():
    @dataclasses.dataclass(frozen=True)
    class Small(Config):
        a: int = 1
        b: tuple[int, ...] = (1, 2)

    assert Small.from_dict({"b": [3, 4]}) == Small(a=1, b=(3, 4))
    assert Small().to_dict() == {"a": 1, "b": [1, 2]}
