"""Stable-Baselines3 PPO on the Gymnasium environments, as a user of Gymnasium would train it.

``train_sb3_ppo`` makes ``pioneer/ElevatorHRRL-v1`` (or ``…HLRR-v1``; other scenarios through the
``scenario`` keyword) with ``stable_baselines3.common.env_util.make_vec_env``, trains SB3's
``PPO("MlpPolicy")`` with SB3's default hyperparameters on the environment's own reward (the
29-D LiDAR observation, absolute (v, ω) actions; ``reward="no-intrusion"`` passes the
CrowdNav++ reward without its intrusion term to the environments instead), and writes (each
file atomically, except the appended curve)

- ``policy.safetensors``: the policy network's tensors, with the SB3 version, the network
  architecture, the spaces and the training settings as JSON metadata. SB3's own ``.zip``
  holds pickles, which this project never asks a user to load, so it is not written;
- ``checkpoint.safetensors``: the training state, when training starts, after every PPO update
  (as the next rollout starts) and at the end: the policy's tensors, Adam's moments and step
  counts (one named tensor each), torch's global RNG state and the state of numpy's global
  RNG (SB3 draws its minibatches from it; the key array as a tensor), and as JSON the
  settings, SB3's ``num_timesteps`` and ``_n_updates`` and the learning curve's running state
  (its rows, the episode count, the window of (return, event) pairs, the elapsed time).
  Safetensors and JSON only: loading it runs no code;
- ``curve.csv`` (appended after every rollout), ``curve.png`` and ``train.json``.

``make_sb3_policy`` rebuilds the policy from that file (no pickle) as the registry's
``sb3-ppo`` policy; it acts on the observation alone with the Gaussian's mean.

Resuming: running the same command on an ``--out`` that holds a run continues from its
checkpoint (``--resume`` insists on one) up to ``--steps`` in all; ``curve.csv`` keeps its
rows and is appended to. A larger ``--steps`` extends a finished run; any other setting
(scenario, environments, seed, reward) must match the checkpoint's, otherwise the command is refused
(use a new ``--out``), as is a folder written before runs were resumable (a
``policy.safetensors`` without a checkpoint). Nothing is deleted. Ctrl-C or SIGTERM during an
update lets it finish and writes the checkpoint; during a rollout it stops at once (the
checkpoint written as that rollout started holds everything, and the rollout is collected
again). The run then prints what it kept and the command that resumes it.

A resumed run continues with the same weights, optimizer state, step count and RNG states,
but it is not bit-identical to an uninterrupted one: SB3's vector environment cannot save the
episodes in progress, so the environments restart their episodes at the resume. Their seeds
then come from the seed and ``num_timesteps`` (``train._env_seed``; at step 0 the seed itself,
as in a fresh run), so a resumed run is itself reproducible: the same sequence of commands
gives the same weights bit for bit.

The package: :mod:`.train` (the run, its resume rule and learning curve), :mod:`.checkpoint`
(the two files' formats, the training state written and restored), :mod:`.policy` (the
registry's ``sb3-ppo``). Needs the ``sb3`` extra: ``pip install pioneer-nav[sb3]``.
"""

from pioneer.baselines.sb3.checkpoint import CHECKPOINT, CURVE_COLUMNS, SB3_FORMAT, TRAIN_FORMAT
from pioneer.baselines.sb3.policy import Sb3Policy, make_sb3_policy
from pioneer.baselines.sb3.train import env_id_for, train_sb3_ppo

__all__ = [
    "CHECKPOINT",
    "CURVE_COLUMNS",
    "SB3_FORMAT",
    "TRAIN_FORMAT",
    "Sb3Policy",
    "env_id_for",
    "make_sb3_policy",
    "train_sb3_ppo",
]
