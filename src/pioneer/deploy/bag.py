"""Replay a recorded ROS bag through an exported student: LaserScan messages → commands CSV.

Reads ROS 1 bags (a ``.bag`` file) and ROS 2 bags (a directory with ``metadata.yaml``, sqlite3
or mcap storage) with ``rosbags``' :class:`~rosbags.highlevel.AnyReader` — pure Python, no ROS
installation (``pip install 'pioneer-nav[ros]'``). Like the rest of :mod:`pioneer.deploy` it
never imports torch.

Every ``sensor_msgs/msg/LaserScan`` message of the scan topic is one decision of
:meth:`StudentRuntime.step <pioneer.deploy.runtime.StudentRuntime.step>`, so the CSV has one
row per scan at the scanner's rate. On the robot a node calls the runtime at the control rate
the student was trained with, 10 Hz (one decision per 0.1 s, on the latest scan); a 10 Hz
scanner gives the same decisions as the replay, a faster one more rows than the robot would
act on.

The goal (x, y) [m] is either fixed in the robot frame (``goal_frame="robot"``: x forward, y
left), or fixed in the odometry frame (``goal_frame="odom"``) and moved into the robot frame at
each scan with the latest ``nav_msgs/msg/Odometry`` pose recorded up to that scan's bag time
(scans before the first odometry message are skipped and counted). The odometry pose is taken
as the pose of the scan's frame: a laser mounted off the robot centre needs a transform first,
as in :mod:`pioneer.deploy.runtime`.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal

from pioneer.config import default
from pioneer.deploy.runtime import RuntimeDecision, StudentRuntime
from pioneer.errors import ConfigError, DataError, PioneerError, expect
from pioneer.io import atomic_path
from pioneer.laser import LidarConfig
from pioneer.progress import progress_bar

__all__ = [
    "CSV_COLUMNS",
    "INSTALL_HINT",
    "LASER_SCAN",
    "ODOMETRY",
    "goal_in_robot_frame",
    "replay_bag",
]

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
CSV_COLUMNS = (
    "stamp_s",
    "bag_time_s",
    "v",
    "omega",
    "aleatoric",
    "epistemic",
    "stop_reason",
    "valid_share",
    "coverage_rad",
    "age_s",
)
INSTALL_HINT = "pip install 'pioneer-nav[ros]' (or, for the light runtime, './runtime[ros]')"
GOAL_FRAMES = ("robot", "odom")
_BAG_FIX = "check that it is a complete ROS 1 .bag or ROS 2 bag directory"


def goal_in_robot_frame(
    goal_xy: Sequence[float], x: float, y: float, yaw: float
) -> tuple[float, float]:
    """The goal ``(x, y)`` [m] given in a fixed frame, seen from a robot at ``(x, y, yaw)``
    [m, m, rad] in that frame: ``R(−yaw) · (goal − position)``."""
    dx, dy = goal_xy[0] - x, goal_xy[1] - y
    c, s = math.cos(yaw), math.sin(yaw)
    return c * dx + s * dy, -s * dx + c * dy


def _yaw(q: Any) -> float:
    # Heading of a quaternion (rotation about z after projecting out roll and pitch).
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _seconds(sec: int, nanosec: int) -> str:
    # Exact decimal seconds, no float rounding: "1700000000.000000005".
    return f"{int(sec)}.{int(nanosec):09d}"


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


def _pick_topic(
    topics: dict[str, str], msgtype: str, wanted: str | None, option: str, bag: Path
) -> str:
    """The one topic of ``msgtype``: ``wanted`` if given (checked), else the only one."""
    listing = dict(sorted(topics.items()))
    if wanted is not None:
        if topics.get(wanted) != msgtype:
            raise DataError(
                expect(
                    f"{bag}: topic {wanted}",
                    f"a {msgtype} topic",
                    topics.get(wanted, "absent"),
                    f"pick one of the bag's topics {listing}",
                )
            )
        return wanted
    found = sorted(t for t, m in topics.items() if m == msgtype)
    if len(found) != 1:
        raise DataError(
            expect(
                f"{bag}: {msgtype} topics",
                "exactly one (or name one with " + option + ")",
                found,
                f"the bag's topics are {listing}"
                if not found
                else f"pass {option} with one of {found}",
            )
        )
    return found[0]


def _check_goal(goal: Sequence[float], goal_frame: str) -> tuple[float, float]:
    if goal_frame not in GOAL_FRAMES:
        fix = f"use {default(replay_bag, 'goal_frame')!r}"
        raise ConfigError(expect("goal_frame", f"one of {GOAL_FRAMES}", goal_frame, fix))
    g = tuple(float(c) for c in goal)
    if len(g) != 2 or not all(math.isfinite(c) for c in g):
        raise ConfigError(expect("goal", "finite (x, y) [m]", list(goal), "pass --goal X Y"))
    return g[0], g[1]


def _runtime(model_onnx: str | Path | StudentRuntime, lidar: LidarConfig | None) -> StudentRuntime:
    if not isinstance(model_onnx, StudentRuntime):
        return StudentRuntime(model_onnx, lidar=lidar)
    if lidar is not None:
        raise ConfigError(
            expect("lidar", "None with a ready StudentRuntime", lidar, "set it on the runtime")
        )
    return model_onnx


def _check_bag(bag: Path) -> None:
    if not bag.exists():
        raise DataError(
            expect(
                "ROS bag",
                "a .bag file (ROS 1) or a bag directory (ROS 2)",
                str(bag),
                "check the path",
            )
        )


def _tqdm() -> Any:
    """tqdm's progress bar class (the light runtime installs it with its [ros] extra)."""
    try:
        from tqdm import tqdm
    except ImportError as exc:
        raise ConfigError(
            expect("bag replay", "tqdm installed", f"ImportError ({exc})", INSTALL_HINT)
        ) from exc
    return tqdm


