"""CrowdNav++ baseline: graph observation, attention and masking, increments → commands, PPO's
GAE against a brute-force oracle, the reward terms, checkpoints, determinism, the shipped
weights in the spawned-process harness, the training command end to end with resume (also
after SIGINT or SIGTERM), and the imitation warm start (teacher actions in the policy's action
space, cloning, its rounds on disk, resume during and after it)."""

from __future__ import annotations

import csv
import json
import math
import shlex
import shutil
import signal

import numpy as np
import pytest
import torch

from pioneer.baselines.crowdnav import collect as crowdnav_collect
from pioneer.baselines.crowdnav import imitation as crowdnav_bc
from pioneer.baselines.crowdnav.bc_data import BCData
from pioneer.baselines.crowdnav.collect import action_from_command, collect_episode, episode_seeds
from pioneer.baselines.crowdnav.imitation import WarmStartConfig, bc_loss, train_bc, warm_start
from pioneer.baselines.crowdnav.network import (
    CHECKPOINT_FORMAT,
    CrowdNavConfig,
    CrowdNavNet,
    load_crowdnav,
    read_crowdnav_meta,
    save_crowdnav,
)
from pioneer.baselines.crowdnav.observation import build_observation, command_from_action
from pioneer.baselines.crowdnav.policy import CrowdNavPolicy
from pioneer.baselines.crowdnav.ppo import PPOConfig, compute_gae
from pioneer.cli import main
from pioneer.control.registry import build_policy
from pioneer.data import shipped_crowdnav_weights as shipped_weights
from pioneer.errors import ConfigError, DataError
from pioneer.eval.episode import run_episode
from pioneer.eval.harness import PolicySpec, evaluate
from pioneer.reward.crowdnav import NO_INTRUSION, crowdnav_reward
from pioneer.reward.crowdnav import CrowdNavRewardConfig as RewardConfig
from pioneer.sim.events import classify
from pioneer.sim.humans import GONE
from pioneer.sim.robot import RobotConfig
from pioneer.sim.scenarios import get_scenario, sample_state
from pioneer.sim.world import step
from pioneer_testutils import (
    STOP_SIGNALS,
    assert_house_message,
    file_tree,
    interrupted_line,
    make_state,
    open_world,
    stop_cli,
)

torch.set_num_threads(1)


def random_graph(seed: int, b: int = 4, n: int = 5, cfg: CrowdNavConfig | None = None):
    cfg = cfg or CrowdNavConfig(max_humans=n)
    g = torch.Generator().manual_seed(seed)
    robot = torch.randn(b, 8, generator=g)
    temporal = torch.randn(b, 2, generator=g)
    spatial = torch.randn(b, n, cfg.spatial_dim, generator=g) * 2.0
    mask = torch.rand(b, n, generator=g) < 0.6
    mask[0] = False  # nobody present
    mask[1] = True  # everybody present
    return robot, temporal, spatial, mask


# ------------------------------------------------------------------------- network
def test_attention_shapes_and_weights():
    net = CrowdNavNet(CrowdNavConfig(max_humans=5), seed=3)
    robot, temporal, spatial, mask = random_graph(0)
    x, a_rh, a_hh = net.encode(robot, temporal, spatial, mask)
    assert x.shape == (4, 64)
    assert a_rh.shape == (4, 5)
    assert a_hh.shape == (4, 5, 5)
    for b in range(4):
        m = mask[b]
        assert torch.all(a_rh[b][~m] == 0)
        assert torch.all(a_hh[b][:, ~m] == 0)
        if m.any():
            assert float(a_rh[b][m].sum().detach()) == pytest.approx(1.0, abs=1e-6)
            assert torch.allclose(a_hh[b].sum(-1), torch.ones(5), atol=1e-6)
        else:
            assert torch.all(a_rh[b] == 0)
    assert torch.isfinite(x).all()
    # Leading batch dimensions are kept (the PPO update encodes (T, B, …) at once).
    x2, a2, h2 = net.encode(
        *(t.reshape(2, 2, *t.shape[1:]) for t in (robot, temporal, spatial, mask))
    )
    assert x2.shape == (2, 2, 64) and a2.shape == (2, 2, 5) and h2.shape == (2, 2, 5, 5)
    assert torch.allclose(x2.reshape(4, 64), x, atol=1e-6)


