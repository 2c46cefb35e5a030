"""Typed frozen configs: defaults, validation, unknown keys, dict round trips."""

from __future__ import annotations

import dataclasses
import importlib
import json
import math
from typing import Annotated, Literal

import pytest
from annotated_types import Ge, Gt, Interval, Le, Lt, MinLen, MultipleOf

from pioneer.bounds import Finite, NonNegative, Positive, Span
from pioneer.config import (
    Config,
    Ordered,
    check_nonnegative,
    check_positive,
    check_range,
    check_within,
    default,
)
from pioneer.errors import (
    CommandError,
    ConfigError,
    DataError,
    PioneerError,
    ScenarioError,
    expect,
)
from pioneer.reward.crowdnav import CrowdNavRewardConfig as RewardConfig
from pioneer.reward.density import DensityConfig
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


# --------------------------------------------------------------- bounds declared on the fields
@dataclasses.dataclass(frozen=True)
class Bounded(Config):
    rate: Positive = 1.0
    offset: NonNegative = 0.0
    share: Annotated[float, Interval(ge=0, le=1)] = 0.5
    below: Annotated[float, Lt(10)] = 1.0
    open_share: Annotated[float, Gt(0), Le(1)] = 1.0
    count: Annotated[int, Ge(1)] = 3
    scale: Positive | None = None


@pytest.mark.parametrize(
    ("kwargs", "helper"),
    [({"rate": 0.0}, check_positive), ({"offset": -1.0}, check_nonnegative)],
)
def test_declared_bounds_say_what_the_check_helpers_say(kwargs, helper):
    ((name, value),) = kwargs.items()
    with pytest.raises(ConfigError) as declared:
        Bounded(**kwargs)
    with pytest.raises(ConfigError) as by_hand:
        helper("Bounded", name, value)
    assert str(declared.value) == str(by_hand.value)


@pytest.mark.parametrize(
    ("kwargs", "kind", "bounds"),
    [
        ({"rate": -2.0}, "a finite number", "> 0"),
        ({"rate": math.nan}, "a finite number", "> 0"),
        ({"rate": math.inf}, "a finite number", "> 0"),
        ({"rate": "1"}, "a finite number", "> 0"),
        ({"offset": -1e-12}, "a finite number", ">= 0"),
        ({"share": 1.5}, "a finite number", ">= 0 and <= 1"),
        ({"share": -0.1}, "a finite number", ">= 0 and <= 1"),
        ({"below": 10.0}, "a finite number", "< 10"),
        ({"open_share": 0.0}, "a finite number", "> 0 and <= 1"),
        ({"count": 0}, "an integer", ">= 1"),
        ({"count": 2.5}, "an integer", ">= 1"),
        ({"count": True}, "an integer", ">= 1"),
        ({"scale": 0.0}, "a finite number", "> 0"),
    ],
)
def test_declared_bounds_are_enforced_with_the_house_message(kwargs, kind, bounds):
    ((name, value),) = kwargs.items()
    with pytest.raises(ConfigError) as exc:
        Bounded(**kwargs)
    msg = str(exc.value)
    assert msg == expect(f"Bounded.{name}", f"{kind} {bounds}", value, f"set {name} {bounds}")
    assert_house_message(msg, f"Bounded.{name}")


def test_declared_bounds_accept_their_edges_and_none():
    edges = Bounded(rate=1, offset=0.0, share=0.0, below=9.99, open_share=1.0, count=1)
    assert edges.rate == 1 and edges.scale is None
    assert Bounded(share=1.0, scale=2.0).scale == 2.0


def test_declared_bounds_hold_for_replace_from_dict_and_subclasses():
    with pytest.raises(ConfigError, match=r"Bounded\.rate"):
        Bounded().replace(rate=0.0)
    with pytest.raises(ConfigError, match=r"Bounded\.count"):
        Bounded.from_dict({"count": 0})

    @dataclasses.dataclass(frozen=True)
    class Wider(Bounded):
        extra: NonNegative = 1.0

    with pytest.raises(ConfigError, match=r"Wider\.rate"):
        Wider(rate=0.0)
    with pytest.raises(ConfigError, match=r"Wider\.extra"):
        Wider(extra=-1.0)


