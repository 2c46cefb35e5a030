"""Controllers behind one :class:`~pioneer.control.policy.Policy` protocol."""

from pioneer.control.classic import DWAPolicy, GoalPolicy, SocialForceRobotPolicy
from pioneer.control.cvar_bf import CvarBfConfig, CvarBfPolicy, CvarDecision
from pioneer.control.policy import Policy, make_policy, policy_names
from pioneer.control.rollout import Rollout, candidate_commands, rollout
from pioneer.control.teacher import Decision, LookaheadTeacher, TeacherConfig

__all__ = [
    "CvarBfConfig",
    "CvarBfPolicy",
    "CvarDecision",
    "DWAPolicy",
    "Decision",
    "GoalPolicy",
    "LookaheadTeacher",
    "Policy",
    "Rollout",
    "SocialForceRobotPolicy",
    "TeacherConfig",
    "candidate_commands",
    "make_policy",
    "policy_names",
    "rollout",
]