def test_output_invariant_to_padded_entries():
    net = CrowdNavNet(CrowdNavConfig(max_humans=5), seed=4)
    robot, temporal, spatial, mask = random_graph(1)
    h = torch.randn(4, 64, generator=torch.Generator().manual_seed(9))
    mean, value, h1 = net(robot, temporal, spatial, mask, h)
    junk = spatial.clone()
    junk[~mask] = torch.randn(int((~mask).sum()), spatial.shape[-1]) * 100.0
    mean2, value2, h2 = net(robot, temporal, junk, mask, h)
    assert torch.equal(mean, mean2) and torch.equal(value, value2) and torch.equal(h1, h2)
    # The gradients stay finite with nobody present (masked softmax of an all-masked row).
    net.train()
    m, v, _ = net(robot, temporal, spatial, mask, h)
    (m.sum() + v.sum()).backward()
    assert all(torch.isfinite(p.grad).all() for p in net.parameters() if p.grad is not None)


# ------------------------------------------------------------------------- observation
def test_observation_sorted_masked_and_predicted():
    world = open_world()
    humans = [
        {"pos": (3.0, 0.0), "vel": (0.0, 0.4)},
        {"pos": (0.0, 1.5), "vel": (-0.2, 0.0)},
        {"pos": (-1.0, 0.0), "status": GONE},
        {"pos": (9.0, 0.0)},  # beyond the 5 m sensor range
    ]
    s = make_state((1.0, 0.0, 0.5), goal=(4.0, 4.0), humans=humans)
    s.command[:] = (0.3, -0.2)
    cfg = CrowdNavConfig(max_humans=4)
    o = build_observation(s, world, cfg)
    assert o.robot.shape == (1, 8) and o.spatial.shape == (1, 4, 12) and o.mask.shape == (1, 4)
    np.testing.assert_allclose(
        o.robot[0], [1.0, 0.0, 0.3, 3.0, 4.0, 0.8, math.cos(0.5), math.sin(0.5)], rtol=1e-6
    )
    np.testing.assert_allclose(o.temporal[0], [0.3, -0.2])
    assert o.mask[0].tolist() == [True, True, False, False]
    # Nearest first: human 1 at 1.80 m, then human 0 at 2 m; K = 5 CV predictions at 0.25 s.
    k = np.arange(6) * 0.25
    want1 = np.stack([-1.0 - 0.2 * k, 1.5 + 0 * k], -1).ravel()
    want0 = np.stack([2.0 + 0 * k, 0.4 * k], -1).ravel()
    np.testing.assert_allclose(o.spatial[0, 0], want1, atol=1e-6)
    np.testing.assert_allclose(o.spatial[0, 1], want0, atol=1e-6)
    assert np.all(o.spatial[0, 2:] == 0)
    # Fewer slots than present humans: the nearest are kept.
    o2 = build_observation(s, world, CrowdNavConfig(max_humans=1))
    np.testing.assert_allclose(o2.spatial[0, 0], want1, atol=1e-6)


def test_command_from_action_integrates_increments():
    robot = RobotConfig()
    cfg = CrowdNavConfig()
    v_prev = np.array([0.0, 0.5, 0.78, 0.3])
    a = np.array([[1.0, 1.0], [-1.0, -1.0], [5.0, 0.5], [0.0, 0.0]])
    u = command_from_action(a, v_prev, robot, 0.1, cfg)
    np.testing.assert_allclose(u[:, 0], [0.087, 0.4, 0.8, 0.3])  # clipped to v_max
    np.testing.assert_allclose(u[:, 1], [0.6, -0.6, 0.3, 0.0])  # Δθ / Δt
    u = command_from_action(np.array([[-1.0, 0.0]]), np.array([0.05]), robot, 0.1, cfg)
    assert u[0, 0] == 0.0  # never below v_min


# ------------------------------------------------------------------------- PPO pieces
def gae_oracle(r, v, d, last, gamma, lam):
    """Brute force: A_t = Σ_l (γλ)^l δ_{t+l}, summed until the episode's last step."""
    t_len, b = r.shape
    vn = np.concatenate([v, last[None]], axis=0)
    adv = np.zeros_like(r)
    for j in range(b):
        for t in range(t_len):
            total, factor = 0.0, 1.0
            for u in range(t, t_len):
                delta = r[u, j] + gamma * vn[u + 1, j] * (1 - d[u, j]) - v[u, j]
                total += factor * delta
                if d[u, j]:
                    break
                factor *= gamma * lam
            adv[t, j] = total
    return adv


