"""How fast the critic fits from images vs from the ground-truth state, on one fixed replay buffer.

A diagnostic for the visual path: it replays the episode chunks an online run saved (``<run>/replay``),
and trains a fresh policy on them offline with the oracle reward (so the rewards are the same for both
inputs) and HER-style relabeling. ``inputs="state"`` swaps the images for the episodes' ground-truth
end-effector positions (``gt_achieved`` as the observation, ``gt_desired`` as the goal): the same transitions,
the same reward, only the critic's input differs. Ground truth is used here to *measure*, never to train a
policy of the product.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from benchmarks.speed.updates import STATE_FEATURES, make_policy, rgbd_features
from lerobot_indicator.keys import goal_key
from lerobot_indicator.training.batches import to_transition_batch
from lerobot_indicator.training.replay_buffer import EpisodeReplayBuffer
from lerobot_indicator.training.run_state import (
    CHUNK_ACTIONS,
    CHUNK_GT_ACHIEVED,
    CHUNK_GT_DESIRED,
    REPLAY_DIR,
    add_replay_chunk,
)


def load_chunks(run_dir: Path, horizon: int, inputs: str, max_chunks: int) -> EpisodeReplayBuffer:
    files = sorted((run_dir / REPLAY_DIR).glob("cycle_*.npz"))[:max_chunks]
    if not files:
        raise FileNotFoundError(f"{run_dir}/{REPLAY_DIR} has no cycle_*.npz episode chunks")
    buffer = EpisodeReplayBuffer(10**6, horizon)
    for path in files:
        with np.load(path) as z:
            chunk = dict(z)
        if inputs == "state":
            goal = np.repeat(chunk[CHUNK_GT_DESIRED][:, None], chunk[CHUNK_GT_ACHIEVED].shape[1], axis=1)
            chunk = {
                "obs/observation.state": chunk[CHUNK_GT_ACHIEVED],
                "obs/observation.goal_state": goal,
                **{k: chunk[k] for k in (CHUNK_ACTIONS, CHUNK_GT_ACHIEVED, CHUNK_GT_DESIRED)},
            }
        add_replay_chunk(buffer, chunk)
    return buffer


def fit_critic(
    run_dir: Path, inputs: str, updates: int, image_size: int, horizon: int = 25, batch_size: int = 128,
    max_chunks: int = 60, every: int = 250, seed: int = 0, **config: object,
) -> dict:  # fmt: skip
    """Critic loss (mean over each ``every`` updates) of a policy trained offline on ``run_dir``'s replay."""
    buffer = load_chunks(run_dir, horizon, inputs, max_chunks)
    features = STATE_FEATURES if inputs == "state" else rgbd_features(image_size)
    torch.manual_seed(seed)
    cfg = {"reward": "oracle", "oracle_epsilon": 0.05, "balance": False, "filter": False, "horizon": horizon}
    policy = make_policy(features, **{**cfg, **config})
    policy.set_observation_stats(buffer.observation_stats())
    optimizer = policy.config.get_optimizer_preset().build(policy.get_optim_params())
    rng, generator = np.random.default_rng(seed), torch.Generator().manual_seed(seed)
    keys, losses, curve, start = policy.config.observation_keys, [], [], time.perf_counter()
    for step in range(1, updates + 1):
        sample = buffer.sample(batch_size, rng, packed=True, n_step=policy.config.n_step)
        loss, stats = policy.forward(to_transition_batch(sample, keys, horizon, "cpu"), generator=generator)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        policy.update()
        losses.append(stats["critic_loss"])
        if step % every == 0:
            curve.append(
                {"updates": step, "critic_loss": float(np.mean(losses[-every:])), "q_mean": stats["q_mean"]}
            )
    return {
        "inputs": inputs,
        "config": {k: v for k, v in config.items()},
        "episodes": buffer.num_episodes,
        "curve": curve,
        "wall_s": time.perf_counter() - start,
    }


