"""The trajectory kernel with the copies in SIMD lanes (``advance(..., lanes=True)``): the
reference kernel's values bit for bit, and its vectorised e^x (``vector_exp``) within 2 ulp."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pioneer.errors import ConfigError
from pioneer.sim import get_scenario, sample_state
from pioneer.sim.humans import ARRIVED, GONE
from pioneer.sim.world import State, WorldTrace, advance
from pioneer.vecmath import exp64_lanes
from pioneer_testutils import states_equal


def _copies(name: str, seed: int, n_b: int) -> tuple[object, State, np.ndarray]:
    """``n_b`` different seeded start states of ``name`` in one batch, and random commands
    (each copy its own people, speeds and command: lanes must not mix them up)."""
    scenario = get_scenario(name)
    rng = np.random.default_rng(seed)
    states = State.concat([sample_state(scenario, rng) for _ in range(n_b)])
    u = np.stack([rng.uniform(-0.2, 0.9, n_b), rng.uniform(-1.5, 1.5, n_b)], axis=1)
    return scenario.world(), states, u


def _assert_same(a: WorldTrace, b: WorldTrace) -> None:
    assert states_equal(a.final, b.final)
    for name in ("poses", "circles", "gap", "wall_gap", "live_steps"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


@pytest.mark.parametrize("stop", [True, False])
@pytest.mark.parametrize(("name", "seed"), [("hr-rl", 1), ("hl-rr", 2), ("hr-rl-compact", 3)])
def test_lanes_are_the_reference_bit_for_bit(name, seed, stop):
    """Over 12 s (people board, arrive, leave the map; copies collide and stop at different
    steps) every state array and every record equals the reference kernel's."""
    world, s0, u = _copies(name, seed, 37)
    ref = advance(world, s0, u, dt=0.3, n_steps=40, stop_at_collision=stop)
    lanes = advance(world, s0, u, dt=0.3, n_steps=40, stop_at_collision=stop, lanes=True)
    _assert_same(ref, lanes)
    assert (ref.final.h_wp_index != s0.h_wp_index).any()  # people passed waypoints
    if stop:  # both kinds of copies were there
        assert 0 < ref.final.collided.sum() < 37
        assert len(set(ref.live_steps.tolist())) > 2


def test_lanes_follow_people_to_the_end_of_their_paths():
    """30 s of slow robots: people wait for others, arrive (static obstacles) and leave the
    map (removed): every branch of the people's bookkeeping, as in the reference."""
    world, s0, u = _copies("hr-rl", 8, 16)
    u[:, 0] = np.abs(u[:, 0]) * 0.2
    ref = advance(world, s0, u, dt=0.3, n_steps=100)
    _assert_same(ref, advance(world, s0, u, dt=0.3, n_steps=100, lanes=True))
    assert s0.h_wait_for.any()
    assert (ref.final.h_status == ARRIVED).any() and (ref.final.h_status == GONE).any()


def test_lanes_leave_copies_collided_on_entry_as_they_are():
    """With ``stop_at_collision`` a copy collided before the call is not advanced (its lane is
    never used), the others are: as in the reference."""
    world, s0, u = _copies("hr-rl", 4, 11)
    s0.collided[::3] = True
    ref = advance(world, s0, u, dt=0.3, n_steps=8, stop_at_collision=True)
    lanes = advance(world, s0, u, dt=0.3, n_steps=8, stop_at_collision=True, lanes=True)
    _assert_same(ref, lanes)
    np.testing.assert_array_equal(lanes.live_steps[::3], 1)
    np.testing.assert_array_equal(lanes.final.robot[::3], s0.robot[::3])


def test_lanes_of_the_teachers_candidates_are_the_reference():
    """The teacher's case: one state, 120 candidates (the rollout uses lanes)."""
    from pioneer.control.teacher import make_teacher

    world, s0, _ = _copies("hr-rl", 5, 1)
    cand = make_teacher("hr-rl").candidates
    copies = s0.repeat(cand.shape[0])
    for stop in (True, False):
        _assert_same(
            advance(world, copies, cand, dt=0.3, n_steps=10, stop_at_collision=stop),
            advance(world, copies, cand, dt=0.3, n_steps=10, stop_at_collision=stop, lanes=True),
        )