def test_declared_bounds_are_checked_before_the_subclass_post_init():
    seen = []

    @dataclasses.dataclass(frozen=True)
    class Span(Config):
        lo: NonNegative = 0.0
        hi: NonNegative = 1.0

        def __post_init__(self) -> None:  # a cross-field check, written as code
            seen.append((self.lo, self.hi))
            if self.lo > self.hi:
                raise ConfigError(expect("Span.lo", "<= hi", self.lo, "lower lo"))

    with pytest.raises(ConfigError) as exc:
        Span(lo=-1.0, hi=-2.0)
    assert "Span.lo: expected a finite number >= 0" in str(exc.value)
    assert seen == []  # the cross-field check never saw an out-of-range value
    with pytest.raises(ConfigError, match="<= hi"):
        Span(lo=2.0)
    assert seen == [(2.0, 1.0)]


def test_unsupported_constraints_are_refused_not_ignored():
    @dataclasses.dataclass(frozen=True)
    class Named(Config):
        name: Annotated[str, MinLen(1)] = "x"

    @dataclasses.dataclass(frozen=True)
    class Even(Config):
        n: Annotated[int, MultipleOf(2)] = 2

    with pytest.raises(TypeError, match=r"Named\.name"):
        Named()
    with pytest.raises(TypeError, match="unsupported constraint"):
        Even()


@pytest.mark.parametrize(
    ("cls", "name", "value", "helper"),
    [
        (RobotConfig, "radius", 0.0, check_positive),
        (RobotConfig, "v_min", -0.1, check_nonnegative),
        (RobotConfig, "v_max", -1.0, check_positive),
        (RobotConfig, "omega_max", math.nan, check_positive),
        (SocialForceConfig, "tau", 0.0, check_positive),
        (SocialForceConfig, "a_robot", -0.5, check_nonnegative),
        (SocialForceConfig, "settle_distance", math.inf, check_positive),
        (DensityConfig, "lam", -1.0, check_positive),
        (DensityConfig, "length_scale", 0.0, check_positive),
        (DensityConfig, "jitter", 0.0, check_positive),
    ],
)
def test_converted_configs_keep_their_messages(cls, name, value, helper):
    with pytest.raises(ConfigError) as declared:
        cls(**{name: value})
    with pytest.raises(ConfigError) as by_hand:
        helper(cls.__name__, name, value)
    assert str(declared.value) == str(by_hand.value)


def test_converted_configs_keep_their_cross_field_and_choice_checks():
    assert SocialForceConfig(a_robot=0.0).a_robot == 0.0  # the robot may be invisible
    assert DensityConfig(length_scale=None).length_scale is None
    with pytest.raises(ConfigError, match="v_max="):
        RobotConfig(v_min=0.5, v_max=0.2)
    with pytest.raises(ConfigError, match="inducing"):
        DensityConfig(inducing="random")
    with pytest.raises(ConfigError, match="an integer >= 1"):
        DensityConfig(max_inducing=0)


@dataclasses.dataclass(frozen=True)
class _Choice(Config):
    mode: Literal["fast", "safe"] = "fast"
    level: Literal[1, 2] | None = None


def test_a_literal_field_takes_only_its_values_on_every_construction():
    assert _Choice(mode="safe", level=2).mode == "safe"
    assert _Choice(level=None).level is None  # optional: None passes
    for bad in ({"mode": "slow"}, {"mode": 1}, {"level": 3}, {"level": True}):
        with pytest.raises(ConfigError) as err:
            _Choice(**bad)
        assert_house_message(str(err.value))
        assert "one of" in str(err.value)
    with pytest.raises(ConfigError, match="mode"):
        _Choice().replace(mode="slow")
    with pytest.raises(ConfigError, match="mode"):
        _Choice.from_dict({"mode": "slow"})


@pytest.mark.parametrize(
    ("cfg", "field"),
    [(LidarConfig, "sector_layout"), (DensityConfig, "inducing")],
)
def test_the_libraries_choices_are_checked_by_the_base(cfg, field):
    with pytest.raises(ConfigError, match=field):
        cfg(**{field: "no-such-choice"})


# ------------------------------------------------------------------------------ tuple fields
@dataclasses.dataclass(frozen=True)
class _Tupled(Config):
    span: Span = (0.0, 1.0)
    maybe: Span | None = None
    rates: Annotated[tuple[Positive, ...], MinLen(1)] = (1.0,)
    signs: tuple[Annotated[float, Lt(0)], Positive] = (-1.0, 1.0)
    picks: tuple[Literal["a", "b"], ...] = ("a",)
    levels: Annotated[tuple[Annotated[float, Interval(gt=0, le=1)], ...], Ordered()] = (0.1, 0.5)


