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
from lerobot_indicator.training.online import add_replay_chunk, to_transition_batch
from lerobot_indicator.training.replay_buffer import EpisodeReplayBuffer


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
