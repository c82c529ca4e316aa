"""Context inputs (``--policy.context_keys``): state keys the actor and critic see beside the compared ones, never
compared, never relabeled, never part of a goal or of the reward; o_t's context goes with o_t and o_{t+1}'s
with the frame the TD target bootstraps from."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from lerobot.configs import FeatureType, PolicyFeature
from test_encode_paths import gradients, image_transition_batch
from test_learning_math_pixels import B, image_policy

from lerobot_indicator.keys import goal_key
from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy.configuration_indicator_ddpg import (
    IndicatorDDPGConfig,
    IndicatorDDPGConfigError,
)
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy
from lerobot_indicator.training.batches import to_transition_batch
from lerobot_indicator.training.replay_buffer import EpisodeReplayBuffer
from lerobot_indicator.training.rollout import stored_keys

STATE, GOAL = "observation.state", "observation.goal_state"
CTX = "observation.environment_state"
RGB, GOAL_RGB = "observation.images.front", "observation.images.goal_front"
GT = "observation.gt_achieved_goal"
S, K, A = 3, 5, 2  # compared state, context and action sizes


def vec(n: int, kind: FeatureType = FeatureType.STATE) -> PolicyFeature:
    return PolicyFeature(kind, (n,))


def state_features() -> dict[str, PolicyFeature]:
    return {STATE: vec(S), GOAL: vec(S), CTX: vec(K, FeatureType.ENV), GT: vec(S)}


def make_config(inputs: dict | None = None, **kwargs) -> IndicatorDDPGConfig:
    defaults = {"hidden_dims": [16, 16], "horizon": 6, "observation_keys": [STATE]}
    cfg = IndicatorDDPGConfig(device="cpu", **{**defaults, **kwargs})
    cfg.input_features = dict(state_features() if inputs is None else inputs)
    cfg.output_features = {"action": PolicyFeature(FeatureType.ACTION, (A,))}
    return cfg


def make_policy(**kwargs) -> IndicatorDDPGPolicy:
    torch.manual_seed(0)
    policy = IndicatorDDPGPolicy(make_config(**{"context_keys": [CTX], **kwargs}))
    # Stats that move the context: a context term ignored by the networks cannot pass for a constant one.
    policy.set_observation_stats({CTX: {"mean": torch.full((K,), 0.5), "std": torch.full((K,), 2.0)}})
    return policy


def randn(*shape: int, seed: int) -> torch.Tensor:
    return torch.randn(*shape, generator=torch.Generator().manual_seed(seed))


def transition_batch(seed: int = 0, n: int = 8) -> dict[str, torch.Tensor]:
    """o_t, o_{t+1}, a future frame and a recorded goal; rows 0-3's recorded goal is their o_{t+1} (R+)."""
    nxt = randn(n, S, seed=seed + 1)
    goal = randn(n, S, seed=seed + 3)
    goal[:4] = nxt[:4]
    return {
        STATE: randn(n, S, seed=seed),
        core.NEXT + STATE: nxt,
        core.FUTURE + STATE: randn(n, S, seed=seed + 2),
        GOAL: goal,
        CTX: randn(n, K, seed=seed + 4),
        core.NEXT + CTX: randn(n, K, seed=seed + 5),
        "action": torch.rand(n, A, generator=torch.Generator().manual_seed(seed + 6)) * 2 - 1,
        core.HAS_FUTURE: torch.ones(n, dtype=torch.bool),
    }


def loss(policy: IndicatorDDPGPolicy, batch: dict, encode_once: bool = True) -> tuple[torch.Tensor, dict]:
    torch.manual_seed(5)
    return core.indicator_ddpg_loss(
        batch, policy.actor, policy.critic, policy.target_actor, policy.target_critic, policy.config,
        torch.Generator().manual_seed(0), encode_once=encode_once,
    )  # fmt: skip


# ------------------------------------------------------------------------------------------------ config