@pytest.mark.parametrize(
    ("kwargs", "field", "expected"),
    [
        ({"span": (1.0, 0.0)}, "_Tupled.span", "finite bounds with low <= high"),
        ({"span": (0.0, math.inf)}, "_Tupled.span", "finite bounds with low <= high"),
        ({"span": (0.0,)}, "_Tupled.span", "a list of 2 values"),
        ({"span": 1.0}, "_Tupled.span", "a list of 2 values"),
        ({"maybe": (2.0, 1.0)}, "_Tupled.maybe", "finite bounds with low <= high"),
        ({"rates": ()}, "_Tupled.rates", "a list of at least 1 value"),
        ({"rates": (1.0, 0.0)}, "_Tupled.rates[1]", "a finite number > 0"),
        ({"signs": (0.5, 1.0)}, "_Tupled.signs[0]", "a finite number < 0"),
        ({"signs": (-0.5, -1.0)}, "_Tupled.signs[1]", "a finite number > 0"),
        ({"picks": ("a", "c")}, "_Tupled.picks[1]", "one of 'a', 'b'"),
        ({"levels": (0.5, 0.1)}, "_Tupled.levels", "finite numbers in non-decreasing order"),
        ({"levels": (0.0, 0.1)}, "_Tupled.levels[0]", "a finite number > 0 and <= 1"),
    ],
)
def test_tuple_fields_are_checked_item_by_item(kwargs, field, expected):
    with pytest.raises(ConfigError) as exc:
        _Tupled(**kwargs)
    msg = str(exc.value)
    assert msg.startswith(f"{field}: expected {expected}, received ")
    assert_house_message(msg, field)


def test_tuple_fields_accept_lists_equal_bounds_and_none():
    cfg = _Tupled(span=(0.5, 0.5), maybe=None, rates=[2.0, 3.0], levels=(0.2, 0.2, 1.0))
    assert cfg.span == (0.5, 0.5) and cfg.rates == [2.0, 3.0]
    assert _Tupled.from_dict({"span": [0.0, 2.0]}).span == (0.0, 2.0)
    with pytest.raises(ConfigError, match=r"_Tupled\.span"):
        _Tupled.from_dict({"span": [2.0, 0.0]})


def test_a_declared_range_says_what_check_range_says():
    with pytest.raises(ConfigError) as declared:
        _Tupled(span=(1.0, 0.0))
    with pytest.raises(ConfigError) as by_hand:
        check_range("_Tupled", "span", 1.0, 0.0)
    assert str(declared.value) == str(by_hand.value)


def test_unsupported_tuple_constraints_are_refused():
    @dataclasses.dataclass(frozen=True)
    class Fixed(Config):
        pair: Annotated[tuple[float, float], MinLen(1)] = (0.0, 1.0)

    with pytest.raises(TypeError, match=r"Fixed\.pair"):
        Fixed()


def test_finite_and_within_bounds():
    @dataclasses.dataclass(frozen=True)
    class Free(Config):
        x: Finite = 0.0

    assert Free(x=-1e300).x == -1e300
    with pytest.raises(ConfigError) as exc:
        Free(x=math.nan)
    assert str(exc.value) == expect(
        "Free.x", "a finite number", math.nan, "set x to a finite number"
    )
    check_within("X", "share", 1.0, 0.0, 1.0)
    with pytest.raises(ConfigError) as exc:
        check_within("X", "share", 1.5, 0.0, 1.0)
    assert "X.share: expected a finite number >= 0 and <= 1" in str(exc.value)


def test_a_config_may_raise_a_subclass_of_config_error():
    @dataclasses.dataclass(frozen=True)
    class Place(Config):
        error_type = ScenarioError
        width: Positive = 1.0

    with pytest.raises(ScenarioError, match=r"Place\.width"):
        Place(width=0.0)
    with pytest.raises(ScenarioError):
        ElevatorLayout(human_side="up")  # type: ignore[arg-type]


# ---------------------------------------------------------- the library's converted configs
def _config(path: str) -> type[Config]:
    module, name = path.rsplit(".", 1)
    cls = getattr(importlib.import_module(module), name)
    assert issubclass(cls, Config)
    return cls


