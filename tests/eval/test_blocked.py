"""pioneer.eval.blocked: whether the robot still has a way to its goal among people standing
where they are, against a brute-force oracle of the door; and the timeouts' ``blocked``
measure."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray

from pioneer.eval.blocked import CELL_M, way_open
from pioneer.eval.episode import run_episode
from pioneer.eval.metrics import MEASURE_LIST
from pioneer.seeds import episode_seed
from pioneer.sim.scenarios import get_scenario

PAPER = get_scenario("hr-rl")  # a 1.8 m door (posts at x = ±0.9, y = 0) into a 2.5 × 2.7 m cabin
R_R = PAPER.sim.robot.radius
POST = PAPER.walls[1][0]  # the right door post; the left one at −POST
START, GOAL = (0.0, -2.0), (0.0, 2.0)  # in the lobby, deep in the cabin


def _open(people: list[tuple[float, float]], radii: list[float]) -> bool:
    return way_open(PAPER.walls, R_R, START, GOAL, 0.1, people, radii)


@settings(max_examples=120, deadline=None)
@given(x=st.floats(-POST, POST), r_h=st.floats(0.2, 0.6))
def test_a_person_in_the_door_line_leaves_a_way_exactly_when_a_gap_fits_the_robot(
    x: float, r_h: float
) -> None:
    # The oracle: a person centred on the door line, between the posts, leaves the robot the
    # wider of the two gaps to a post, (x + post) − r_h or (post − x) − r_h; the robot passes
    # exactly when it is at least its diameter (inside the wider cabin and lobby, nothing
    # narrower follows). Cases within two cells of the threshold are the grid's to round.
    gap = max(x + POST, POST - x) - r_h
    assume(abs(gap - 2 * R_R) > 2 * CELL_M)
    assert _open([(x, 0.0)], [r_h]) == (gap > 2 * R_R)


def test_an_empty_world_is_open_and_two_people_filling_the_door_close_it() -> None:
    assert _open([], [])
    assert not _open([(-0.45, 0.0), (0.45, 0.0)], [0.3, 0.3])  # 0.0 m left between them
    assert _open([(-0.7, 0.0), (0.7, 0.0)], [0.2, 0.2])  # 1.0 m between them
    # a person standing on the goal itself leaves no goal region to reach
    assert not _open([GOAL], [0.3])


class _Still:
    """Stands where it starts: the boarders fill the cabin around it, or walk into it."""

    name = "still"

    def reset(self, info: Mapping[str, Any], rng: np.random.Generator) -> None:
        """Stateless."""

    def act(self, obs: NDArray[np.float32], info: Mapping[str, Any]) -> NDArray[np.float64]:
        """Zero command."""
        return np.zeros(2)


def test_a_robot_that_waits_out_the_paper_world_is_shut_out_and_only_timeouts_say_so() -> None:
    # validation episode 9 of HR-RL: nobody walks into the still robot; the two boarders
    # fill the cabin, the last one standing in its door (docs/metrics.md, "blocked")
    rec, _ = run_episode("hr-rl", _Still(), seed=episode_seed("validation", "hr-rl", 0, 9))
    assert rec.event == "timeout" and rec.measures["blocked"] is True
    goal, _ = run_episode("hr-rl", _Still(), seed=episode_seed("validation", "hr-rl", 0, 0))
    assert goal.event != "timeout" and goal.measures["blocked"] is None
    (rate,) = [m for m in MEASURE_LIST if m.key == "blocked_timeout_rate"]
    assert rate.test is not None and rate.test(rec.measures) and not rate.test(goal.measures)
