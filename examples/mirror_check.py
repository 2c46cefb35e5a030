"""Why does the teacher succeed less in HR-RL than in HL-RR, when the worlds are mirrors?

Runs the teacher on the same validation seeds in four arms (docs/calibration.md, "The
mirror check"):

1. ``hr-rl``   — HR-RL world, the density fitted on HR-RL's demos (as shipped);
2. ``hr-rl/hl`` — HR-RL world, HL-RR's density read through the mirror map of the features
   (sectors reversed, bearings and ω negated);
3. ``hl-rr``   — HL-RR world on the exact mirror images of arm 1's initial states, the density
   fitted on HL-RR's demos (as shipped);
4. ``rules``   — the rule terms alone in both worlds on the mirrored states (must agree
   episode for episode: the simulator and the rule terms are mirror-equivariant).

Arm 1 vs 2 isolates the demonstrations; 2 vs 3 isolates the one place where the features are
not mirror-equivariant: the 24 sectors group beams (0, 1, 2), (3, 4, 5), … from the heading,
so the mirror of a sector straddles two sectors (a one-beam, 5° offset).

    python examples/mirror_check.py --episodes 60
"""

from __future__ import annotations

import argparse
import dataclasses
from collections import Counter
from typing import Any

import numpy as np
from tqdm import tqdm

from pioneer.control.teacher import make_teacher
from pioneer.envs.env import NavEnv
from pioneer.reward.default import default_reward
from pioneer.seeds import validation_seed
from pioneer.sim.world import State

F64 = np.ndarray


def mirror_state(s: State) -> State:
    """The state reflected in x = 0 (the door's centre line): x → −x, θ → π − θ, ω → −ω."""

    def mx(a: F64) -> F64:
        out = a.copy()
        out[..., 0] *= -1.0
        return out

    robot = mx(s.robot)
    robot[:, 2] = np.arctan2(np.sin(np.pi - s.robot[:, 2]), np.cos(np.pi - s.robot[:, 2]))
    return dataclasses.replace(
        s,
        robot=robot,
        goal=mx(s.goal),
        start=mx(s.start),
        command=s.command * np.array([1.0, -1.0]),
        h_pos=mx(s.h_pos),
        h_vel=mx(s.h_vel),
        h_waypoints=mx(s.h_waypoints),
        h_home=mx(s.h_home),
    )


def mirror_features(z: F64) -> F64:
    """z = (r_1..r_24, d_1, d_2, φ_1, φ_2, φ_g, v, ω) of the mirror image, to one beam."""
    z = np.asarray(z, dtype=np.float64)
    out = z.copy()
    out[:, 0:24] = z[:, 23::-1]
    out[:, [26, 27, 28, 30]] *= -1.0
    return out


class MirroredDensity:
    """A density reward evaluated on the mirror image of its input."""

    def __init__(self, model: Any) -> None:
        self.model = model
        self.info_ = model.info_

    def __call__(self, z: F64) -> F64:
        return self.model(mirror_features(z))


def run(env: NavEnv, teacher: Any, seed: int, state: State | None) -> str:
    """One episode from ``state`` (or the env's own draw); its event."""
    obs, info = env.reset(seed=seed, options={"state": state} if state is not None else None)
    teacher.reset(info, np.random.default_rng(seed))
    while info.get("event") is None:
        obs, _, _, _, info = env.step(teacher.act(obs, info))
    return str(info["event"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=60)
    n = ap.parse_args().episodes
    hr, hl = NavEnv("hr-rl"), NavEnv("hl-rr")
    teachers = {
        "hr-rl": make_teacher("hr-rl"),
        "hr-rl/hl": make_teacher("hr-rl"),
        "hl-rr": make_teacher("hl-rr"),
        "rules hr-rl": make_teacher("hr-rl", density=False),
        "rules hl-rr": make_teacher("hl-rr", density=False),
    }
    teachers["hr-rl/hl"].density = MirroredDensity(default_reward("hl-rr"))  # type: ignore[assignment]
    events: dict[str, list[str]] = {k: [] for k in teachers}
    for k in tqdm(range(n), desc="mirror check"):
        seed = validation_seed("mirror", "hr-rl", k)
        hr.reset(seed=seed)
        start = hr.state.copy()
        mirrored = mirror_state(start)
        for arm, teacher in teachers.items():
            env, state = (hl, mirrored) if arm.endswith("hl-rr") else (hr, start)
            events[arm].append(run(env, teacher, seed, state))
    for arm, ev in events.items():
        c = Counter(ev)
        print(f"{arm:12s} success {100 * c['success'] / n:5.1f} %  {dict(c)}")
    same = sum(a == b for a, b in zip(events["rules hr-rl"], events["rules hl-rr"], strict=True))
    print(f"rule terms: {same}/{n} episodes end alike in the two worlds")


if __name__ == "__main__":
    main()
