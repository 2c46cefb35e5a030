"""Students distilled from the teacher: MDN and MLP, uncertainty, checkpoints, ONNX export.

This package imports torch (install the ``learn`` extra). Importing it registers the
``student-mdn``, ``student-mlp`` and ``student-onnx`` policies. The torch-free robot runtime is
:mod:`pioneer.deploy`.
"""

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

__all__ = [
    "MDN",
    "MLPStudent",
    "Student",
    "StudentConfig",
    "StudentPolicy",
    "build_student",
    "export_onnx",
    "load_student",
    "make_student_policy",
    "read_checkpoint_meta",
    "save_student",
    "select_action",
    "train_student",
    "uncertainty",
]
