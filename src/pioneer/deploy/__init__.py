"""Deployment without torch: ONNX Runtime student, scan adapter and health, mixture read-outs,
bag replay.

It never imports torch (a test blocks the import and runs a step), nor the controllers, nor
the simulator: the light robot install (``runtime/``) has numpy and onnxruntime only.
"""

from pioneer.deploy.bag import replay_bag
from pioneer.deploy.config import RuntimeConfig
from pioneer.deploy.mixture import mixture_action, mixture_uncertainty
from pioneer.deploy.runtime import (
    STOP_REASONS,
    OnnxStudentPolicy,
    RuntimeDecision,
    StudentRuntime,
    make_onnx_student_policy,
)

__all__ = [
    "STOP_REASONS",
    "OnnxStudentPolicy",
    "RuntimeConfig",
    "RuntimeDecision",
    "StudentRuntime",
    "make_onnx_student_policy",
    "mixture_action",
    "mixture_uncertainty",
    "replay_bag",
]
