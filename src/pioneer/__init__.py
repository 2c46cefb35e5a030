"""PioneeR: social navigation from positive and negative demonstrations and rules.

Importing the package registers the Gymnasium environments ``pioneer/ElevatorHRRL-v0``,
``pioneer/ElevatorHLRR-v0`` and ``pioneer/StaticStudy-v0`` (by entry-point string). It imports
neither the simulator (numba) nor matplotlib nor torch; subpackages load what they need.
"""

from pioneer.registration import register_envs

__version__ = "0.1.0"

register_envs()

__all__ = ["__version__", "register_envs"]
