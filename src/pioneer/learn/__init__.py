"""Students distilled from the teacher (paper §IV-B): MDN and MLP, uncertainty, DAgger, the
uncertainty shield and ONNX export.

This package imports torch (install the ``learn`` extra). The policies ``student-mdn``,
``student-mlp`` and ``student-shield`` are built by name through
:mod:`pioneer.control.registry`; the torch-free robot runtime is :mod:`pioneer.deploy`.
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
    uncertainty,
)
from pioneer.learn.policy import StudentPolicy, make_student_policy
from pioneer.learn.shield import ShieldPolicy, make_shield_policy
from pioneer.learn.training import train_student

__all__ = [
    "MDN",
    "MLPStudent",
    "ShieldPolicy",
    "Student",
    "StudentConfig",
    "StudentPolicy",
    "build_student",
    "export_onnx",
    "load_student",
    "make_shield_policy",
    "make_student_policy",
    "read_checkpoint_meta",
    "save_student",
    "select_action",
    "train_student",
    "uncertainty",
]
