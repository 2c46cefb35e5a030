"""Students distilled from the teacher: MDN and MLP, uncertainty, checkpoints, ONNX export;
and the CrowdNav++ RL baseline (:mod:`pioneer.learn.crowdnav`, trained by :mod:`pioneer.learn.ppo`).

This package imports torch (install the ``learn`` extra). Importing it registers the
``student-mdn``, ``student-mlp``, ``student-onnx``, ``student-shield`` and ``crowdnav++``
policies. The torch-free robot runtime is :mod:`pioneer.deploy`.
"""

from pioneer.learn.crowdnav import (
    CrowdNavConfig,
    CrowdNavNet,
    CrowdNavPolicy,
    load_crowdnav,
    make_crowdnav_policy,
    save_crowdnav,
)
from pioneer.learn.export import export_onnx
from pioneer.learn.models import (
    MDN,
    MLPStudent,
    Student,
    StudentConfig,
    build_student,
    load_student,
    read_checkpoint_meta,
    save_student,
    select_action,
    train_student,
    uncertainty,
)
from pioneer.learn.policy import StudentPolicy, make_student_policy
from pioneer.learn.shield import ShieldPolicy, make_shield_policy

__all__ = [
    "MDN",
    "CrowdNavConfig",
    "CrowdNavNet",
    "CrowdNavPolicy",
    "MLPStudent",
    "ShieldPolicy",
    "Student",
    "StudentConfig",
    "StudentPolicy",
    "build_student",
    "export_onnx",
    "load_crowdnav",
    "load_student",
    "make_crowdnav_policy",
    "make_shield_policy",
    "make_student_policy",
    "read_checkpoint_meta",
    "save_crowdnav",
    "save_student",
    "select_action",
    "train_student",
    "uncertainty",
]