@pytest.mark.parametrize("seed", range(6))
def test_gae_matches_bruteforce(seed):
    rng = np.random.default_rng(seed)
    t_len, b = int(rng.integers(1, 12)), int(rng.integers(1, 4))
    r, v = rng.normal(size=(t_len, b)), rng.normal(size=(t_len, b))
    d = (rng.random((t_len, b)) < 0.25).astype(float)
    last = rng.normal(size=b)
    gamma, lam = float(rng.uniform(0.8, 1.0)), float(rng.uniform(0.0, 1.0))
    adv, ret = compute_gae(r, v, d, last, gamma, lam)
    np.testing.assert_allclose(adv, gae_oracle(r, v, d, last, gamma, lam), atol=1e-10)
    np.testing.assert_allclose(ret, adv + v)
    # λ = 1: the return is the discounted sum up to the episode end (or the bootstrap).
    _, ret1 = compute_gae(r, v, d, last, gamma, 1.0)
    for j in range(b):
        for t in range(t_len):
            g, f = 0.0, 1.0
            for u in range(t, t_len):
                g += f * r[u, j]
                f *= gamma
                if d[u, j]:
                    break
            else:
                g += f * last[j]
            assert ret1[t, j] == pytest.approx(g, abs=1e-9)


def test_reward_terms():
    world = open_world()
    rc = RewardConfig()
    # Potential only: nobody near, goal straight ahead; 3 × (decrease of goal distance).
    s0 = make_state((0.0, 0.0, 0.0), goal=(5.0, 0.0), humans=[{"pos": (0.0, 10.0)}])
    s1 = step(world, s0, [0.5, 0.0])
    ev = classify(s0, s1, world.sim.time_limit)
    r = crowdnav_reward(world, s0, s1, ev, rc)
    assert ev[0] == 0
    assert r[0] == pytest.approx(3.0 * 0.05, abs=1e-9)
    # Intrusion: a human walking into the robot's place in 0.5 s (k = 2) but not at 0.25 s.
    s0 = make_state(
        (0.0, 0.0, 0.0),
        goal=(5.0, 0.0),
        humans=[{"pos": (2.0, 0.0), "vel": (-2.4, 0.0), "goal": (-5.0, 0.0)}],
    )
    s1 = step(world, s0, [0.0, 0.0])
    s1.h_pos[:] = (2.15, 0.0)
    s1.h_vel[:] = (-2.4, 0.0)
    s1.gap[:] = 1.25
    r = crowdnav_reward(world, s1, s1, classify(s1, s1, world.sim.time_limit), rc)
    # k = 1: 2.15 − 0.6 = 1.55 m (clear); k = 2: 0.95 m (clear, > 0.9); k = 3: 0.35 m (hit).
    # Charged per 0.25 s step in the original: × Δt/T = 0.1/0.25 per 0.1 s step here.
    assert r[0] == pytest.approx(-20.0 / 2**4 * 0.4)
    none = classify(s1, s1, world.sim.time_limit)
    r_step = crowdnav_reward(world, s1, s1, none, RewardConfig(reference_dt=None))
    assert r_step[0] == pytest.approx(-20.0 / 2**4)
    # Discomfort replaces the potential; spin on the heading change of the step.
    s1.gap[:] = 0.05
    s1.h_pos[:] = (9.0, 9.0)
    s1.command[:] = (0.0, 0.5)
    r = crowdnav_reward(world, s1, s1, classify(s1, s1, world.sim.time_limit), rc)
    assert r[0] == pytest.approx((0.05 - 0.25) * 10 * 0.1 - 4.5 * 0.05**2 / 0.4)
    # Collision and success end the episode with their constants.
    s0 = make_state((0.0, 0.0, 0.0), goal=(0.2, 0.0), humans=[{"pos": (0.0, 10.0)}])
    s1 = step(world, s0, [0.3, 0.0])
    ev = classify(s0, s1, world.sim.time_limit)
    r = crowdnav_reward(world, s0, s1, ev, rc)
    assert ev[0] == 1 and r[0] == pytest.approx(10.0)
    s0 = make_state((0.0, 0.0, 0.0), goal=(5.0, 0.0), humans=[{"pos": (0.95, 0.0)}])
    s1 = step(world, s0, [0.8, 0.0])
    ev = classify(s0, s1, world.sim.time_limit)
    r = crowdnav_reward(world, s0, s1, ev, rc)
    assert ev[0] == 2 and r[0] == pytest.approx(-20.0)


