"""What each CrowdNav++ reward pays for each way an episode goes (docs/baselines.md, "Which
reward").

    python examples/reward_returns.py [--episodes 20] [--policy teacher crowdnav++ sfm]

runs each policy on validation episodes of HR-RL and HL-RR and prices every step with each
reward ``pioneer train crowdnav++ --reward`` offers (:data:`pioneer.reward.crowdnav.REWARDS`),
from the states before and after the step and the world's event. Prints, per scenario, policy,
outcome and reward, the episodes' count and their mean return, undiscounted and discounted with
the trainer's γ per 0.1 s step (what PPO maximises), and the mean of each term.
"""

from __future__ import annotations

import argparse
from collections import defaultdict

import numpy as np

from pioneer.baselines.crowdnav.trainer import PPOConfig
from pioneer.control.registry import build_policy
from pioneer.envs.env import NavEnv
from pioneer.envs.episode import Episode, Step
from pioneer.envs.policy import Policy
from pioneer.reward.crowdnav import REWARDS, crowdnav_reward_terms
from pioneer.seeds import validation_seed

SCENARIOS = ("hr-rl", "hl-rr")


def returns(scenario: str, policy_name: str, episodes: int) -> list[dict[str, object]]:
    """One row per episode: its event and, per reward, the return, the discounted return and
    the sum of each term."""
    gamma = PPOConfig().gamma
    env = NavEnv(scenario)
    policy = build_policy(policy_name, scenario)
    rows = []
    for trial in range(episodes):
        rows.append(_episode(env, policy, validation_seed(scenario, 0, trial), gamma))
    return rows


def _episode(env: NavEnv, policy: Policy, seed: int, gamma: float) -> dict[str, object]:
    sums: dict[str, dict[str, float]] = {name: defaultdict(float) for name in REWARDS}
    disc = dict.fromkeys(REWARDS, 0.0)
    ep = Episode(env, policy, seed)

    def price(step: Step) -> None:
        prev, new = step.info["state"], step.next_info["state"]
        event = np.array([step.next_info["event_code"]], dtype=np.int8)
        for name, cfg in REWARDS.items():
            terms, total = crowdnav_reward_terms(env.world, prev, new, event, cfg)
            for k, v in terms.items():
                sums[name][k] += float(v[0])
            sums[name]["total"] += float(total[0])
            disc[name] += gamma**step.index * float(total[0])

    ep.run(price)
    return {"event": str(ep.event), **{n: (dict(sums[n]), disc[n]) for n in REWARDS}}


def main() -> None:
    """Print the table."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--policy", nargs="+", default=["teacher", "crowdnav++", "sfm"])
    args = ap.parse_args()
    print("| scenario | policy | outcome | episodes | reward | return | discounted | terms |")
    print("|---|---|---|---|---|---|---|---|")
    for sc in SCENARIOS:
        for pol in args.policy:
            rows = returns(sc, pol, args.episodes)
            for event in sorted({str(r["event"]) for r in rows}):
                sel = [r for r in rows if r["event"] == event]
                for name in REWARDS:
                    terms = [r[name][0] for r in sel]  # type: ignore[index]
                    total = np.mean([t["total"] for t in terms])
                    dsc = np.mean([r[name][1] for r in sel])  # type: ignore[index]
                    parts = ", ".join(
                        f"{k} {np.mean([t[k] for t in terms]):+.1f}"
                        for k in terms[0]
                        if k != "total" and any(abs(t[k]) > 1e-9 for t in terms)
                    )
                    print(
                        f"| {sc} | {pol} | {event} | {len(sel)} | {name} | {total:+.1f} | "
                        f"{dsc:+.1f} | {parts} |"
                    )


if __name__ == "__main__":
    main()
