"""PioneeR: social navigation from positive and negative demonstrations and rules.

Importing the package registers the Gymnasium environments ``pioneer/ElevatorHRRL-v1``,
``pioneer/ElevatorHLRR-v1`` and ``pioneer/StaticStudy-v1`` (by entry-point string). It imports
neither the simulator (numba) nor matplotlib nor torch; subpackages load what they need.
The light robot install (``runtime/``, numpy and onnxruntime only) has no Gymnasium and no
environments to register, so there the import registers nothing.
"""

__version__ = "0.1.0"

try:
    from pioneer.registration import register_envs
except ModuleNotFoundError as exc:  # only the light runtime install lacks Gymnasium
    if exc.name != "gymnasium":
        raise
else:
    register_envs()

__all__ = ["__version__"]