def test_ppo_config_errors():
    with pytest.raises(ConfigError) as e:
        PPOConfig(minibatches=4, n_envs=2)
    assert_house_message(str(e.value), "minibatches")
    with pytest.raises(ConfigError):
        PPOConfig(total_steps=0)
    with pytest.raises(ConfigError):
        CrowdNavConfig(dv_range=(0.1, 0.2))


# ------------------------------------------------------------------------- checkpoints, policy
def test_checkpoint_round_trip_and_errors(tmp_path):
    net = CrowdNavNet(CrowdNavConfig(max_humans=3, embed=16, hidden=8), seed=5)
    p = save_crowdnav(net, tmp_path / "w.safetensors", {"scenario": "hr-rl"})
    back = load_crowdnav(p)
    assert back.config == net.config
    for k, v in net.state_dict().items():
        assert torch.equal(back.state_dict()[k], v)
    assert read_crowdnav_meta(p)["info"] == {"scenario": "hr-rl"}
    bad = tmp_path / "bad.safetensors"
    bad.write_bytes(p.read_bytes()[:100])
    with pytest.raises(DataError) as e:
        load_crowdnav(bad)
    assert_house_message(str(e.value))
    with pytest.raises(DataError):
        shipped_weights("static")


def test_checkpoint_with_foreign_or_non_finite_tensors_is_refused(tmp_path):
    from safetensors.torch import load_file, save_file

    net = CrowdNavNet(CrowdNavConfig(max_humans=3, embed=16, hidden=8), seed=5)
    p = save_crowdnav(net, tmp_path / "w.safetensors")
    meta = read_crowdnav_meta(p)
    raw = {"format": CHECKPOINT_FORMAT, "config": json.dumps(meta["config"])}
    tensors = load_file(str(p))
    # Weights of a wider network under this config: the error names the mis-shaped tensors.
    wide = CrowdNavNet(CrowdNavConfig(max_humans=3, embed=32, hidden=8), seed=5)
    save_file(
        {k: v.contiguous() for k, v in wide.state_dict().items()},
        str(tmp_path / "wide.st"),
        metadata=raw,
    )
    with pytest.raises(DataError) as e:
        load_crowdnav(tmp_path / "wide.st")
    assert_house_message(str(e.value), "tensors", "shape")
    name = next(iter(tensors))
    tensors[name].view(-1)[0] = float("nan")
    save_file(tensors, str(tmp_path / "nan.st"), metadata=raw)
    with pytest.raises(DataError) as e:
        load_crowdnav(tmp_path / "nan.st")
    assert_house_message(str(e.value), name, "finite float32")


def test_policy_is_deterministic_and_registered():
    pol = CrowdNavPolicy(CrowdNavNet(CrowdNavConfig(max_humans=3), seed=6))
    a, _ = run_episode("hr-rl", pol, seed=11)
    b, _ = run_episode("hr-rl", pol, seed=11)
    assert a == b
    shipped = build_policy("crowdnav++", "hr-rl")
    assert shipped.name == "crowdnav++"


def test_shipped_weights_in_spawned_harness(tmp_path):
    for sc in ("hr-rl", "hl-rr"):
        pure = read_crowdnav_meta(shipped_weights(sc))["info"]
        assert pure["scenario"] == sc
        # the crowdnav++ row is pure PPO (the original's recipe)
        assert "warm_start" not in pure and pure["ppo"]["lr"] == 4e-5
        # the imitation warm start ships for the compact world only (no independent expert
        # succeeds in the paper world), under its own row name
        warm = read_crowdnav_meta(shipped_weights(f"{sc}-compact", "il"))["info"]
        assert warm["warm_start"]["expert"] == "sfm"
        with pytest.raises(DataError, match=f"crowdnav-{sc}-compact"):
            shipped_weights(f"{sc}-compact")
        with pytest.raises(DataError, match=f"crowdnav-il-{sc}"):
            shipped_weights(sc, "il")
        # the paper world's warm start imitates the teacher and is paid without intrusion
        arrive = read_crowdnav_meta(shipped_weights(sc, "il-teacher"))["info"]
        assert arrive["scenario"] == sc and arrive["warm_start"]["expert"] == "teacher"
        assert arrive["reward"] == NO_INTRUSION.to_dict()
        assert arrive["ppo"]["seed"] == 0
    assert build_policy("crowdnav++-il", "hl-rr-compact").name == "crowdnav++-il"
    assert build_policy("crowdnav++-il-teacher", "hr-rl").name == "crowdnav++-il-teacher"
    with pytest.raises(DataError, match="variant"):
        shipped_weights("hr-rl", "bogus")
    recs = evaluate(
        ["hr-rl"], [PolicySpec.make("crowdnav++")], 1, 2, tmp_path, workers=2, progress=False
    )
    assert len(recs) == 2
    assert {r["policy"] for r in recs} == {"crowdnav++"}
    assert all(r["event"] in {"success", "collision", "timeout"} for r in recs)
    assert all(r["path_length_m"] > 0.1 for r in recs)  # a trained policy drives


