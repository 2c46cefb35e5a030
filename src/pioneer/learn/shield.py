"""An uncertainty shield around a student (beyond the paper, which only suggests it, §V-B.2).

At every step the student proposes ``(v, ω)`` and reports its aleatoric and epistemic
uncertainty. When the chosen signal exceeds the threshold the shield intervenes:

- ``mode="handover"``: the fallback decides this step — the privileged teacher in simulation
  (labelling from the command actually applied, like DAgger), or a rule-based controller
  (``fallback="goal" | "dwa" | "sfm"``, what a robot without privileged state would use);
- ``mode="slow"``: the student's command with the speed scaled by ``slow_factor``.

``hold``: after an intervention the fallback keeps deciding for this many more steps, even
where the signal has fallen (0: only the unsure steps themselves).

Threshold: a number, or by default the ``quantile`` (0.95) of the signal over the student's
own DAgger training frames, stored in the checkpoint (``uncertainty_quantiles``) — the shield
then intervenes on the ≈ 5 % least familiar situations, and the fallback keeps deciding for
``hold`` = 10 steps (1 s) after each. Default signal: the total predictive variance
(aleatoric + epistemic). All three chosen on validation episodes: the most success for a
handover of at most ≈ 10 % of the steps (docs/student.md, "Uncertainty shield"). Registered
as ``student-shield``.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from annotated_types import Interval
from numpy.typing import NDArray

from pioneer.bounds import NonNegative
from pioneer.config import default
from pioneer.control.registry import build_policy
from pioneer.envs.policy import Planner, Policy
from pioneer.errors import ConfigError, expect
from pioneer.learn.models import read_checkpoint_meta
from pioneer.learn.policy import StudentPolicy, make_student_policy
from pioneer.nn.forward_choice import FORWARD, Forward

__all__ = ["ShieldPolicy", "make_shield_policy"]

SIGNALS = ("epistemic", "aleatoric", "total")
SIGNAL = "total"  # the default signal (module docstring)
QUANTILE = 0.95  # the default threshold's quantile of the signal over the training frames
HOLD = 10  # [steps] the fallback's extra steps after an unsure one (module docstring)
MODES = ("handover", "slow")


class ShieldPolicy:
    """Student + fallback; ``shielded`` records (0/1) whether each step was overridden."""

    def __init__(
        self,
        student: StudentPolicy,
        fallback: Policy | None,
        threshold: float,
        signal: str = SIGNAL,
        mode: str = "handover",
        slow_factor: float = 0.3,
        name: str = "student-shield",
        hold: int = HOLD,
    ) -> None:
        if signal not in SIGNALS:
            fix = f"use {default(ShieldPolicy, 'signal')}"
            raise ConfigError(expect("shield signal", f"one of {SIGNALS}", signal, fix))
        if mode not in MODES:
            fix = f"use {default(ShieldPolicy, 'mode')}"
            raise ConfigError(expect("shield mode", f"one of {MODES}", mode, fix))
        if mode == "handover" and fallback is None:
            raise ConfigError(
                expect("shield fallback", "a policy for handover", None, "pass fallback=teacher")
            )
        if not (threshold >= 0.0 and np.isfinite(threshold)):
            raise ConfigError(expect("shield threshold", "a finite number >= 0", threshold, "0.1"))
        if not 0.0 <= slow_factor <= 1.0:
            fix = f"use {default(ShieldPolicy, 'slow_factor')}"
            raise ConfigError(expect("slow_factor", "in [0, 1]", slow_factor, fix))
        if not (isinstance(hold, int) and hold >= 0):
            fix = f"use {default(ShieldPolicy, 'hold')}"
            raise ConfigError(expect("shield hold", "an integer >= 0 [steps]", hold, fix))
        self.student = student
        self.fallback = fallback
        self.threshold = float(threshold)
        self.signal = signal
        self.mode = mode
        self.slow_factor = float(slow_factor)
        self.name = name
        self.hold = hold
        self.shielded: list[float] = []
        self._held = 0  # steps the fallback still decides after the last unsure one

    @property
    def uncertainty(self) -> list[tuple[float, float]]:
        """The student's ``(aleatoric, epistemic)`` of every step of this episode."""
        return self.student.uncertainty

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Start an episode (student and fallback)."""
        self.student.reset(info, rng)
        if self.fallback is not None:
            self.fallback.reset(info, rng)
        self.shielded = []
        self._held = 0

    def _value(self) -> float:
        ale, epi = self.student.uncertainty[-1]
        return {"epistemic": epi, "aleatoric": ale, "total": ale + epi}[self.signal]

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """The student's command, or the fallback's / a slowed one when it is unsure."""
        u = self.student.act(obs, info)
        unsure = self._value() > self.threshold
        intervene = unsure or self._held > 0
        self._held = self.hold if unsure else max(self._held - 1, 0)
        self.shielded.append(float(intervene))
        if not intervene:
            return u
        sent = self._instead(u, obs, info)
        self.student.sent(sent)  # a student reading u_{t−1} must see what the robot ran
        return sent

    def _instead(
        self, u: NDArray[np.float64], obs: NDArray[np.float32], info: Mapping[str, Any]
    ) -> NDArray[np.float64]:
        if self.mode == "slow":
            return np.array([u[0] * self.slow_factor, u[1]])
        assert self.fallback is not None
        if isinstance(self.fallback, Planner):  # e.g. the teacher: smooth from the applied command
            state = info["state"]
            return self.fallback.decide(info["world"], state, prev=state.command[0]).command
        return np.asarray(self.fallback.act(obs, info), dtype=np.float64)


def default_threshold(checkpoint: str | Path, signal: str, quantile: float) -> float:
    """The ``quantile`` of ``signal`` over the checkpoint's DAgger training frames."""
    info = read_checkpoint_meta(checkpoint)["info"]
    qs = info.get("uncertainty_quantiles", {}) if isinstance(info, dict) else {}
    names = ["aleatoric", "epistemic"] if signal == "total" else [signal]
    try:
        return float(sum(qs[n][str(quantile)] for n in names))
    except KeyError as exc:
        raise ConfigError(
            expect(
                f"{checkpoint}: uncertainty_quantiles[{quantile}]",
                "stored by `pioneer distill` (quantiles 0.5, 0.9, 0.95, 0.99)",
                "missing",
                "pass threshold=VALUE",
            )
        ) from exc