def test_exp_lanes_is_within_two_ulp_of_libm():
    """The vectorised e^x against ``math.exp`` on the forces' range and the whole domain it
    serves (|z| <= 700); masked lanes are exactly 0."""
    rng = np.random.default_rng(0)
    for lo, hi in ((-12.0, 4.0), (-700.0, 700.0), (-1e-6, 1e-6)):
        z = rng.uniform(lo, hi, 20_000)
        ok = rng.random(z.size) < 0.8
        out = np.empty_like(z)
        exp64_lanes(z, ok, out, np.empty_like(z), z.size)
        ref = np.array([math.exp(v) for v in z[ok]])
        assert np.all(np.abs(out[ok] - ref) <= 2 * np.spacing(ref))
        assert np.all(out[~ok] == 0.0)
    out = np.empty(3)
    exp64_lanes(np.array([0.0, 1.0, -1.0]), np.ones(3, bool), out, np.empty(3), 3)
    assert out[0] == 1.0 and out[1] == pytest.approx(math.e, rel=1e-15)


def test_vector_exp_moves_the_rollout_by_last_bits_only():
    """``vector_exp`` changes the forces in their last bits: the predicted world stays within
    nanometres of the reference over 3 s, and repeats bit for bit."""
    world, s0, u = _copies("hr-rl", 6, 24)
    ref = advance(world, s0, u, dt=0.3, n_steps=10, lanes=True)
    fast = advance(world, s0, u, dt=0.3, n_steps=10, lanes=True, vector_exp=True)
    again = advance(world, s0, u, dt=0.3, n_steps=10, lanes=True, vector_exp=True)
    _assert_same(fast, again)
    assert not np.array_equal(fast.circles, ref.circles)
    np.testing.assert_allclose(fast.circles, ref.circles, rtol=0.0, atol=1e-9)
    np.testing.assert_array_equal(fast.final.collided, ref.final.collided)


def test_vector_exp_needs_lanes():
    world, s0, u = _copies("hr-rl", 7, 2)
    with pytest.raises(ConfigError, match="lanes=True"):
        advance(world, s0, u, dt=0.3, n_steps=2, vector_exp=True)


def test_lanes_without_people_or_walls():
    """No people (the static study's world) and no walls (an open world): the loops over them
    are empty, the rest is the reference's."""
    from pioneer_testutils import make_state, open_world

    world = open_world()
    rng = np.random.default_rng(9)
    for humans in ([], [{"pos": (2.0, 1.5)}]):
        s0 = make_state((0.0, 0.0, 0.0), goal=(3.0, 0.0), humans=humans).repeat(5)
        u = np.stack([rng.uniform(0.0, 0.8, 5), rng.uniform(-1.0, 1.0, 5)], axis=1)
        for stop in (True, False):
            _assert_same(
                advance(world, s0, u, dt=0.3, n_steps=6, stop_at_collision=stop),
                advance(world, s0, u, dt=0.3, n_steps=6, stop_at_collision=stop, lanes=True),
            )


@pytest.mark.parametrize("lanes", [False, True])
def test_in_place_advances_the_given_state_itself(lanes):
    """``in_place`` skips the copy: the trace's final state is the argument, advanced to the
    values a copying call gives; the copying call leaves its argument alone."""
    world, s0, u = _copies("hr-rl", 4, 9)
    before = s0.copy()
    copied = advance(world, s0, u, dt=0.3, n_steps=10, stop_at_collision=True, lanes=lanes)
    assert states_equal(s0, before)
    mine = s0.copy()
    owned = advance(
        world, mine, u, dt=0.3, n_steps=10, stop_at_collision=True, lanes=lanes, in_place=True
    )
    assert owned.final is mine
    _assert_same(copied, owned)


def test_repeat_gives_independent_copies():
    _, s0, _ = _copies("hr-rl", 5, 1)
    r = s0.repeat(4)
    assert r.batch_size == 4 and states_equal(r.take(2), s0)
    r.h_pos[1] += 1.0
    assert states_equal(r.take(0), s0) and not states_equal(r.take(1), s0)