# ------------------------------------------------------------------------- the CLI
def _train(out, steps, *extra):
    argv = ["train", "crowdnav++", "--scenario", "hr-rl", "--out", str(out), "--steps", str(steps)]
    return main([*argv, "--envs", "2", "--checkpoint-every", "1", *extra])


def _curve(out):
    with open(out / "curve.csv") as fh:
        return [{k: v for k, v in row.items() if k != "wall_time_s"} for row in csv.DictReader(fh)]


def test_train_cli_end_to_end_and_resume(tmp_path, capsys):
    a, b = tmp_path / "a", tmp_path / "b"
    assert _train(a, 120) == 0  # 2 updates of 2 envs × 30 steps
    assert (a / "curve.png").is_file() and (a / "checkpoint.safetensors").is_file()
    assert [r["update"] for r in _curve(a)] == ["1", "2"]
    assert _train(a, 240, "--resume") == 0  # continues at update 3
    info = json.loads((a / "train.json").read_text())
    assert info["resumed_from_update"] == 2 and info["updates"] == 4 and info["env_steps"] == 240
    assert _train(b, 240) == 0  # the same run, uninterrupted
    assert _curve(a) == _curve(b)
    wa, wb = load_crowdnav(a / "policy.safetensors"), load_crowdnav(b / "policy.safetensors")
    for k, v in wa.state_dict().items():
        assert torch.equal(v, wb.state_dict()[k]), k
    assert _train(a, 240) == 0  # finished: a rerun changes nothing
    assert json.loads((a / "train.json").read_text())["updates"] == 4
    capsys.readouterr()


@pytest.mark.slow
@STOP_SIGNALS
def test_a_signal_stops_training_between_updates_and_the_rerun_matches(
    tmp_path, capsys, signum, group
):
    """Stopped mid-run: exit 128 + signal within 2 s, no process left, every finished update
    kept (not only those of the last periodic checkpoint) and named in the one line; the
    rerun continues from there and ends as the uninterrupted run."""
    a, b = tmp_path / "a", tmp_path / "b"

    def argv_to(out):  # 30 updates of ~0.15 s
        return [
            "train", "crowdnav++", "--scenario", "hr-rl", "--out", str(out), "--steps", "1800",
            "--envs", "2", "--checkpoint-every", "4",
        ]  # fmt: skip

    argv = argv_to(a)
    ckpt = a / "checkpoint.safetensors"
    stopped = stop_cli(argv, ckpt.is_file, signum, tmp_path, group)
    name = signal.Signals(signum).name
    with capsys.disabled():
        print(f"{name}: exit {stopped.returncode} in {stopped.seconds:.2f} s")
    stopped.assert_clean(signum)
    updates = len(_curve(a))
    assert 4 <= updates < 30
    assert interrupted_line(stopped.stderr) == (
        f"pioneer: interrupted ({name}); update {updates} of 30 kept in "
        f"{ckpt}; resume with: {shlex.join(['pioneer', *argv])}"
    )
    assert main(argv) == 0  # resumed
    assert json.loads((a / "train.json").read_text())["resumed_from_update"] == updates
    assert main(argv_to(b)) == 0  # uninterrupted
    assert _curve(a) == _curve(b)
    wa, wb = load_crowdnav(a / "policy.safetensors"), load_crowdnav(b / "policy.safetensors")
    for k, v in wa.state_dict().items():
        assert torch.equal(v, wb.state_dict()[k]), k
    capsys.readouterr()


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        (["--steps", "0"], "--steps"),
        (["--scenario", "nope"], "scenario"),
        (["--envs", "1"], "minibatches"),
        (["--resume"], "--resume"),
        (["--lr", "-1"], "--lr"),
        (["--threads", "0"], "--threads"),
        (["--reward", "no-time-cost"], "--reward"),
    ],
)
def test_train_cli_bad_input(tmp_path, capsys, extra, needle):
    base = {"--steps": "60", "--envs": "2"}
    base.pop(extra[0], None)  # the bad value replaces the default (an option may not repeat)
    argv = ["train", "crowdnav++", "--out", str(tmp_path / "x")]
    argv += [a for kv in base.items() for a in kv]
    try:  # a value out of range is refused with the command line (SystemExit), others later
        code = main([*argv, *extra])
    except SystemExit as exc:
        code = int(exc.code or 0)
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("pioneer: error:")
    assert needle in err[0]
    assert not (tmp_path / "x").exists()  # refused before anything is written