@pytest.mark.parametrize(
    ("context", "inputs", "message"),
    [
        ([GT], None, "context_keys: 'observation.gt_achieved_goal' is a ground-truth key"),
        ([GOAL], None, "context_keys: 'observation.goal_state' is a goal key"),
        ([STATE], None, "context_keys: 'observation.state' is also in observation_keys"),
        ([CTX, CTX], None, "context_keys: 'observation.environment_state' is listed twice"),
        (["action"], None, "'action' is not an observation key"),
        (["observation.velocity"], None, "context key 'observation.velocity' is missing from the input"),
        (
            [RGB],
            {**state_features(), RGB: PolicyFeature(FeatureType.VISUAL, (3, 8, 8))},
            "context key 'observation.images.front' is an image",
        ),
    ],
)
def test_bad_context_keys_are_refused_in_one_line(context, inputs, message):
    with pytest.raises((ValueError, IndicatorDDPGConfigError)) as err:
        make_config(inputs, context_keys=context).validate_features()
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_default_compared_key_named_as_context_is_refused():
    with pytest.raises(ValueError, match="'observation.state' is also in observation_keys"):
        make_config(observation_keys=None, context_keys=[STATE]).validate_features()


def test_default_context_is_the_goal_less_state_keys_unless_an_image_is_compared():
    cfg = make_config(observation_keys=None)
    cfg.validate_features()
    assert cfg.observation_keys == [STATE] and cfg.context_keys == [CTX]
    assert sorted(cfg.input_features) == sorted([STATE, GOAL, CTX])  # never ground truth
    visual = {**state_features(), RGB: PolicyFeature(FeatureType.VISUAL, (3, 8, 8))}
    visual[GOAL_RGB] = visual[RGB]
    images = make_config(visual, observation_keys=None)
    images.validate_features()
    assert images.observation_keys == [RGB] and images.context_keys == []
    # A state that has a goal can still be context instead of compared.
    named = make_config(visual, observation_keys=[RGB], context_keys=[STATE])
    named.validate_features()
    assert sorted(named.input_features) == sorted([RGB, GOAL_RGB, STATE])
    none = make_config(context_keys=[])
    none.validate_features()
    assert none.context_keys == [] and sorted(none.input_features) == [GOAL, STATE]


# ------------------------------------------------------------------------------------ networks and acting


def test_context_changes_the_action_and_q_and_a_missing_context_is_named():
    policy = make_policy()
    obs = {STATE: randn(4, S, seed=1), GOAL: randn(4, S, seed=2), CTX: randn(4, K, seed=3)}
    action = policy.select_action(obs)
    other = policy.select_action({**obs, CTX: obs[CTX] + 1.0})
    assert (action - other).abs().min() > 0, "every row's action must depend on its context"
    goal = {STATE: obs[GOAL]}
    q = policy.critic({STATE: obs[STATE], CTX: obs[CTX]}, goal, action)
    q_other = policy.critic({STATE: obs[STATE], CTX: obs[CTX] + 1.0}, goal, action)
    assert (q - q_other).abs().min() > 0
    assert policy.actor.net[0].in_features == 2 * S + K
    assert policy.critic.net[0].in_features == 2 * S + K + A
    with pytest.raises(KeyError, match="observation.environment_state"):
        policy.select_action({STATE: obs[STATE], GOAL: obs[GOAL]})


def test_context_is_normalised_with_its_own_statistics():
    policy = make_policy()
    encoder = policy.actor.encoder
    x = randn(4, K, seed=7)
    (features,) = encoder.context({CTX: x})
    torch.testing.assert_close(features, ((x - 0.5) / 2.0).clamp(-5, 5))
    assert torch.equal(policy.target_critic.encoder.stats()[CTX]["std"], torch.full((K,), 2.0))


def test_without_context_the_networks_ignore_extra_keys():
    torch.manual_seed(0)
    policy = IndicatorDDPGPolicy(make_config(context_keys=[]))
    obs = {STATE: randn(4, S, seed=1), GOAL: randn(4, S, seed=2), CTX: randn(4, K, seed=3)}
    assert torch.equal(policy.select_action(obs), policy.select_action({**obs, CTX: obs[CTX] + 1.0}))
    assert "actor.encoder.mean_1" not in policy.state_dict()  # no context buffers: older checkpoints load


# ------------------------------------------------------------------------- reward, relabeling and targets


