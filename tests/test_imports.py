"""Import hygiene: the simulator and env pull in neither torch nor matplotlib."""

from __future__ import annotations

import subprocess
import sys

SCRIPT = """
import sys
import pioneer
import gymnasium as gym
env = gym.make("pioneer/ElevatorHRRL-v1")
env.reset(seed=0)
env.action_space.seed(0)
for _ in range(50):
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    if terminated or truncated:
        env.reset(seed=1)
assert obs.shape == (29,), obs.shape
bad = sorted(m for m in ("torch", "matplotlib") if m in sys.modules)
print("heavy:", ",".join(bad))
"""


def test_env_does_not_import_torch_or_matplotlib():
    proc = subprocess.run(
        [sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=300, check=False
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == "heavy:"


def test_package_import_is_light():
    code = (
        "import sys, pioneer, pioneer.sim, pioneer.control, pioneer.eval\n"
        "print(sorted(m for m in ('torch', 'matplotlib', 'PIL') if m in sys.modules))"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=False
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"