@pytest.mark.parametrize(
    ("other", "needle"),
    [(["--lr", "1e-3"], "ppo.lr"), (["--reward", "no-intrusion"], "reward.intrusion")],
)
def test_train_cli_refuses_other_settings_on_resume(tmp_path, capsys, other, needle):
    assert _train(tmp_path, 60) == 0
    capsys.readouterr()
    before = file_tree(tmp_path)
    assert _train(tmp_path, 120, *other) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]
    assert file_tree(tmp_path) == before


# ------------------------------------------------------------------------- imitation warm start
@pytest.fixture(scope="module")
def teacher_episode():
    from pioneer.control.teacher import make_teacher

    sc = get_scenario("hr-rl-compact")  # a world where this teacher episode succeeds
    world = sc.world()
    cfg = CrowdNavConfig(max_humans=3)
    ep = collect_episode(sc, world, make_teacher("hr-rl-compact"), 123, cfg)
    return sc, world, cfg, BCData.from_episodes([{**ep, "round": np.array(0)}])


def test_action_from_command_inverts_command_from_action():
    cfg = CrowdNavConfig()
    rng = np.random.default_rng(0)
    a = rng.uniform(-1.0, 1.0, size=(50, 2))
    v_prev = rng.uniform(0.2, 0.6, size=50)  # away from v_min/v_max: no command clipping
    u = command_from_action(a, v_prev, RobotConfig(), 0.1, cfg)
    np.testing.assert_allclose(action_from_command(u, v_prev, 0.1, cfg), a, atol=1e-12)
    # Out of reach: clipped to the increment bounds.
    far = action_from_command(np.array([[0.8, -1.2]]), np.array([0.0]), 0.1, cfg)
    np.testing.assert_allclose(far, [[1.0, -1.0]])


def test_teacher_episode_replays_through_the_action_space(teacher_episode):
    sc, world, cfg, data = teacher_episode
    sim = world.sim
    assert data.ep_event.tolist() == [1]  # the teacher succeeds through the action space
    s = sample_state(sc, np.random.default_rng(int(data.ep_seed[0])))
    for t in range(data.episode.size):
        cmd = command_from_action(data.action[t : t + 1], s.command[:, 0], sim.robot, sim.dt, cfg)
        np.testing.assert_allclose(cmd[0], data.command[t], atol=1e-6)  # float32 labels
        # The applied command is the teacher's, clipped to what one increment can reach.
        lo = max(sim.robot.v_min, s.command[0, 0] + cfg.dv_range[0])
        hi = min(sim.robot.v_max, s.command[0, 0] + cfg.dv_range[1])
        want_v = np.clip(data.teacher_command[t, 0], lo, hi)
        assert abs(data.command[t, 0] - want_v) < 1e-6
        w_max = min(sim.robot.omega_max, cfg.dtheta_range[1] / sim.dt)
        assert abs(data.command[t, 1] - np.clip(data.teacher_command[t, 1], -w_max, w_max)) < 1e-6
        s = step(world, s, cmd)
    assert s.reached[0]
    summary = data.summary()
    assert summary["teacher_clipped_fraction"] < 0.2


def test_bc_reduces_imitation_loss(teacher_episode):
    data = teacher_episode[3]
    small = CrowdNavConfig(max_humans=3, embed=16, hidden=16, head_hidden=16)
    warm = WarmStartConfig(bc_episodes=1, bc_epochs=40, bc_lr=1e-2)
    before = bc_loss(CrowdNavNet(small, seed=0), data)
    model, losses = train_bc(data, small, warm, seed=0)
    assert losses[-1] < 0.7 * losses[0]
    assert bc_loss(model, data) < 0.7 * before
    assert torch.all(model.log_std >= math.log(warm.min_std) - 1e-6)
    again, losses2 = train_bc(data, small, warm, seed=0)  # seeded: identical
    assert losses == losses2
    assert all(torch.equal(v, again.state_dict()[k]) for k, v in model.state_dict().items())
    with pytest.raises(ConfigError):
        WarmStartConfig(dagger_rounds=1)


