"""Regression guard for the simulator's numbers: seeded trajectories against stored ones.

The behaviour tests check physics; this one pins *the values*, so a refactor or an
optimisation of the step kernel, the social-force model or the LiDAR that changes any
trajectory fails here instead of silently changing every dataset, teacher label and result
made with it. Continuous values are compared to 1e-9 (a different CPU's libm may differ in
the last bits; over 25 steps that stays far below this), discrete ones exactly: a collision
flag could only flip where a gap lies within that tolerance of 0, and
``test_discrete_outcomes_are_no_near_ties`` checks that none does (the closest is 3·10⁻⁴ m).

Two references: ``regression.npz`` was made before the paper world existed and pins the
compact world (``hr-rl-compact``, ``hl-rr-compact``; stored under the names ``hr-rl`` and
``hl-rr`` it had then), so the earlier world stays reproducible bit for bit;
``regression-paper.npz`` pins the paper world (``hr-rl``, ``hl-rr``) and the static study,
with the mirror-true sector layout (sector 0 centred on the heading). After an *intended*
change of the paper world's dynamics or observation, regenerate that one and say why in the
commit::

    .venv/bin/python tests/sim/test_regression.py --regenerate
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from pioneer.sim import get_scenario, observe, sample_state, step

if (_TESTS := str(Path(__file__).resolve().parents[1])) not in sys.path:
    sys.path.insert(0, _TESTS)  # run as a script (--regenerate); under pytest conftest does it

from pioneer_testutils import keyed_runs, load_reference, regenerate_reference

REFERENCE = Path(__file__).with_name("data") / "regression.npz"
PAPER_REFERENCE = Path(__file__).with_name("data") / "regression-paper.npz"
SCENARIOS = ("hr-rl", "hl-rr")  # the keys of the earlier reference …
COMPACT = {"hr-rl": "hr-rl-compact", "hl-rr": "hl-rr-compact"}  # … their names today
PAPER = ("hr-rl", "hl-rr", "static")
SEEDS = (0, 1, 2)
N_COPIES, N_STEPS = 4, 25
CONTINUOUS = ("robot", "h_pos", "h_vel", "gap", "wall_gap", "path_length", "obs")
DISCRETE = ("collided", "reached", "h_status", "h_wp_index")


def trajectory(name: str, seed: int) -> dict[str, np.ndarray]:
    """Every step's state of 4 copies under seeded random commands (some out of range)."""
    scenario = get_scenario(name)
    world = scenario.world()
    rng = np.random.default_rng(seed)
    state = sample_state(scenario, rng).repeat(N_COPIES)
    lo, hi = scenario.sim.robot.command_low, scenario.sim.robot.command_high
    out: dict[str, list[np.ndarray]] = {k: [] for k in (*CONTINUOUS, *DISCRETE)}
    for k in range(N_STEPS):
        u = rng.uniform(lo - 0.2, hi + 0.2, size=(N_COPIES, 2))
        state = step(world, state, u, dt=0.3 if k % 2 else None)
        for key in out:
            out[key].append(observe(world, state) if key == "obs" else getattr(state, key))
    return {key: np.stack(v) for key, v in out.items()}


@pytest.fixture(scope="module")
def reference() -> dict[str, np.ndarray]:
    return load_reference(REFERENCE)


@pytest.fixture(scope="module")
def paper_reference() -> dict[str, np.ndarray]:
    return load_reference(PAPER_REFERENCE)


def _assert_matches(now: dict[str, np.ndarray], ref: dict[str, np.ndarray], prefix: str) -> None:
    for key in CONTINUOUS:
        np.testing.assert_allclose(now[key], ref[f"{prefix}/{key}"], rtol=0, atol=1e-9, err_msg=key)
    for key in DISCRETE:
        np.testing.assert_array_equal(now[key], ref[f"{prefix}/{key}"], err_msg=key)


@pytest.mark.parametrize("name", SCENARIOS)
@pytest.mark.parametrize("seed", SEEDS)
def test_the_compact_world_reproduces_the_earlier_reference(name, seed, reference):
    _assert_matches(trajectory(COMPACT[name], seed), reference, f"{name}/{seed}")


@pytest.mark.parametrize("name", PAPER)
@pytest.mark.parametrize("seed", SEEDS)
def test_the_paper_world_matches_its_reference(name, seed, paper_reference):
    _assert_matches(trajectory(name, seed), paper_reference, f"{name}/{seed}")


def test_the_reference_covers_humans_walls_and_collisions(reference):
    """The stored runs exercise what they guard: moving humans, walls and collisions."""
    walked = [
        np.abs(np.diff(reference[f"{n}/{s}/h_pos"], axis=0)).max()
        for n in SCENARIOS[:2]
        for s in SEEDS
    ]
    assert min(walked) > 0.0
    assert any(reference[f"{n}/{s}/collided"].any() for n in SCENARIOS for s in SEEDS)
    assert any(np.isfinite(reference[f"{n}/{s}/wall_gap"]).all() for n in SCENARIOS for s in SEEDS)


NEAR_TIE = 1e-6  # [m] a gap this close to 0 could flip a collision flag between CPUs


def test_discrete_outcomes_are_no_near_ties(reference, paper_reference):
    """Every stored gap is far from 0 compared with the continuous tolerance, so the
    collision flags are stable to last-bit differences and may be compared exactly."""
    for ref in (reference, paper_reference):
        for key, value in ref.items():
            if key.endswith(("/gap", "/wall_gap")):
                finite = value[np.isfinite(value)]
                assert np.all(np.abs(finite) > NEAR_TIE), key


if __name__ == "__main__":
    regenerate_reference(PAPER_REFERENCE, keyed_runs(trajectory, PAPER, SEEDS), sys.argv[1:])
