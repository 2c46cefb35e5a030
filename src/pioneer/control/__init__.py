"""Controllers behind one :class:`~pioneer.control.policy.Policy` protocol."""

from pioneer.control.classic import GoalPolicy
from pioneer.control.policy import Policy, make_policy, policy_names
from pioneer.control.rollout import Rollout, candidate_commands, rollout
from pioneer.control.teacher import Decision, LookaheadTeacher, TeacherConfig

__all__ = [
    "Decision",
    "GoalPolicy",
    "LookaheadTeacher",
    "Policy",
    "Rollout",
    "TeacherConfig",
    "candidate_commands",
    "make_policy",
    "policy_names",
    "rollout",
]
