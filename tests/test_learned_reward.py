"""The AE / VAE learned-reward baselines: rewards on hand-made codes, training, and their place in the loss."""

import json
import math

import numpy as np
import pytest
import torch
from lerobot.configs import FeatureType

from benchmarks.speed.updates import make_batch, make_policy, policy_update, rgbd_features
from lerobot_indicator.keys import goal_key
from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy import learned_reward as lr
from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfigError
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

RGB, DEPTH = "observation.images.front", "observation.images.front_depth"
SMALL = {"hidden_dims": [16, 16, 16], "conv_precision": "float32", "filter": False, "balance": False}
STATS = {
    RGB: {"mean": torch.full((3, 1, 1), 0.5), "std": torch.full((3, 1, 1), 0.3)},
    DEPTH: {"mean": torch.full((1, 1, 1), 1150.0), "std": torch.full((1, 1, 1), 500.0)},
}


def policy_and_batch(reward: str, size: int = 24, batch_size: int = 8, **config):
    torch.manual_seed(0)
    features = rgbd_features(size)
    policy = make_policy(features, reward=reward, **{**SMALL, **config})
    policy.set_observation_stats(STATS)
    return policy, make_batch(features, batch_size)


def test_ae_reward_is_the_clipped_cosine_of_the_codes():
    code = torch.tensor([[1.0, 0.0], [1.0, 1.0], [-1.0, 0.0], [0.0, 3.0]])
    goal = torch.tensor([[2.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.0, 0.5]])
    expected = [1.0, 1 / math.sqrt(2), 0.0, 1.0]  # scale-free; opposite codes clip to 0
    assert lr.ae_reward(code, goal).tolist() == pytest.approx(expected)


def test_vae_reward_is_the_negative_latent_distance():
    mean = torch.tensor([[0.0, 0.0], [3.0, 4.0], [1.0, 1.0]])
    goal = torch.tensor([[0.0, 0.0], [0.0, 0.0], [2.0, 1.0]])
    assert lr.vae_reward(mean, goal).tolist() == pytest.approx([0.0, -5.0, -1.0])


def test_gaussian_kl_by_hand():
    mean = torch.tensor([[1.0, 0.0], [0.0, 0.0]])
    log_var = torch.tensor([[0.0, math.log(2.0)], [0.0, 0.0]])
    expected = [0.5 * 1.0 + 0.5 * (2.0 - 1.0 - math.log(2.0)), 0.0]
    assert lr.gaussian_kl(mean, log_var).tolist() == pytest.approx(expected)


@pytest.mark.parametrize("reward", ["ae", "vae"])
def test_reward_model_reward_uses_the_codes_of_o_next_and_the_goal(reward):
    policy, batch = policy_and_batch(reward)
    model = policy.reward_model
    keys = [RGB, DEPTH]
    next_obs = {k: batch[core.NEXT + k] for k in keys}
    goal = {k: batch[goal_key(k)] for k in keys}
    code, _ = model.encode(model.images(next_obs))
    goal_code, _ = model.encode(model.images(goal))
    by_hand = lr.vae_reward(code, goal_code) if reward == "vae" else lr.ae_reward(code, goal_code)
    torch.testing.assert_close(model.reward(next_obs, goal), by_hand)
    # A goal that is o_{t+1} gets the best reward: 1 (AE) / 0 (VAE).
    assert model.reward(next_obs, next_obs).tolist() == pytest.approx(
        [policy.config.reward_range[1]] * 8, abs=1e-5
    )


def test_n_step_rewards_encode_the_goals_once_and_match_the_one_step_reward():
    """With 3-step targets the rewards of o_{t+1}, o_{t+2}, o_{t+3} share one encoding of the goals: the
    reward encoder sees B goals + 3 x B frames (not 3 x 2B), and the loss's o_t batch once."""
    policy, _ = policy_and_batch("ae", n_step=3, horizon=3)
    batch = make_batch(rgbd_features(24), 8, n_step=3)
    seen = []
    policy.reward_model.encoder.register_forward_hook(lambda _m, i, _o: seen.append(int(i[0].shape[0])))
    policy.forward(batch)
    assert sorted(seen) == [8] * 5  # goals, o_{t+1}, o_{t+2}, o_{t+3}, and o_t for the reconstruction loss
    keys = [RGB, DEPTH]
    goal = {k: batch[goal_key(k)] for k in keys}
    next_obs = {k: batch[core.NEXT + k] for k in keys}
    reward_to_goal = policy.reward_model.reward_to(goal)
    torch.testing.assert_close(reward_to_goal(next_obs), policy.reward_model.reward(next_obs, goal))