@pytest.mark.parametrize(
    ("path", "kwargs", "field"),
    [
        ("pioneer.sim.world.SimConfig", {"time_limit": -1.0}, "time_limit"),
        ("pioneer.sim.ElevatorLayout", {"human_side": "up"}, "human_side"),
        ("pioneer.sim.ElevatorLayout", {"n_exiting": -1}, "n_exiting"),
        ("pioneer.sim.ElevatorLayout", {"boarding_delay": (1.5, 0.5)}, "boarding_delay"),
        ("pioneer.sim.ElevatorLayout", {"boarder_release_waypoint": 3}, "boarder_release_waypoint"),
        ("pioneer.sim.scenarios.layouts.StaticStudyLayout", {"width": 0.0}, "width"),
        ("pioneer.sim.Region", {"x": (1.0, 0.0), "y": (0.0, 0.0)}, "x"),
        (
            "pioneer.sim.scenarios.distribution.LayoutDistribution",
            {"sides": ("right", "down")},
            "sides[1]",
        ),
        (
            "pioneer.sim.scenarios.distribution.LayoutDistribution",
            {"n_boarding": (3, 1)},
            "n_boarding",
        ),
        (
            "pioneer.sim.scenarios.distribution.LayoutDistribution",
            {"reacts_share": 2.0},
            "reacts_share",
        ),
        ("pioneer.baselines.crowdnav.trainer.PPOConfig", {"gamma": 1.5}, "gamma"),
        ("pioneer.baselines.crowdnav.trainer.PPOConfig", {"n_envs": 0}, "n_envs"),
        ("pioneer.baselines.crowdnav.imitation.WarmStartConfig", {"expert": "me"}, "expert"),
        ("pioneer.baselines.crowdnav.imitation.WarmStartConfig", {"bc_batch": 0}, "bc_batch"),
        ("pioneer.baselines.crowdnav.network.CrowdNavConfig", {"dv_range": (0.1, 0.2)}, "dv_range"),
        ("pioneer.baselines.cvar_bf.config.CvarBfConfig", {"betas": (0.3, 0.1)}, "betas"),
        ("pioneer.baselines.cvar_bf.config.CvarBfConfig", {"max_iter": 0}, "max_iter"),
        ("pioneer.learn.models.StudentConfig", {"hidden": (128, 0)}, "hidden[1]"),
        ("pioneer.learn.models.StudentConfig", {"dropout": 1.0}, "dropout"),
        ("pioneer.deploy.config.RuntimeConfig", {"unseen": "guess"}, "unseen"),
        ("pioneer.deploy.config.RuntimeConfig", {"min_valid_share": 1.5}, "min_valid_share"),
    ],
)
def test_the_converted_configs_refuse_an_out_of_range_value_naming_the_field(path, kwargs, field):
    cls = _config(path)
    with pytest.raises(ConfigError) as exc:
        cls(**kwargs)
    msg = str(exc.value)
    assert_house_message(msg, f"{cls.__name__}.{field.split('[')[0]}", field)
    assert msg.count("expected") == 1


def test_a_nested_config_field_takes_only_its_config():
    with pytest.raises(ConfigError) as exc:
        SimConfig(robot="fast")  # type: ignore[arg-type]
    assert str(exc.value) == expect(
        "SimConfig.robot", "a RobotConfig", "fast", "pass a RobotConfig"
    )


def test_default_reads_fields_parameters_and_class_signatures():
    from pioneer.baselines.classic import DWAPolicy
    from pioneer.deploy.mixture import mixture_action

    assert default(SimConfig, "dt") == SimConfig().dt
    assert default(mixture_action, "mode") == "mode"
    assert default(DWAPolicy, "n_v") == 7
    with pytest.raises(TypeError, match="no default"):
        default(SimConfig, "nope")


@pytest.mark.parametrize(
    ("call", "hint"),
    [
        ("mixture", "fix: use 'mode'"),
        ("lidar_nearest", "fix: use b = 2"),
        ("lidar_beams", "fix: use e.g. 72 beams in groups of 3"),
        ("dwa", "fix: use 7, 15"),
    ],
)
def test_error_hints_name_the_declared_defaults(call, hint):
    """A hint that suggests the default reads it where it is declared (the values here are the
    declared defaults, checked against them)."""
    import numpy as np

    from pioneer.baselines.classic import DWAPolicy
    from pioneer.deploy.mixture import mixture_action

    calls = {
        "mixture": lambda: mixture_action(np.zeros((1, 2)), np.zeros((1, 2, 2)), "median"),
        "lidar_nearest": lambda: LidarConfig(n_nearest=0),
        "lidar_beams": lambda: LidarConfig(n_beams=70),
        "dwa": lambda: DWAPolicy(n_v=1),
    }
    with pytest.raises(ConfigError) as exc:
        calls[call]()
    assert str(exc.value).endswith(hint)
    lidar = LidarConfig()
    assert (lidar.n_beams, lidar.group_size, lidar.n_nearest) == (72, 3, 2)
