"""``pioneer replay`` (a bag through the robot runtime) and ``pioneer export`` (ONNX).

Robot-side: this module imports neither torch nor the simulator (``export`` loads torch only
when it runs).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Annotated, TypeAlias

import tyro

from pioneer.cli._files import InFile, InPath, OutFile
from pioneer.cli._options import Flag, metavar, one_of, optional
from pioneer.config import default
from pioneer.deploy.bag import GOAL_FRAMES, replay_bag
from pioneer.deploy.mixture import ACTION_MODES
from pioneer.io import to_json

if TYPE_CHECKING:
    GoalFrame: TypeAlias = str
    ActionMode: TypeAlias = str
else:
    GoalFrame = one_of(GOAL_FRAMES)
    ActionMode = one_of(ACTION_MODES)

__all__ = ["Export", "Replay"]


@dataclasses.dataclass(frozen=True)
class Replay:
    """ROS bag LaserScans → the student's commands as CSV (no ROS needed); prints a summary."""

    bag: Annotated[InPath, metavar("BAG")]
    """ROS 1 .bag file or ROS 2 bag folder"""
    model: InFile
    """student .onnx (from pioneer export)"""
    out: OutFile
    """output CSV"""
    goal: Annotated[tuple[float, float], tyro.conf.arg(metavar="X Y")]
    """[m] the goal, in --goal-frame"""
    goal_frame: GoalFrame = default(replay_bag, "goal_frame")
    """robot: fixed in the robot frame (x forward, y left); odom: fixed in the odometry frame"""
    scan_topic: Annotated[str | None, optional("TOPIC", "the bag's only one")] = None
    """LaserScan topic"""
    odom_topic: Annotated[str | None, optional("TOPIC", "the bag's only one")] = None
    """Odometry topic for --goal-frame odom"""
    overwrite: Flag = False
    """replace an existing --out (otherwise refused: a file you made is never replaced)"""

    def run(self) -> int:
        """Replay and write the CSV."""
        summary = replay_bag(
            self.bag,
            self.model,
            self.out,
            goal=self.goal,
            goal_frame=self.goal_frame,  # type: ignore[arg-type]  # a GOAL_FRAMES name
            scan_topic=self.scan_topic,
            odom_topic=self.odom_topic,
        )
        print(to_json(summary))
        return 0


@dataclasses.dataclass(frozen=True)
class Export:
    """Student checkpoint → ONNX, written only if it passes a parity check; prints a summary."""

    model: InPath
    """student .safetensors or a distill folder"""
    out: OutFile
    """output .onnx"""
    action_mode: Annotated[ActionMode | None, optional("{mode,mean}", "the model's")] = None
    """the MDN's executed action"""
    overwrite: Flag = False
    """replace an existing --out (otherwise refused: a file you made is never replaced)"""

    def run(self) -> int:
        """Export with the parity check."""
        from pioneer.learn.export import export_checkpoint

        print(to_json(export_checkpoint(self.model, self.out, action_mode=self.action_mode)))
        return 0