def make_shield_policy(
    checkpoint: str | Path | None = None,
    scenario: str | None = None,
    fallback: str = "teacher",
    threshold: NonNegative | None = None,
    quantile: Annotated[float, Interval(gt=0, lt=1)] = QUANTILE,
    signal: str = SIGNAL,
    mode: str = "handover",
    slow_factor: Annotated[float, Interval(ge=0, le=1)] = 0.3,
    reward: str | None = None,
    name: str = "student-shield",
    hold: Annotated[int, Interval(ge=0)] = HOLD,
    forward: Forward = FORWARD,
) -> ShieldPolicy:
    """Policy factory: an MDN student (default: the shipped one of ``scenario``; ``forward``:
    its network's step, :mod:`pioneer.nn.forward_choice`) shielded by ``fallback`` (a
    registered policy name; the teacher gets ``reward`` if given)."""
    student = make_student_policy(checkpoint, scenario=scenario, kind="mdn", forward=forward)
    assert student.checkpoint is not None
    thr = (
        threshold
        if threshold is not None
        else default_threshold(student.checkpoint, signal, quantile)
    )
    fb = None
    if mode == "handover":
        kwargs: dict[str, Any] = {"reward": reward} if (fallback == "teacher" and reward) else {}
        fb = build_policy(fallback, scenario, **kwargs)
    return ShieldPolicy(student, fb, thr, signal, mode, slow_factor, name=name, hold=hold)
