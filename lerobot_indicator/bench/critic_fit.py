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

from lerobot_indicator.bench.updates import STATE_FEATURES, make_policy, rgbd_features
from lerobot_indicator.training.online import add_replay_chunk
from lerobot_indicator.training.replay_buffer import EpisodeReplayBuffer
from lerobot_indicator.training.transition_batch import to_transition_batch


def load_chunks(run_dir: Path, horizon: int, inputs: str, max_chunks: int) -> EpisodeReplayBuffer:
    files = sorted((run_dir / "replay").glob("cycle_*.npz"))[:max_chunks]
    if not files:
        raise FileNotFoundError(f"{run_dir}/replay has no cycle_*.npz episode chunks")
    buffer = EpisodeReplayBuffer(10**6, horizon)
    for path in files:
        with np.load(path) as z:
            chunk = dict(z)
        if inputs == "state":
            goal = np.repeat(chunk["gt_desired"][:, None], chunk["gt_achieved"].shape[1], axis=1)
            chunk = {
                "obs/observation.state": chunk["gt_achieved"],
                "obs/observation.goal_state": goal,
                **{k: chunk[k] for k in ("actions", "gt_achieved", "gt_desired")},
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
        sample = buffer.sample(batch_size, rng, packed=True)
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
