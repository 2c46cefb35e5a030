"""PioneeR's own controller and the contract every controller meets.

:mod:`.policy` is the one ``Policy`` protocol; :mod:`.registry` the one lazy, string-based
registry of every controller (teacher, baselines, students, plugins); :mod:`.rollout` and
:mod:`.teacher` the lookahead teacher of the paper (§IV-A.2).
"""

from pioneer.control.registry import build_policy, make_policy, policy_names, register_policy
from pioneer.control.rollout import Rollout, candidate_commands, rollout
from pioneer.control.teacher import Decision, LookaheadTeacher, TeacherConfig
from pioneer.envs.policy import Policy

__all__ = [
    "Decision",
    "LookaheadTeacher",
    "Policy",
    "Rollout",
    "TeacherConfig",
    "build_policy",
    "candidate_commands",
    "make_policy",
    "policy_names",
    "register_policy",
    "rollout",
]
