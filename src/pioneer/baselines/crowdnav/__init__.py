"""CrowdNav++ (Liu et al., ICRA 2023), the RL baseline: observation, network, PPO, imitation.

Modules: :mod:`.observation` (graph observation, action → command), :mod:`.network`
(actor–critic, checkpoints), :mod:`.policy` (the ``crowdnav++`` policy), :mod:`.ppo` (the
original's training recipe), :mod:`.imitation` (an optional behaviour-cloning warm start;
its episodes: :mod:`.collect`, :mod:`.bc_data`);
the reward is :mod:`pioneer.reward.crowdnav` (the Gymnasium environment's reward too).

Baseline ``crowdnav++`` of the paper's Table I: "Intention aware robot crowd navigation with
attention-based interaction graph". A recurrent actor–critic over a spatio-temporal graph of
the robot and the humans, with human–human self-attention, robot–human attention and the
humans' predicted trajectories, trained with PPO (:mod:`.ppo`) on the privileged
simulator state (ground-truth human positions and velocities, as in the original).

Formulation as implemented
--------------------------
*Observation* (:func:`build_observation`, from ``info["state"]`` and ``info["world"]``):

- robot node u = [p_x, p_y, r_r, g_x − p_x, g_y − p_y, v_pref, cos θ, sin θ]  (B, 8)
  Positions in the map frame (as the original, whose robot node holds absolute p and g):
  our scenes have walls at fixed map coordinates and the observation has no other wall
  information, so the absolute position is what lets the network learn where the walls are.
  The goal enters as its offset from the robot (the part that matters for reaching it, and
  translation invariant), the heading as (cos θ, sin θ) (no jump at ±π). v_pref = v_max.
- temporal edge w = [v, ω], the last applied command  (B, 2)  (the original uses the robot's
  (v_x, v_y); with incremental unicycle actions the command state is what the policy must know).
- spatial edges e_i = [p_i − p_r, p̂_i(1) − p_r, …, p̂_i(K) − p_r]  (B, N_max, 2(K + 1)),
  robot-relative current and K = 5 predicted positions of every present human, in the map
  frame, sorted by current distance, padded to ``max_humans`` with a mask (B, N_max).
  Absent humans (status GONE) and humans beyond ``sensor_range`` are masked; if more humans are
  present than ``max_humans``, the nearest are kept.
- Prediction: constant velocity from the privileged state, p̂_i(k) = p_i + k Δt_pred v_i with
  Δt_pred = 0.25 s (the original's step, so the horizon stays 1.25 s at our Δt = 0.1 s). The
  original uses a learned predictor (GST); CV is its simplest stand-in and needs no training.

*Network* (:class:`CrowdNavNet`; E = ``embed`` = 64, H = ``hidden`` = 64):

    r   = ReLU(W_r [u, w])                                     robot embedding (B, E)
    s_i = ReLU(W_s e_i)                                        human embeddings (B, N, E)
    A^hh = softmax_j((W_q s_i)ᵀ(W_k s_j) / √E | mask_j)        human–human attention (B, N, N)
    h_i = ReLU(s_i + Σ_j A^hh_ij W_v s_j) · mask_i
    a^rh = softmax_i((W_q' r)ᵀ(W_k' h_i) / √E | mask_i)         robot–human attention (B, N)
    c   = Σ_i a^rh_i h_i
    x   = ReLU(W_x [r, c]);   h_t = GRU(x, h_{t−1})           temporal part of the graph
    μ   = actor(h_t) (2,),   V = critic(h_t)                    tanh MLPs, 64 hidden units

The masked softmaxes give exactly zero weight to absent humans (and all-zero weights when no
human is present), so the output does not depend on the padded entries. The GRU's hidden state
is reset at the start of every episode (:meth:`CrowdNavPolicy.reset`).

*Action* (:func:`command_from_action`): a diagonal Gaussian N(μ, diag σ²) over a ∈ R², clipped to
[−1, 1]² and scaled piecewise-linearly (0 ↦ 0) onto the original's unicycle increments
Δv ∈ [−0.1, 0.087] m/s and Δθ ∈ [−0.06, 0.06] rad per step. The policy integrates them on
the command state, since our environment takes absolute commands:

    v_t = clip(v_{t−1} + Δv, v_min, v_max),   ω_t = clip(Δθ / Δt, −ω_max, ω_max)

with v_{t−1} = ``state.command[:, 0]`` and the limits of the world's robot. As in the original,
Δθ is the heading change of the step (not an increment of ω); at our Δt = 0.1 s the turn rate
is at most 0.6 rad/s (0.24 rad/s in the original at Δt = 0.25 s) and the speed can change by
up to 0.87 m/s² (0.35 m/s²). The original samples unit-scale raw actions and clips them to
these small ranges, so most samples saturate; scaling the unit box keeps the initial
Gaussian (σ = e^−0.5 ≈ 0.6) inside it. In eval mode the action is the mean μ (deterministic).

Checkpoints (:func:`save_crowdnav` / :func:`load_crowdnav`) are safetensors with the
:class:`CrowdNavConfig` and free-form info as JSON metadata; no pickle.
"""