def test_train_cli_warm_start_and_resume_after_imitation(tmp_path, capsys, monkeypatch):
    """The ``crowdnav++-il-teacher`` recipe in small (the teacher's demonstrations, a DAgger
    round, the critic warm-up, PPO paid without the intrusion term): resumed after any update
    or after the imitation phase, it ends as the uninterrupted run, bit for bit."""
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    warm = [
        "--bc-expert", "teacher", "--bc-episodes", "2", "--bc-epochs", "2", "--dagger-rounds",
        "1", "--dagger-episodes", "1", "--critic-warmup", "1", "--reward", "no-intrusion",
        "--ppo-std", "0.1", "--value-coef", "0.01",
    ]  # fmt: skip
    assert _train(b, 120, *warm) == 0  # uninterrupted: imitation, 1 critic-only + 1 PPO update
    info = json.loads((b / "train.json").read_text())
    assert info["imitation"]["data"]["episodes"] == 3 and info["updates"] == 2
    assert info["reward"] == NO_INTRUSION.to_dict()
    assert info["warm_start"]["expert"] == "teacher"
    assert load_crowdnav(b / "bc_policy.safetensors").config.max_humans == 3
    assert _train(a, 60, *warm) == 0  # stopped after the critic warm-up update
    # PPO starts from σ = --ppo-std (the critic warm-up leaves the actor as it is)
    std = torch.exp(load_crowdnav(a / "policy.safetensors").log_std.detach())
    torch.testing.assert_close(std, torch.full((2,), 0.1), rtol=1e-6, atol=0.0)

    def boom(*args, **kwargs):
        raise AssertionError("the imitation phase was redone")

    monkeypatch.setattr(crowdnav_collect, "collect_episode", boom)
    monkeypatch.setattr(crowdnav_bc, "train_bc", boom)
    assert _train(a, 120, *warm, "--resume") == 0  # from the checkpoint
    # Interrupted after imitation, before any PPO checkpoint: its files are reused.
    c.mkdir()
    shutil.copytree(a / "imitation", c / "imitation")
    shutil.copy(a / "bc_policy.safetensors", c / "bc_policy.safetensors")
    assert _train(c, 120, *warm) == 0
    for out in (a, c):
        assert _curve(out) == _curve(b)
        wo, wb = load_crowdnav(out / "policy.safetensors"), load_crowdnav(b / "policy.safetensors")
        for k, v in wo.state_dict().items():
            assert torch.equal(v, wb.state_dict()[k]), (out.name, k)
    capsys.readouterr()
    bigger = [*warm]
    bigger[bigger.index("--bc-episodes") + 1] = "3"
    assert _train(a, 180, *bigger) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bc_episodes" in err[0]


# ------------------------------------------------------------------------- imitation rounds
SMALL = CrowdNavConfig(max_humans=3, embed=16, hidden=16, head_hidden=16)
WARM = WarmStartConfig(bc_episodes=2, bc_epochs=2, dagger_rounds=2, dagger_episodes=1)


def _warm(out, config=WARM, **kwargs):
    sc = get_scenario("hr-rl")
    return warm_start(sc, SMALL, config, 0, out, progress=False, **kwargs)


def _same_weights(a, b):
    sa, sb = a.state_dict(), b.state_dict()
    return list(sa) == list(sb) and all(torch.equal(v, sb[k]) for k, v in sa.items())


@pytest.fixture(scope="module")
def warm_run(tmp_path_factory):
    """An uninterrupted imitation phase: 2 expert episodes, 2 DAgger rounds of 1."""
    out = tmp_path_factory.mktemp("warm") / "run"
    model, info = _warm(out)
    return out, model, info


def test_imitation_rounds_are_stored_one_episode_per_file(warm_run):
    out, model, info = warm_run
    rounds = out / "imitation" / "rounds"
    assert sorted(str(p.relative_to(rounds)) for p in rounds.rglob("*")) == [
        "round-00", "round-00/ep-000.npz", "round-00/ep-001.npz", "round-00/policy.safetensors",
        "round-01", "round-01/ep-000.npz", "round-01/policy.safetensors",
        "round-02", "round-02/ep-000.npz", "round-02/policy.safetensors",
    ]  # fmt: skip
    settings = json.loads((out / "imitation" / "config.json").read_text())
    assert settings == info["settings"] and settings["dagger_rounds"] == 2
    assert info["data"]["episodes"] == 4 and set(info["data"]) >= {"round0", "round1", "round2"}
    # the clone is the last round's; each round's is a fresh fit on the rounds so far
    assert _same_weights(model, load_crowdnav(rounds / "round-02" / "policy.safetensors"))
    first = read_crowdnav_meta(rounds / "round-00" / "policy.safetensors")["info"]
    assert first["round"] == 0 and first["data"]["episodes"] == 2
    assert first["driver_loss_on_round"] is None  # nobody drove round 0 but the expert
    later = read_crowdnav_meta(rounds / "round-01" / "policy.safetensors")["info"]
    assert later["driver_loss_on_round"] > 0
    with np.load(rounds / "round-01" / "ep-000.npz", allow_pickle=False) as f:
        assert int(f["round"]) == 1 and str(f["event"]) in {"success", "collision", "timeout"}


