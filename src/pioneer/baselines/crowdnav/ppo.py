"""PPO training of the CrowdNav++ baseline (Liu et al., ICRA 2023) in a PioneeR scenario.

``pioneer train crowdnav++ --scenario hr-rl --out DIR`` calls :func:`train_crowdnav`.

Environments
    B copies of the scenario stepped together by the pure batched core
    (:func:`pioneer.sim.world.step`); CrowdNav++ needs no LiDAR, so a step of 16 copies costs
    ~0.03 ms and the network dominates. Initial states are the scenario's randomised ones
    (:func:`pioneer.sim.scenarios.sample_state`), each from its own episode seed drawn from the
    trainer's ``np.random.Generator``. An episode ends on success, collision (humans or walls)
    or at the time limit (30 s); every end is terminal for the returns, as in the original
    (the time is not observed, so the timeout is not bootstrapped).

Reward: :func:`pioneer.reward.crowdnav.crowdnav_reward` (the original's unicycle terms, also
the Gymnasium environments' reward).

PPO (Schulman et al. 2017) with GAE, clip 0.2, 5 epochs, 2 minibatches, 30-step rollouts per
environment, value-loss weight 0.5, gradient norm ≤ 0.5, Adam (ε = 1e−5) — the original's
values, except:

- discount and GAE λ per step are converted to our 0.1 s step so that they weigh time as the
  original's 0.99 and 0.95 per 0.25 s step do: γ = 0.99^0.4 ≈ 0.996, λ = 0.95^0.4 ≈ 0.98
  (with 0.99 per 0.1 s the success reward 20 s ahead would count 0.13 instead of 0.45);
- learning rate 3e−4: the original's 4e−5 is for 20 M steps, our budget is a few million;
- entropy bonus 0.01 (original: none), against an early collapse of σ; at our budget, pilots
  with and without it settled the same way ("drive to the door and wait", docs/baselines.md);
- the shipped weights use 64 environments (``--envs 64``; default 16 as the original): the
  update costs about the same for 16 or 64 (10 gradient steps, dominated by per-op overhead),
  so 4× the data per update comes almost free in wall time; the warm-started rows fine-tune an
  imitation warm start (below) with no entropy bonus and a small learning rate
  (``--lr 3e-5 --entropy-coef 0`` for ``crowdnav++-il``; ``--lr 1e-5`` for
  ``crowdnav++-il-teacher``, whose clone also explores with ``--ppo-std 0.1`` and learns with
  ``--value-coef 0.01``: actor and critic share the encoder and the GRU, and at the original's
  0.5 the critic's gradient reshaped the shared layers and took the clone from 80 to 20 %
  success on validation episodes, docs/baselines.md).

Imitation warm start (``--bc-episodes N``, :mod:`~pioneer.baselines.crowdnav.imitation`; a deviation
from CrowdNav++, after the imitation pretraining of the CrowdNav family): before PPO the network
clones the lookahead teacher (optionally with DAgger rounds); its result is stored in ``out`` and in
the first checkpoint, so a resumed run never redoes it. ``--critic-warmup U``: the
first U updates train only the critic head (own Adam), the cloned actor frozen, so PPO's
first policy updates see a fitted critic. ``--ppo-std S``: PPO starts from σ = S instead of the
clone's σ (its RMS residual). All are off by default (pure PPO, as above).

Recurrent minibatches are whole 30-step sequences of a subset of the environments; the GRU
is re-run from the rollout's first hidden state with resets at episode starts, the whole
sequence in one numba kernel each way (:func:`pioneer.nn.recurrent.gru_sequence`, equal to
the step-by-step ``GRUCell`` to float32 rounding); Adam is PyTorch's fused one. Advantages
are normalised over the rollout. The rollouts act through the network's NumPy forward
(:class:`~.inference.CrowdNavInference`, with the critic's value); the update runs in torch,
on one intra-op thread by default (``torch_threads``: on an otherwise idle 2-core machine
two threads train ≈ 1.2× faster, beside another busy process ≈ 2× slower, docs/performance.md;
a seeded run repeats itself with any fixed number, and on the hosts measured 1 and 2 threads
gave the same weights bit for bit).

Outputs in ``out/`` (each written atomically)::

    ``checkpoint.safetensors``  the whole training state every ``checkpoint_every`` updates:
                                weights, Adam moments, the environments' states, GRU states,
                                episode accumulators, the learning curve and the RNG states
                                (numpy ``bit_generator.state`` as JSON ints, torch generator
                                bytes as a tensor) — a resumed run is identical to an
                                uninterrupted one;
    ``policy.safetensors``      the policy weights (:func:`~.network.load_crowdnav`);
    ``curve.csv`` / ``curve.png``  the learning curve, ``train.json`` the run's summary;
    ``imitation/`` / ``bc_policy.safetensors``  the imitation data (one file per episode)
                                and the cloned policy (with ``--bc-episodes``).

Resuming: running the same command on an ``out`` that holds a checkpoint continues from it
(``--resume`` insists on one). A larger ``--steps`` extends a finished run; any other setting
must match the checkpoint's, otherwise it is an error (use a new ``--out``). Nothing is
deleted.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import torch

from pioneer.baselines.crowdnav.imitation import WarmStartConfig
from pioneer.baselines.crowdnav.network import CrowdNavConfig, save_crowdnav
from pioneer.baselines.crowdnav.trainer import CURVE_COLUMNS, PPOConfig, _Trainer, compute_gae
from pioneer.interrupt import Interrupted
from pioneer.io import output_dir_kind, run_lock, to_json, write_text_atomic
from pioneer.nn.ppo import check_resume, curve_columns, curve_csv, update_loop
from pioneer.reward.crowdnav import CrowdNavRewardConfig
from pioneer.sim.scenarios import get_scenario

__all__ = ["CURVE_COLUMNS", "PPOConfig", "compute_gae", "train_crowdnav"]


# ------------------------------------------------------------------------------ outputs
def _write_outputs(tr: _Trainer, out: Path, info: Mapping[str, Any], final: bool) -> None:
    tr.save(out / "checkpoint.safetensors")
    save_crowdnav(tr.model, out / "policy.safetensors", info)
    write_text_atomic(out / "curve.csv", curve_csv(CURVE_COLUMNS, tr.curve))
    if final:
        from pioneer.viz.plots import plot_learning_curve

        plot_learning_curve(
            curve_columns(CURVE_COLUMNS, tr.curve),
            out / "curve.png",
            title=f"CrowdNav++ · {tr.scenario.name} · "
            + ("imitation + PPO" if tr.warm.bc_episodes else "PPO"),
        )
        write_text_atomic(out / "train.json", to_json(dict(info), indent=2) + "\n")


def _train_loop(
    tr: _Trainer,
    out: Path,
    info: Callable[[], dict[str, Any]],
    progress: bool,
    on_update: Callable[[dict[str, float]], None] | None,
) -> None:
    """PPO updates until the budget, with a progress bar and periodic checkpoints."""
    ppo = tr.ppo
    update_loop(
        tr,
        ppo.updates,
        ppo.steps_per_update,
        CURVE_COLUMNS,
        f"crowdnav++ {tr.scenario.name}",
        progress,
        ppo.checkpoint_every,
        lambda: _write_outputs(tr, out, info(), final=False),
        on_update,
    )


def _imitation(tr: _Trainer, out: Path, fresh: bool, progress: bool) -> dict[str, Any] | None:
    """With ``--bc-episodes``: the imitation phase's summary, and for a ``fresh`` run (no
    checkpoint yet) its result loaded into ``tr`` and saved as the first checkpoint (the
    phase itself reuses what is in ``out``)."""
    if not tr.warm.bc_episodes:
        return None
    from pioneer.baselines.crowdnav.imitation import POLICY_FILE, warm_start
    from pioneer.baselines.crowdnav.network import read_crowdnav_meta

    if fresh:
        model, info = warm_start(
            tr.scenario, tr.net_cfg, tr.warm, tr.ppo.seed, out, progress=progress
        )
        tr.model.load_state_dict(model.state_dict(), strict=True)
        if tr.warm.ppo_std is not None:  # PPO explores around the clone with this σ
            with torch.no_grad():
                tr.model.log_std.fill_(math.log(tr.warm.ppo_std))
        tr.save(out / "checkpoint.safetensors")
        return info
    if (out / POLICY_FILE).is_file():
        return dict(read_crowdnav_meta(out / POLICY_FILE)["info"])
    return None


def train_crowdnav(
    scenario: str,
    out_dir: str | Path,
    ppo: PPOConfig | None = None,
    net: CrowdNavConfig | None = None,
    reward: CrowdNavRewardConfig | None = None,
    warm: WarmStartConfig | None = None,
    resume: bool | None = None,
    progress: bool = True,
    command: str = "",
    torch_threads: int | None = 1,
    on_update: Callable[[dict[str, float]], None] | None = None,
) -> dict[str, Any]:
    """Train (or resume) CrowdNav++ on ``scenario``; returns the summary written to train.json.

    ``resume``: ``None`` continues from ``out/checkpoint.safetensors`` if there is one,
    ``True`` requires it, ``False`` refuses an ``out`` that holds one (nothing is deleted).
    ``torch_threads``: torch's intra-op threads (``None``: leave torch's setting).
    Every setting is checked before ``out`` is created; one run writes to it at a time
    (:func:`pioneer.io.run_lock`).
    """
    ppo = ppo or PPOConfig()
    sc = get_scenario(scenario)
    out = output_dir_kind(out_dir)
    ckpt = out / "checkpoint.safetensors"
    check_resume(resume, ckpt, out)
    if torch_threads is not None:
        torch.set_num_threads(int(torch_threads))
    # One spatial-edge slot per human of the scenario unless configured otherwise.
    net = net or CrowdNavConfig(max_humans=max(1, len(sc.humans)))
    warm = warm or WarmStartConfig()
    tr = _Trainer(sc, ppo, net, reward or CrowdNavRewardConfig(), warm)
    with run_lock(out):
        check_resume(resume, ckpt, out)  # again, holding the lock
        return _train(tr, out, ckpt, warm, command, progress, on_update)


def _train(
    tr: _Trainer,
    out: Path,
    ckpt: Path,
    warm: WarmStartConfig,
    command: str,
    progress: bool,
    on_update: Callable[[dict[str, float]], None] | None,
) -> dict[str, Any]:
    sc, ppo = tr.scenario, tr.ppo
    resumed_from = None
    if ckpt.is_file():
        tr.load(ckpt)
        resumed_from = tr.update
    bc_info = _imitation(tr, out, resumed_from is None, progress)

    def info() -> dict[str, Any]:
        last = tr.curve[-1] if tr.curve else [math.nan] * len(CURVE_COLUMNS)
        return {
            "scenario": sc.name,
            "command": command,
            "updates": tr.update,
            "env_steps": tr.env_steps,
            "episodes": tr.episodes,
            "wall_time_s": round(tr.wall, 1),
            "resumed_from_update": resumed_from,
            "final": dict(zip(CURVE_COLUMNS[3:7], last[3:7], strict=True)),
            "ppo": ppo.to_dict(),
            "reward": tr.reward_cfg.to_dict(),
            **({"warm_start": warm.to_dict()} if warm.active else {}),
            **(
                {"imitation": {k: bc_info[k] for k in ("data", "bc_loss", "log_std")}}
                if bc_info
                else {}
            ),
        }

    t_start, s_start = time.perf_counter(), tr.env_steps
    try:
        _train_loop(tr, out, info, progress, on_update)
        summary = info()
        summary["steps_per_s_this_run"] = (tr.env_steps - s_start) / max(
            time.perf_counter() - t_start, 1e-9
        )
        _write_outputs(tr, out, summary, final=True)
    except Interrupted as exc:  # between two updates (they run deferred): keep every one
        _write_outputs(tr, out, info(), final=False)
        exc.kept = f"update {tr.update} of {ppo.updates} kept in {ckpt}"
        raise
    return summary