def _open_reader(bag: Path) -> Any:
    """An open rosbags ``AnyReader`` on ``bag``; DataError/ConfigError on failure."""
    try:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.typesys import Stores, get_typestore
    except ImportError as exc:
        raise ConfigError(
            expect("bag replay", "rosbags installed", f"ImportError ({exc})", INSTALL_HINT)
        ) from exc
    try:
        reader = AnyReader([bag], default_typestore=get_typestore(Stores.LATEST))
        reader.open()
    except (AnyReaderError, OSError, ValueError, KeyError) as exc:
        raise DataError(
            expect(f"ROS bag {bag}", "a readable bag", _one_line(exc), _BAG_FIX)
        ) from exc
    return reader


def _stamp_ns(msg: Any) -> int:
    stamp = msg.header.stamp
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _command_row(msg: Any, t_ns: int, d: RuntimeDecision) -> tuple[str, ...]:
    stamp = msg.header.stamp
    return (
        _seconds(stamp.sec, stamp.nanosec),
        _seconds(t_ns // 1_000_000_000, t_ns % 1_000_000_000),
        repr(d.v),
        repr(d.omega),
        repr(d.aleatoric),
        repr(d.epistemic),
        d.stop_reason or "",
        repr(d.valid_share),
        repr(d.coverage_rad),
        repr(d.age_s),
    )


def _replay_messages(
    reader: Any,
    runtime: StudentRuntime,
    out: Any,
    topics: tuple[str, str | None],
    goal: tuple[float, float],
    bag: Path,
    bar: Any,
    stops: dict[str, int],
) -> tuple[int, int, int]:
    """Write one CSV row per scan of ``topics[0]`` and count the stops by reason in
    ``stops``; returns (scans, rows, skipped)."""
    scan, odom = topics
    conns = [c for c in reader.connections if c.topic in (scan, odom)]
    rows, skipped, k = 0, 0, 0
    pose: tuple[float, float, float] | None = None
    for con, t_ns, raw in reader.messages(connections=conns):
        msg: Any = reader.deserialize(raw, con.msgtype)
        if con.topic == odom:
            p = msg.pose.pose
            pose = (float(p.position.x), float(p.position.y), _yaw(p.orientation))
            continue
        k += 1
        bar.update(1)
        if odom is not None and pose is None:
            skipped += 1
            continue
        goal_robot = goal_in_robot_frame(goal, *pose) if pose is not None else goal
        try:
            d = runtime.step(
                msg.ranges,
                float(msg.angle_min),
                float(msg.angle_increment),
                float(msg.range_max),
                goal_robot,
                range_min=float(msg.range_min),
                age_s=(t_ns - _stamp_ns(msg)) * 1e-9,
            )
        except PioneerError as exc:  # name the message; the cause says what and fix
            raise DataError(f"{bag}: {scan} message {k} (bag time {t_ns} ns): {exc}") from exc
        if d.stop_reason is not None:
            stops[d.stop_reason] = stops.get(d.stop_reason, 0) + 1
        out.writerow(_command_row(msg, t_ns, d))
        rows += 1
    return k, rows, skipped


def replay_bag(
    bag_path: str | Path,
    model_onnx: str | Path | StudentRuntime,
    out_csv: str | Path,
    *,
    goal: Sequence[float],
    goal_frame: Literal["robot", "odom"] = "robot",
    scan_topic: str | None = None,
    odom_topic: str | None = None,
    lidar: LidarConfig | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Feed every LaserScan of ``bag_path`` to the student and write the commands to ``out_csv``.

    ``model_onnx`` is an exported student (or a ready :class:`StudentRuntime`); ``goal`` is
    ``(x, y)`` [m] in ``goal_frame`` (see the module docstring); ``scan_topic`` and
    ``odom_topic`` default to the bag's only topic of that type. The CSV (written atomically)
    has the columns :data:`CSV_COLUMNS`: the scan's header stamp and its bag (receive) time,
    both in seconds, then the decision ``v`` [m/s], ``omega`` [rad/s] (clipped; 0, 0 on a
    stop), ``aleatoric`` and ``epistemic`` [(m/s)² + (rad/s)²] (NaN for a regression student
    or a stop), and the scan's health: ``stop_reason`` (empty when the student drove, else one
    of :data:`~pioneer.deploy.runtime.STOP_REASONS`), ``valid_share``, ``coverage_rad`` [rad]
    and ``age_s`` [s], the bag time minus the header stamp (the replay decides when a scan is
    received). Returns a summary: ``out``, ``bag``, ``scan_topic``, ``odom_topic``,
    ``scans``, ``rows``, ``skipped`` and ``stops`` (stop decisions by reason).

    Raises :class:`DataError` for a missing or unreadable bag, no (or several) LaserScan
    topics, or a malformed scan; :class:`ConfigError` for a bad goal or goal frame.
    """
    g = _check_goal(goal, goal_frame)
    bag = Path(bag_path)
    _check_bag(bag)
    runtime = _runtime(model_onnx, lidar)
    runtime.reset()  # a bag is one drive to its goal: no previous scan or command before it
    _tqdm()  # the [ros] extra's tqdm, or one line naming it
    reader = _open_reader(bag)
    from rosbags.highlevel import AnyReaderError

    try:
        topics = {c.topic: c.msgtype for c in reader.connections}
        scan = _pick_topic(topics, LASER_SCAN, scan_topic, "--scan-topic", bag)
        odom = (
            _pick_topic(topics, ODOMETRY, odom_topic, "--odom-topic", bag)
            if goal_frame == "odom"
            else None
        )
        n_scans = sum(c.msgcount for c in reader.connections if c.topic == scan)
        stops: dict[str, int] = {}
        with (
            atomic_path(Path(out_csv)) as tmp,
            tmp.open("w", newline="") as fh,
            progress_bar(total=n_scans, desc="scans", unit="scan", enabled=progress) as bar,
        ):
            out = csv.writer(fh)
            out.writerow(CSV_COLUMNS)
            k, rows, skipped = _replay_messages(
                reader, runtime, out, (scan, odom), g, bag, bar, stops
            )
    except AnyReaderError as exc:
        raise DataError(
            expect(f"ROS bag {bag}", "readable messages", _one_line(exc), _BAG_FIX)
        ) from exc
    finally:
        reader.close()
    return {
        "out": str(out_csv),
        "bag": str(bag),
        "model": str(runtime.path),
        "scan_topic": scan,
        "odom_topic": odom,
        "goal_frame": goal_frame,
        "scans": k,
        "rows": rows,
        "skipped": skipped,
        "stops": stops,
    }