def localization_probe(
    run_dir: Path, updates: int, image_size: int, horizon: int = 25, batch_size: int = 128, max_chunks: int = 60,
    every: int = 500, seed: int = 0, **config: object,
) -> dict:  # fmt: skip
    """The same encoder trained *supervised* to predict the end-effector position (ground truth) from one
    frame: what the image pipeline can represent, as a bound for what the critic could learn from it."""
    buffer = load_chunks(run_dir, horizon, "rgbd", max_chunks)
    torch.manual_seed(seed)
    encoder = make_policy(rgbd_features(image_size), **config).critic.encoder
    encoder.set_stats(buffer.observation_stats())
    keys = [k for k in buffer.obs if k in encoder.image_keys]
    n = buffer.num_episodes
    frames = {k: buffer.obs[k].data[:n].reshape(-1, *buffer.obs[k].data.shape[2:]) for k in keys}
    target = torch.from_numpy(buffer.gt_achieved[:n].reshape(-1, buffer.gt_achieved.shape[-1]))
    perm = torch.randperm(len(target), generator=torch.Generator().manual_seed(seed))
    n_test = min(500, len(target) // 5)
    test, train = perm[:n_test], perm[n_test:]
    mean, std = target[train].mean(0), target[train].std(0)
    head = torch.nn.Linear(encoder.out_dim, target.shape[1])
    optimizer = torch.optim.Adam([*encoder.parameters(), *head.parameters()], lr=1e-3)

    def predict(rows: torch.Tensor) -> torch.Tensor:
        obs = {k: torch.from_numpy(v[rows.numpy()]) for k, v in frames.items()}
        obs = {k: v.float() if v.dtype == torch.uint16 else v for k, v in obs.items()}
        return head(encoder(obs)) * std + mean

    curve = []
    for step in range(1, updates + 1):
        rows = train[torch.randint(0, len(train), (batch_size,))]
        loss = (((predict(rows) - target[rows]) / std) ** 2).mean()
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        if step % every == 0:
            with torch.no_grad():
                err = torch.linalg.vector_norm(predict(test) - target[test], dim=1)
            curve.append(
                {
                    "updates": step,
                    "test_error_mean_m": float(err.mean()),
                    "test_error_median_m": float(err.median()),
                }
            )
    return {"frames": len(target), "curve": curve}


def feature_probe(run_dir: Path, horizon: int = 25, max_chunks: int = 30, test_fraction: float = 0.2) -> dict:
    """How well a trained run's own encoder features locate the end effector: a ridge regression (linear, ground
    truth as the target, for *measurement* only) from the features of its last ``max_chunks`` replay chunks to
    ``gt_achieved``, tested on held-out episodes, and applied unchanged to the goal frames (``gt_desired``).

    Separates "the features do not hold the position" from "the critic does not use them": an encoder
    trained only by the critic loss holds what that loss needed.
    """
    from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

    policy = IndicatorDDPGPolicy.from_pretrained(str(run_dir / "checkpoints" / "last" / "pretrained_model"))
    encoder = policy.critic.encoder.eval()
    files = sorted((run_dir / "replay").glob("cycle_*.npz"))[-max_chunks:]
    if not files:
        raise FileNotFoundError(f"{run_dir}/replay has no cycle_*.npz episode chunks")
    buffer = EpisodeReplayBuffer(10**6, horizon)
    for path in files:
        with np.load(path) as z:
            add_replay_chunk(buffer, dict(z))
    n = buffer.num_episodes
    keys = encoder.image_keys

    def features(frames: dict[str, np.ndarray]) -> np.ndarray:
        obs = {k: torch.from_numpy(v) for k, v in frames.items()}
        obs = {k: v.float() if v.dtype == torch.uint16 else v for k, v in obs.items()}
        with torch.no_grad():
            return encoder(obs).double().numpy()

    obs = {k: buffer.obs[k].data[:n].reshape(-1, *buffer.obs[k].data.shape[2:]) for k in keys}
    goal = {k: buffer.goals[goal_key(k)].data[:n] for k in keys}
    x, y = features(obs), buffer.gt_achieved[:n].reshape(-1, buffer.gt_achieved.shape[-1]).astype(np.float64)
    xg, yg = features(goal), buffer.gt_desired[:n].astype(np.float64)
    frames_per_episode = buffer.obs[keys[0]].data.shape[1]
    split = frames_per_episode * max(1, int(round(n * (1 - test_fraction))))

    def fit(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        a = np.c_[a, np.ones(len(a))]
        return np.linalg.solve(a.T @ a + 1e-3 * np.eye(a.shape[1]), a.T @ b)

    def errors(w: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.linalg.norm(np.c_[a, np.ones(len(a))] @ w - b, axis=1)

    w = fit(x[:split], y[:split])
    test_err, goal_err = errors(w, x[split:], y[split:]), errors(fit(x, y), xg, yg)
    return {
        "episodes": n,
        "feature_dim": int(x.shape[1]),
        "ee_error_mean_m": float(test_err.mean()),
        "ee_error_median_m": float(np.median(test_err)),
        "goal_error_mean_m": float(goal_err.mean()),
        "ee_spread_m": float(np.linalg.norm(y[split:] - y[:split].mean(0), axis=1).mean()),
    }
