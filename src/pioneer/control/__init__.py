"""Controllers behind one :class:`~pioneer.control.policy.Policy` protocol."""

from pioneer.control.classic import GoalPolicy
from pioneer.control.policy import Policy, make_policy, policy_names

__all__ = ["GoalPolicy", "Policy", "make_policy", "policy_names"]