def test_reward_and_relabeling_are_the_same_whatever_the_context(monkeypatch):
    """The indicator reward never sees the context (it is in no goal), relabeling draws the same goals, and o_t's
    context does not move the TD target while o_{t+1}'s does (it goes with the bootstrap frame)."""
    seen = []
    reward_fn = core.indicator_reward

    def spy(next_obs, goal, r_pos, r_neg):
        reward = reward_fn(next_obs, goal, r_pos, r_neg)
        seen.append((sorted(goal), reward))
        return reward

    monkeypatch.setattr(core, "indicator_reward", spy)
    policy = make_policy(filter=False)
    batch = transition_batch()
    before = {k: v.clone() for k, v in batch.items()}
    _, stats = loss(policy, batch)
    other_obs_context = {**batch, CTX: batch[CTX] * -3.0 + 1.0}
    _, stats_obs = loss(policy, other_obs_context)
    other_next_context = {**batch, core.NEXT + CTX: batch[core.NEXT + CTX] * -3.0 + 1.0}
    _, stats_next = loss(policy, other_next_context)
    assert all(keys == [STATE] for keys, _ in seen), "a goal holds the compared keys only"
    rewards = [r for _, r in seen]
    assert (rewards[0] == 1).any() and (rewards[0] == -1).any()  # both outcomes occur
    assert all(torch.equal(r, rewards[0]) for r in rewards)
    for name in ("frac_positive", "frac_goal_next", "frac_goal_future", "frac_goal_recorded"):
        assert stats[name] == stats_obs[name] == stats_next[name], name
    assert stats["q_target_mean"] == stats_obs["q_target_mean"]  # o_t's context: not in the target
    assert stats["q_mean"] != stats_obs["q_mean"]  # ... but in Q(o_t, g, a_t)
    assert stats["q_target_mean"] != stats_next["q_target_mean"]  # o_{t+1}'s context: in the target
    assert stats["q_mean"] == stats_next["q_mean"]
    assert all(torch.equal(batch[k], before[k]) for k in batch)


def test_select_goals_never_returns_context():
    cfg = make_config(context_keys=[CTX])
    cfg.validate_features()
    batch = transition_batch()
    for source in (core.SOURCE_NEXT, core.SOURCE_FUTURE, core.SOURCE_RECORDED):
        goal = core.select_goals(batch, cfg.observation_keys, torch.full((8,), source))
        assert list(goal) == [STATE]


def test_n_step_targets_bootstrap_from_the_path_frames_context():
    policy = make_policy(filter=False, n_step=2)
    batch = transition_batch()
    batch[core.PATH + STATE] = randn(8, 1, S, seed=20)
    batch[core.PATH + CTX] = randn(8, 1, K, seed=21)
    batch[core.PATH_VALID] = torch.ones(8, 1, dtype=torch.bool)
    _, stats = loss(policy, batch)
    _, stats_next = loss(policy, {**batch, core.NEXT + CTX: batch[core.NEXT + CTX] + 1.0})
    _, stats_path = loss(policy, {**batch, core.PATH + CTX: batch[core.PATH + CTX] + 1.0})
    assert stats["q_target_mean"] == stats_next["q_target_mean"]  # o_{t+1} is not the bootstrap frame here
    assert stats["q_target_mean"] != stats_path["q_target_mean"]


ONE_STEP = {"n_step": 1, "inverse_dynamics": 0.0}
IMAGE_CONFIGS = {
    "drq": ONE_STEP,
    "drq, target encoder, target filter": {**ONE_STEP, "target_encoder": True, "filter_q": "target"},
    "drq, 2-step, inverse dynamics": {"n_step": 2, "inverse_dynamics": 1.0},
    "paper, target filter": {**ONE_STEP, "image_encoder": "paper", "filter_q": "target"},
}