@pytest.mark.parametrize("precision", ["float32", "bfloat16"])
def test_reward_model_convs_run_in_the_conv_precision(precision):
    policy, batch = policy_and_batch("vae", conv_precision=precision)
    dtypes = []
    for conv in [m for m in policy.reward_model.modules() if isinstance(m, torch.nn.Conv2d)]:
        conv.register_forward_hook(lambda _m, _i, out: dtypes.append(out.dtype))
    loss, _ = policy.reward_model.loss({k: batch[k] for k in (RGB, DEPTH)})
    assert loss.dtype == torch.float32 and torch.isfinite(loss)
    assert set(dtypes) == {torch.bfloat16 if precision == "bfloat16" else torch.float32} and len(dtypes) == 8


def test_ae_reconstruction_loss_decreases_on_a_fixed_batch():
    policy, _ = policy_and_batch("ae")
    model = policy.reward_model
    # Eight frames of one colour and depth each (a square brighter than the rest): learnable structure, unlike
    # i.i.d. pixel noise.
    gen = torch.Generator().manual_seed(0)
    rgb = (torch.rand(8, 3, 1, 1, generator=gen) * 255).expand(8, 3, 24, 24).clone()
    rgb[:, :, 6:14, 6:14] = 255 - rgb[:, :, 6:14, 6:14]
    depth = (torch.rand(8, 1, 1, 1, generator=gen) * 1000 + 600).expand(8, 1, 24, 24).clone()
    frames = {RGB: rgb.to(torch.uint8), DEPTH: depth}
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
    losses = []
    for _ in range(60):
        loss, _ = model.loss(frames)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    assert losses[-1] < 0.5 * losses[0], losses[::10]


def test_vae_loss_is_reconstruction_plus_beta_kl():
    policy, batch = policy_and_batch("vae", vae_beta=5.0)
    torch.manual_seed(1)
    loss, stats = policy.reward_model.loss({k: batch[k] for k in (RGB, DEPTH)})
    expected = stats["reward_model_reconstruction"] + 5.0 * stats["reward_model_kl"]
    assert loss.item() == pytest.approx(expected.item(), rel=1e-5)
    assert stats["reward_model_kl"] > 0


@pytest.mark.parametrize("reward", ["ae", "vae"])
def test_learned_reward_replaces_the_indicator_in_the_td_target(reward, monkeypatch):
    policy, batch = policy_and_batch(reward)
    fixed = torch.linspace(0.0, 1.0, 8) if reward == "ae" else -torch.linspace(0.0, 3.0, 8)
    monkeypatch.setattr(policy.reward_model, "reward_to", lambda goal: lambda frames: fixed)
    # Target critic constant K: the TD target is r + gamma K, clipped to the reward's return range.
    last = policy.target_critic.net[-1]
    torch.nn.init.zeros_(last.weight)
    torch.nn.init.constant_(last.bias, -2.0)
    _, stats = policy.forward(batch)
    cfg = policy.config
    expected = (fixed + cfg.gamma * -2.0).clamp(cfg.q_min, cfg.q_max).mean().item()
    assert stats["q_target_mean"] == pytest.approx(expected, abs=1e-5)
    assert stats["reward_mean"] == pytest.approx(fixed.mean().item())


def test_reward_model_is_trained_only_by_its_own_loss_and_in_the_same_step():
    policy, batch = policy_and_batch("ae")
    params = [p for group in policy.get_optim_params() for p in group["params"]]
    model_params = list(policy.reward_model.parameters())
    assert all(any(p is q for q in params) for p in model_params)  # the one optimizer moves it
    before = [p.detach().clone() for p in model_params]
    policy_update(policy, batch)()
    assert any(not torch.equal(b, p) for b, p in zip(before, model_params, strict=True))
    # Without its own loss no gradient reaches it: the reward enters the TD target without gradients.
    policy.zero_grad()
    original = policy.reward_model.loss
    policy.reward_model.loss = lambda frames: (original(frames)[0] * 0.0, {})
    loss, _ = policy.forward(batch)
    loss.backward()
    assert all(p.grad is None or not p.grad.any() for p in model_params)


