"""PioneeR: social navigation from positive and negative demonstrations and rules.

Importing the package registers the Gymnasium environments ``pioneer/ElevatorHRRL-v0``,
``pioneer/ElevatorHLRR-v0`` and ``pioneer/StaticStudy-v0`` (by entry-point string). It imports
neither the simulator (numba) nor matplotlib nor torch; subpackages load what they need.
The light robot install (``runtime/``, numpy and onnxruntime only) has no Gymnasium and no
environments to register, so there the import registers nothing.
"""

import importlib.util

__version__ = "0.1.0"

if importlib.util.find_spec("gymnasium") is not None:  # absent only in the light runtime
    from pioneer.registration import register_envs

    register_envs()

__all__ = ["__version__"]