@pytest.mark.parametrize("config", IMAGE_CONFIGS.values(), ids=IMAGE_CONFIGS.keys())
def test_both_encode_paths_agree_with_image_compared_and_state_context(config, monkeypatch):
    """With an image compared and a state context, the encode-once and the plain path give the same loss,
    statistics and gradients, and the context reaches the critic's gradient."""
    ctx_feature = PolicyFeature(FeatureType.STATE, (K,))
    original = IndicatorDDPGPolicy.__init__

    def with_context(self, cfg, *args, **kwargs):
        cfg.input_features = {**cfg.input_features, CTX: ctx_feature}
        cfg.context_keys = [CTX]
        original(self, cfg, *args, **kwargs)

    monkeypatch.setattr(IndicatorDDPGPolicy, "__init__", with_context)
    policy = image_policy(**config)
    assert policy.config.context_keys == [CTX] and policy.critic.encoder.context_dim == K
    batch = image_transition_batch(policy.config.n_step)
    batch[CTX] = randn(B, K, seed=30).requires_grad_(True)
    batch[core.NEXT + CTX] = randn(B, K, seed=31)
    if policy.config.n_step == 2:
        batch[core.PATH + CTX] = randn(B, 1, K, seed=32)
    fast_loss, fast_stats = loss(policy, batch, encode_once=True)
    plain_loss, plain_stats = loss(policy, batch, encode_once=False)
    torch.testing.assert_close(fast_loss, plain_loss, rtol=1e-5, atol=1e-6)
    for name in plain_stats:
        torch.testing.assert_close(fast_stats[name], plain_stats[name], rtol=1e-5, atol=1e-6, msg=name)
    (context_grad,) = torch.autograd.grad(plain_loss, batch[CTX], retain_graph=True)
    assert context_grad.abs().sum() > 0
    fast_grads, plain_grads = gradients(fast_loss, policy), gradients(plain_loss, policy)
    for name in plain_grads:
        torch.testing.assert_close(fast_grads[name], plain_grads[name], rtol=1e-5, atol=1e-6, msg=name)


# --------------------------------------------------------------------------- buffers and dataset batches


def test_replay_batches_carry_context_with_o_t_o_next_and_the_path_never_the_future():
    T, n = 6, 64
    buffer = EpisodeReplayBuffer(10 * T, T)
    steps = np.arange(T + 1, dtype=np.float32)
    for episode in range(3):
        context = np.stack([steps + 100 * episode] * K, axis=1) + 0.25  # o_t's context encodes (episode, t)
        state = np.stack([steps * 0.5 + episode] * S, axis=1)
        goal = np.full((1, S), 9.0, np.float32)
        buffer.add_episode({STATE: state, GOAL: goal, CTX: context}, np.zeros((T, A), np.float32))
    assert buffer.keys == sorted(stored_keys([STATE], [CTX]))
    assert CTX in buffer.observation_stats()
    sample = buffer.sample(n, np.random.default_rng(0), packed=True, n_step=3)
    batch = to_transition_batch(sample, [STATE], T, "cpu", context_keys=[CTX])
    ep, t = torch.from_numpy(sample["episode"]), torch.from_numpy(sample["t"])
    expected = (t + 100 * ep).float() + 0.25
    torch.testing.assert_close(batch[CTX][:, 0], expected)
    torch.testing.assert_close(batch[core.NEXT + CTX][:, 0], expected + 1)
    path_t = torch.minimum(t[:, None] + torch.arange(2, 4), torch.tensor(T))
    torch.testing.assert_close(batch[core.PATH + CTX][..., 0], (path_t + 100 * ep[:, None]).float() + 0.25)
    assert core.FUTURE + CTX not in batch and goal_key(CTX) not in batch


def test_lerobot_train_batches_carry_context_of_o_t_and_o_next():
    cfg = make_config(context_keys=[CTX], future_offsets=[2, 3])
    cfg.validate_features()
    n, frames = 4, 2 + 2
    ctx = torch.arange(n * frames * K, dtype=torch.float32).view(n, frames, K)
    batch = {
        STATE: randn(n, frames, S, seed=1),
        GOAL: randn(n, frames, S, seed=2),
        CTX: ctx,
        "action": torch.zeros(n, A),
    }
    out = core.dataset_batch_to_transitions(batch, cfg, torch.Generator().manual_seed(0))
    assert torch.equal(out[CTX], ctx[:, 0]) and torch.equal(out[core.NEXT + CTX], ctx[:, 1])
    assert core.FUTURE + CTX not in out


