"""Students as policies: a trained student's checkpoint and the registry entries (paper §IV-B).

Registered names (importing :mod:`pioneer.learn` registers them):

- ``student-mdn`` / ``student-mlp``: :class:`StudentPolicy` from a safetensors checkpoint
  (``make_student_policy(checkpoint=...)``); the checkpoint's kind must match the name.
- ``student-onnx``: :class:`pioneer.deploy.OnnxStudentPolicy` from an exported ONNX file
  (``model=...``), the torch-free runtime evaluated like any other policy.

A checkpoint path may contain ``{scenario}`` (one spec for every scenario, like the
teacher's reward path).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import torch
from annotated_types import Ge
from numpy.typing import NDArray

from pioneer.deploy.inputs import InputMemory
from pioneer.deploy.mixture import mixture_action, mixture_uncertainty
from pioneer.errors import ConfigError, DataError, expect
from pioneer.learn.inference import StudentInference
from pioneer.learn.models import MDN, Student, load_student, select_action, uncertainty
from pioneer.nn.forward_choice import FORWARD, Forward, check_forward

__all__ = ["StudentPolicy", "make_student_policy"]


class StudentPolicy:
    """A trained student acting from the 29-D observation (batch 1; the network's step in
    NumPy by default, or the PyTorch module in eval mode: ``forward``).

    ``act`` returns the deterministic action (MDN: mean of the most probable component, or
    the mixture mean with ``action_mode="mean"``). ``uncertainty`` holds ``(aleatoric,
    epistemic)`` [(m/s)² + (rad/s)²] for every step of the current episode, NaN for the MLP;
    ``reset`` clears it. A student that also reads o_{t−1} or u_{t−1}
    (:class:`~pioneer.deploy.runtime.StudentInputs`) remembers them as the ONNX runtime does:
    the observation it decided on and the command it sent, clipped to the robot's limits.
    ``forward``: who computes the network's step (:mod:`pioneer.nn.forward_choice`).
    """

    def __init__(
        self,
        model: Student,
        name: str | None = None,
        action_mode: str | None = None,
        forward: Forward = FORWARD,
    ) -> None:
        check_forward("student", forward)
        self.model = model.eval()
        self.forward = forward
        self._numpy = StudentInference(self.model) if forward == "numpy" else None
        self.name = name or f"student-{model.kind}"
        self.action_mode = action_mode or model.config.action_mode
        self.checkpoint: Path | None = None  # the file it was loaded from (make_student_policy)
        self.uncertainty: list[tuple[float, float]] = []
        self.memory = InputMemory(model.config.inputs)
        self._obs: NDArray[np.float32] | None = None  # the observation of the last act

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Start an episode (the student is deterministic; ``rng`` is unused)."""
        self.uncertainty = []
        self.memory.reset()

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """The command ``(v [m/s], ω [rad/s])``, shape ``(2,)``."""
        self._obs = np.asarray(obs, dtype=np.float32)
        if self._numpy is not None:
            return self._act_numpy(self._numpy, self.memory.inputs(self._obs))
        x = torch.as_tensor(self.memory.inputs(self._obs))
        with torch.inference_mode():
            if isinstance(self.model, MDN):
                logits, mu, sigma = self.model(x)
                action = select_action(logits, mu, self.action_mode)
                ale, epi = uncertainty(logits, mu, sigma)
                self.uncertainty.append((float(ale[0]), float(epi[0])))
            else:
                action = self.model.deterministic_action(x)
                self.uncertainty.append((math.nan, math.nan))
        command = action[0].numpy().astype(np.float64)
        self.sent(command)
        return command

    def _act_numpy(self, net: StudentInference, x: NDArray[np.float32]) -> NDArray[np.float64]:
        if net.kind == "mdn":
            logits, mu, sigma = net.mixture(x)
            command = mixture_action(logits, mu, self.action_mode)[0]
            ale, epi = mixture_uncertainty(logits, mu, sigma)
            self.uncertainty.append((float(ale[0]), float(epi[0])))
        else:
            command = net.regress(x)[0].astype(np.float64)
            self.uncertainty.append((math.nan, math.nan))
        self.sent(command)
        return command

    def sent(self, command: NDArray[np.floating]) -> None:
        """Note the command the robot ran this step (u_{t−1} of the next): ``act`` notes its
        own; a wrapper that sends another (a shield) notes that."""
        self.memory.note(self._obs, command)


def make_student_policy(
    checkpoint: str | Path | None = None,
    scenario: str | None = None,
    kind: str | None = None,
    name: str | None = None,
    action_mode: str | None = None,
    torch_threads: Annotated[int, Ge(1)] | None = 1,
    general: bool = False,
    seed: Annotated[int, Ge(0)] = 0,
    recipe: str = "",
    forward: Forward = FORWARD,
) -> StudentPolicy:
    """Policy factory: load ``checkpoint`` (``{scenario}`` filled in) as a :class:`StudentPolicy`.

    Without ``checkpoint``: the shipped DAgger student of ``scenario`` and ``kind`` (default
    "mdn"; :func:`pioneer.data.shipped_student`), or with ``general`` the one student for many
    worlds; ``seed`` picks one of its DAgger seeds (:data:`pioneer.data.STUDENT_SEEDS`) and
    ``recipe="paper"`` the paper's recipe (``student-mdn-paper``). ``kind`` ("mdn" | "mlp"),
    when given, must match the checkpoint. ``torch_threads`` sets torch's intra-op threads for
    this process (1 by default: a batch-1 forward pass gains nothing from threads, and
    evaluation runs one worker per core); ``None`` leaves it. ``forward``: the network's step
    in NumPy (the default) or in torch, the reference (:mod:`pioneer.learn.inference`).
    """
    if checkpoint is None:
        from pioneer.data import DEFAULT_STUDENT_KIND, shipped_student

        if scenario is None and not general:
            raise ConfigError(
                expect("student policy", "checkpoint=PATH or a scenario", None, "pass one")
            )
        checkpoint = shipped_student(
            scenario or "", kind or DEFAULT_STUDENT_KIND, general, seed, recipe
        )
    path = str(checkpoint).format(scenario=scenario) if scenario is not None else str(checkpoint)
    if torch_threads is not None:
        torch.set_num_threads(int(torch_threads))
    model = load_student(path)
    if kind is not None and model.kind != kind:
        raise ConfigError(
            expect(
                f"student checkpoint {path}",
                f"a '{kind}' student",
                model.kind,
                f"use the policy 'student-{model.kind}'",
            )
        )
    _check_width(path, model.config.obs_dim, scenario)
    policy = StudentPolicy(model, name=name, action_mode=action_mode, forward=forward)
    policy.checkpoint = Path(path)
    return policy


def _check_width(path: str, width: int, scenario: str | None) -> None:
    """A student reads the observation of its scenario's LiDAR (29-D with the paper's): one of
    another width is refused when it loads, not at its first decision."""
    from pioneer.sim.lidar import OBS_DIM

    wanted = OBS_DIM
    if scenario is not None:
        from pioneer.sim.scenarios import get_scenario

        wanted = get_scenario(scenario).sim.lidar.obs_dim
    if width != wanted:
        where = f"scenario {scenario}'s" if scenario is not None else "the"
        raise DataError(
            expect(
                f"student checkpoint {path}: obs_dim",
                f"{wanted} ({where} observation)",
                width,
                "use a student trained on this observation (pioneer distill)",
            )
        )