def test_an_interrupted_imitation_resumes_to_the_same_clone(warm_run, tmp_path, monkeypatch):
    """Episodes and clones on disk are reused; a missing episode is collected again and the
    clones from its round on refitted, to the uninterrupted run's weights."""
    out, model, _ = warm_run
    run = tmp_path / "run"
    shutil.copytree(out / "imitation", run / "imitation")
    rounds = run / "imitation" / "rounds"
    (rounds / "round-01" / "ep-000.npz").unlink()
    for r in (1, 2):
        (rounds / f"round-{r:02d}" / "policy.safetensors").unlink()
    (rounds / "round-02" / ".ep-000.npz.abcd1234.npz").write_bytes(b"half")  # a killed write
    collected = []
    real = crowdnav_collect.collect_episode
    monkeypatch.setattr(
        crowdnav_collect, "collect_episode", lambda *a, **k: collected.append(a[3]) or real(*a, **k)
    )
    again, _ = _warm(run)
    assert collected == [episode_seeds(0, 1, 1)[0]]
    assert _same_weights(model, again)
    assert not list(run.rglob(".*.npz"))
    for p in sorted((out / "imitation" / "rounds").rglob("ep-*.npz")):
        with np.load(p) as x, np.load(run / p.relative_to(out)) as y:
            for k in x.files:
                np.testing.assert_array_equal(x[k], y[k], err_msg=f"{p}:{k}")


def test_a_resumed_imitation_over_a_corrupt_episode_is_refused_before_any_work(
    warm_run, tmp_path, monkeypatch
):
    """A corrupt episode is named before a resumed run collects anything (the warm start used
    to collect the missing episodes of the rounds before it first)."""
    out, _, _ = warm_run
    run = tmp_path / "run"
    shutil.copytree(out / "imitation", run / "imitation")
    rounds = run / "imitation" / "rounds"
    (rounds / "round-00" / "ep-000.npz").unlink()  # an episode still to collect, first
    (rounds / "round-01" / "ep-000.npz").write_bytes(b"truncated")
    collected = []
    monkeypatch.setattr(crowdnav_collect, "collect_episode", lambda *a, **k: collected.append(a))
    before = file_tree(run)
    with pytest.raises(DataError) as err:
        _warm(run)
    assert_house_message(str(err.value), "round-01", "ep-000.npz", "delete that file")
    assert file_tree(run) == before and collected == []


def test_an_imitation_of_other_settings_is_refused_before_writing(warm_run, tmp_path):
    out, _, _ = warm_run
    run = tmp_path / "run"
    shutil.copytree(out / "imitation", run / "imitation")
    before = file_tree(run)
    with pytest.raises(ConfigError) as err:
        _warm(run, WarmStartConfig(bc_episodes=2, bc_epochs=3, dagger_rounds=2, dagger_episodes=1))
    assert_house_message(str(err.value), "bc_epochs", "'bc_epochs': 2", "--out")
    assert file_tree(run) == before
    # more rounds extend the run
    _, info = _warm(run, WARM.replace(dagger_rounds=3))
    assert info["data"]["episodes"] == 5


@pytest.mark.slow
def test_imitation_episodes_collected_by_two_workers_are_the_same(warm_run, tmp_path):
    out, model, _ = warm_run
    try:
        again, _ = _warm(tmp_path / "w2", workers=2)
    finally:
        torch.set_num_threads(1)  # the run sets one torch thread per worker in this process
    assert _same_weights(model, again)
    for p in sorted((out / "imitation" / "rounds").rglob("ep-*.npz")):
        with np.load(p) as x, np.load(tmp_path / "w2" / p.relative_to(out)) as y:
            for k in x.files:
                np.testing.assert_array_equal(x[k], y[k], err_msg=f"{p}:{k}")
