"""Deployment without torch: ONNX Runtime student, scan adapter, mixture read-outs, bag replay.

It never imports torch (a test blocks the import and runs a step), nor the controllers.
"""

from pioneer.deploy.bag import replay_bag
from pioneer.deploy.mixture import mixture_action, mixture_uncertainty
from pioneer.deploy.runtime import (
    Decision,
    OnnxStudentPolicy,
    StudentRuntime,
    make_onnx_student_policy,
)

__all__ = [
    "Decision",
    "OnnxStudentPolicy",
    "StudentRuntime",
    "make_onnx_student_policy",
    "mixture_action",
    "mixture_uncertainty",
    "replay_bag",
]