def test_checkpoint_keeps_the_context_keys_and_the_action(tmp_path):
    policy = make_policy()
    policy.save_pretrained(tmp_path)
    assert json.loads((tmp_path / "config.json").read_text())["context_keys"] == [CTX]
    loaded = IndicatorDDPGPolicy.from_pretrained(tmp_path)
    obs = {STATE: randn(2, S, seed=1), GOAL: randn(2, S, seed=2), CTX: randn(2, K, seed=3)}
    assert torch.equal(loaded.select_action(obs), policy.select_action(obs))


# ------------------------------------------------------------------------------------------ end to end

CONFIG_DIR = Path(__file__).resolve().parents[1] / "env_configs"

TINY = [
    "--policy.type=indicator_ddpg",
    "--policy.push_to_hub=false",
    "--policy.device=cpu",
    "--policy.hidden_dims=[16,16]",
    "--online.n_envs=1",
    "--online.use_async_envs=false",
    "--online.episodes_per_cycle=1",
    "--online.updates_per_cycle=3",
    "--online.batch_size=8",
    "--online.eval_episodes=1",
    "--env.episode_length=4",
    "--steps=3",
    "--env_eval_freq=3",
    "--save_freq=3",
    "--seed=1",
]


@pytest.mark.parametrize(
    ("env_args", "env_state_dim"),
    [
        (["--env.type=fetch_reach", "--env.obs_type=state"], 10),
        ([f"--config_path={CONFIG_DIR / 'fetch_push_state_sim.yaml'}"], 25),
    ],
    ids=["fetch_reach_state", "fetch_push_yaml"],
)
def test_online_training_on_fetch_state_conditions_on_the_environment_state(
    tmp_path, env_args, env_state_dim
):
    """With no key flags the Fetch state tasks (FetchPush from its env_configs file) compare
    ``observation.state`` and condition on ``observation.environment_state``; the checkpoint holds its
    normalisation and a context-wide MLP."""
    pytest.importorskip("gymnasium_robotics")
    from safetensors.torch import load_file

    out = tmp_path / "run"
    cmd = [
        str(Path(sys.executable).parent / "lerobot-indicator-train"),
        *TINY,
        *env_args,
        f"--output_dir={out}",
    ]
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]
    pretrained = out / "checkpoints" / "last" / "pretrained_model"
    config = json.loads((pretrained / "config.json").read_text())
    assert config["observation_keys"] == [STATE] and config["context_keys"] == [CTX]
    weights = load_file(pretrained / "model.safetensors")
    assert weights["actor.encoder.mean_1"].shape == (env_state_dim,)
    assert weights["actor.encoder.std_1"].min() > 0
    assert weights["actor.net.0.weight"].shape[1] == 2 * 3 + env_state_dim


def test_lerobot_train_on_a_recorded_fetch_push_dataset_conditions_on_the_environment_state(tmp_path):
    """The offline path: a recorded FetchPush (state) dataset trains with lerobot-train, whose batches reach the
    learning core through ``dataset_batch_to_transitions``, with the environment state as context."""
    pytest.importorskip("gymnasium_robotics")
    from lerobot_indicator.data.recorder import RecordConfig, record
    from lerobot_indicator.envs.configs import FetchPushEnvConfig

    root, repo_id = tmp_path / "data", "local/tiny_fetch_push"
    record(
        RecordConfig(
            env=FetchPushEnvConfig(episode_length=5), repo_id=repo_id, root=root, policy="random",
            num_episodes=2, image_writer_threads=0,
        )
    )  # fmt: skip
    out = tmp_path / "run"
    cmd = [
        str(Path(sys.executable).parent / "lerobot-train"), "--policy.type=indicator_ddpg",
        f"--dataset.repo_id={repo_id}", f"--dataset.root={root}", "--policy.push_to_hub=false",
        "--policy.device=cpu", "--policy.future_offsets=[2,3]", "--policy.hidden_dims=[16,16]",
        "--batch_size=4", "--num_workers=0", "--steps=2", "--save_freq=2", "--wandb.enable=false",
        f"--output_dir={out}",
    ]  # fmt: skip
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "CUDA_VISIBLE_DEVICES": ""}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-6000:]
    config = json.loads((out / "checkpoints" / "000002" / "pretrained_model" / "config.json").read_text())
    assert config["observation_keys"] == [STATE] and config["context_keys"] == [CTX]
