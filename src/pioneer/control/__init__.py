"""PioneeR's own controller and the contract every controller meets.

The one ``Policy`` protocol lives with the environments (:mod:`pioneer.envs.policy`) and is
re-exported here; :mod:`.registry` is the one lazy, string-based registry of every
controller (teacher, baselines, students, plugins); :mod:`.rollout` and :mod:`.teacher` are
the lookahead teacher of the paper (§IV-A.2); :mod:`.precision` checks that the teacher with
float32 rays chooses what it chooses with the float64 reference.
"""

from pioneer.control.registry import build_policy, make_policy, policy_names, register_policy
from pioneer.control.rollout import Rollout, rollout
from pioneer.control.teacher import LookaheadTeacher, TeacherConfig, TeacherDecision
from pioneer.envs.policy import Policy

__all__ = [
    "LookaheadTeacher",
    "Policy",
    "Rollout",
    "TeacherConfig",
    "TeacherDecision",
    "build_policy",
    "make_policy",
    "policy_names",
    "register_policy",
    "rollout",
]