def test_learned_reward_logs_ranking_and_error_rates_against_ground_truth():
    policy, batch = policy_and_batch("ae", batch_size=6)
    gt = torch.tensor([[0.0, 0.0]] * 6)
    batch[core.GT_NEXT_ACHIEVED] = gt
    batch[core.GT_FUTURE_ACHIEVED] = gt
    batch[core.GT_DESIRED] = gt + torch.tensor(
        [[0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [5.0, 0.0], [5.0, 0.0], [5.0, 0]]
    )
    # Goals recorded for everyone (no relabeling): rows 0-2 are ground-truth successes, rows 3-5 not.
    policy.config.p_future_unbalanced = 0.0
    fixed = torch.tensor([0.95, 0.2, 0.99, 0.97, 0.1, 0.0])
    policy.reward_model.reward_to = lambda goal: lambda frames: fixed
    _, stats = policy.forward(batch)
    # positive = reward >= 0.9: rows 0, 2, 3. FN: row 1 of 3 successes; FP: row 3 of 3 failures.
    assert stats["false_negative_rate"] == pytest.approx(1 / 3)
    assert stats["false_positive_rate"] == pytest.approx(1 / 3)
    # Pairs (success, failure) ranked right: 0.95 > {0.1, 0}, 0.2 > {0.1, 0}, 0.99 > all three; 0.95 and 0.2
    # lose to 0.97: 7 of 9.
    assert stats["reward_auc"] == pytest.approx(7 / 9)


def test_config_errors_name_the_field():
    with pytest.raises(IndicatorDDPGConfigError, match=r"filter=True drops R- transitions, but reward='ae'"):
        make_policy(rgbd_features(24), reward="ae", filter=True)
    with pytest.raises(ValueError, match=r"reward='vae' learns its reward from images"):
        make_policy({"observation.state": (FeatureType.STATE, (3,))}, reward="vae", filter=False)
    with pytest.raises(ValueError, match=r"images of 24x24 px are too small for 5 conv \+ max-pool layers"):
        make_policy(rgbd_features(24), reward="ae", filter=False, reward_conv_channels=[4] * 5)


@pytest.mark.parametrize("reward", ["ae", "vae"])
def test_short_online_rope_rgbd_run_trains_and_reloads_the_reward_model(tmp_path, reward):
    import draccus

    from lerobot_indicator.training.config import OnlineTrainConfig
    from lerobot_indicator.training.online import OnlineTrainer

    args = [
        "--policy.type=indicator_ddpg", "--policy.push_to_hub=false", "--policy.device=cpu",
        "--online.n_envs=1", "--online.use_async_envs=false", "--online.episodes_per_cycle=1",
        "--online.updates_per_cycle=3", "--online.batch_size=8", "--online.eval_episodes=1",
        "--env_eval_freq=6", "--save_freq=6", "--seed=3", "--steps=6",
        "--env.type=rope_push", "--env.obs_type=rgbd", "--env.camera.height=24", "--env.camera.width=24",
        f"--policy.observation_keys=[{RGB},{DEPTH}]", "--policy.hidden_dims=[16,16,16]",
        f"--policy.reward={reward}", "--policy.filter=false", "--policy.balance=false",
        f"--output_dir={tmp_path / 'run'}",
    ]  # fmt: skip
    cfg = draccus.parse(OnlineTrainConfig, args=args)
    cfg.validate()
    trainer = OnlineTrainer(cfg)
    try:
        trainer.train()
        model_state = {k: v.clone() for k, v in trainer.policy.reward_model.state_dict().items()}
    finally:
        trainer.close()
    rows = [json.loads(line) for line in (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()]
    for key in (
        "reward_model_reconstruction",
        "reward_mean",
        "reward_auc",
        "false_positive_rate",
        "q_target_mean",
    ):
        assert math.isfinite(rows[-1][key]), key
    assert ("reward_model_kl" in rows[-1]) == (reward == "vae")
    loaded = IndicatorDDPGPolicy.from_pretrained(
        tmp_path / "run" / "checkpoints" / "last" / "pretrained_model"
    )
    assert loaded.config.reward == reward
    for name, value in loaded.reward_model.state_dict().items():
        torch.testing.assert_close(value, model_state[name])

    from benchmarks.probes import learned_reward as probe

    cfg = probe.LearnedRewardProbeConfig(
        run_dirs=[tmp_path / "run"], last_cycles=1, pairs=12, out=tmp_path / "p.json"
    )
    (run,) = probe.run(cfg)["runs"].values()
    assert run["reward"] == reward and list(run["steps"]) == [6]
    assert run["steps"][6]["on_policy"]["episodes"] == 1
    assert json.loads((tmp_path / "p.json").read_text())["runs"][str(tmp_path / "run")]["reward"] == reward


def test_every_method_arm_has_a_label_a_style_and_valid_policy_flags():
    import draccus

    from benchmarks.experiments.presets import LABELS, METHODS, STYLES
    from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig

    assert set(METHODS) == set(LABELS) == set(STYLES)
    assert METHODS["ae"] == [
        "--policy.preset=paper",
        "--policy.reward=ae",
        "--policy.balance=false",
        "--policy.filter=false",
    ]
    for name, flags in METHODS.items():
        args = [f.replace("--policy.", "--", 1) for f in flags]
        cfg = draccus.parse(IndicatorDDPGConfig, args=args)
        learned = name.split("_")[0]
        expected = (
            "oracle" if name.startswith("oracle") else learned if learned in ("ae", "vae") else "indicator"
        )
        assert cfg.reward == expected, name


def _probe_episodes(n_ep: int, size: int = 8) -> dict:
    """Episodes whose every pixel is the ground-truth x of the frame (and of the goal), y = 0."""
    from lerobot_indicator.training.run_state import CHUNK_GT_ACHIEVED, CHUNK_GT_DESIRED

    rng = np.random.default_rng(0)
    x, gx = rng.integers(0, 9, size=(n_ep, 4)) / 8, rng.integers(0, 9, size=n_ep) / 8

    def image(v: np.ndarray, channels: int) -> np.ndarray:
        return np.broadcast_to(v[..., None, None, None], (*v.shape, channels, size, size)).astype(np.float32)

    return {
        f"obs/{RGB}": image(x, 3), f"obs/{DEPTH}": image(x, 1),
        f"obs/{goal_key(RGB)}": image(gx[:, None], 3), f"obs/{goal_key(DEPTH)}": image(gx[:, None], 1),
        CHUNK_GT_ACHIEVED: np.stack([x, 0 * x], -1), CHUNK_GT_DESIRED: np.stack([gx, 0 * gx], -1),
    }  # fmt: skip


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_learned_reward_probe_ranks_a_reward_against_ground_truth_distance(sign):
    """A reward equal to minus the ground-truth distance ranks it perfectly (Spearman 1, AUC 1, on-policy
    reward = -distance); the same reward with the sign flipped ranks it exactly backwards."""
    from benchmarks.probes import learned_reward as probe

    policy, _ = policy_and_batch("ae")

    def reward(frames: dict, goal: dict) -> torch.Tensor:
        return -sign * (frames[RGB].mean(dim=(1, 2, 3)) - goal[RGB].mean(dim=(1, 2, 3))).abs()

    policy.reward_model.reward = reward
    episodes = _probe_episodes(n_ep=40)
    cfg = probe.LearnedRewardProbeConfig(last_cycles=5, pairs=300, batch_size=64)
    record = probe.probe(policy, episodes, cfg, episodes_per_cycle=4)

    on, pairs = record["on_policy"], record["pairs"]
    gt, goal = episodes["gt_achieved"][20:, :, 0], episodes["gt_desired"][20:, None, 0]
    assert on["episodes"] == 20
    assert on["distance_start"] == pytest.approx(np.abs(gt[:, 0] - goal[:, 0]).mean())
    assert on["distance_final"] == pytest.approx(np.abs(gt[:, -1] - goal[:, 0]).mean())
    assert on["reward_final"] == pytest.approx(-sign * on["distance_final"])
    assert on["spearman_final"] == pytest.approx(sign)
    assert pairs["spearman"] == pytest.approx(sign)
    same = pairs["same_episode"]
    assert 0 < same["success_share"] < 1 and same["reward_auc"] == pytest.approx((1 + sign) / 2)
