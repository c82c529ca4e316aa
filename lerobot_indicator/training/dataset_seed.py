"""Seed the online replay buffer from a recorded LeRobotDataset (offline data, then online rollouts).

An episode of horizon T is recorded as T + 1 frames ``o_0..o_T`` (the last frame's action is unused),
so it gives the buffer all T transitions. Frames come back from ``LeRobotDataset`` in the same policy
layout that rollouts store (float RGB in [0, 1], depth in the dataset's unit), which the buffer packs
losslessly again.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator

import numpy as np
import torch
from lerobot.configs.default import DatasetConfig
from lerobot.datasets import LeRobotDataset
from tqdm import tqdm

from lerobot_indicator.data.integrity import check_before_loading, check_dataset, read_frame
from lerobot_indicator.finite import check_episode
from lerobot_indicator.keys import (
    GT_ACHIEVED_GOAL,
    GT_DESIRED_GOAL,
    OBS_GT_ACHIEVED_GOAL,
    OBS_GT_DESIRED_GOAL,
    is_goal_key,
    observation_key,
)
from lerobot_indicator.training.replay_buffer import EpisodeReplayBuffer


def load_dataset(cfg: DatasetConfig) -> LeRobotDataset:
    """The dataset, checked (data/integrity.py: info.json, shapes, content hashes) before LeRobot reads it,
    or right after LeRobot downloads it."""
    checked = check_before_loading(cfg.repo_id, cfg.root, cfg.episodes)
    dataset = LeRobotDataset(
        cfg.repo_id,
        root=cfg.root,
        episodes=cfg.episodes,
        revision=cfg.revision,
        video_backend=cfg.video_backend,
        depth_output_unit=cfg.depth_output_unit,
    )
    if not checked:
        check_dataset(dataset.root, cfg.episodes)
    return dataset


def dataset_episodes(dataset: LeRobotDataset, keys: list[str], horizon: int) -> Iterator[tuple]:
    """Yield ``(observations, actions, ground_truth | None)`` per episode, as the buffer takes them.

    A goal key the dataset lacks (data without goal columns) is the episode's last frame of its observation
    key: relabeling draws every other goal from the episode's own later frames."""
    substituted = [
        g
        for g in keys
        if is_goal_key(g) and g not in dataset.features and observation_key(g) in dataset.features
    ]
    if substituted:
        logging.info(
            "dataset %s has no goal columns %s: the buffer's recorded goal of each episode is its last frame; "
            "relabeling draws every other goal from the episode's later frames",
            dataset.repo_id,
            substituted,
        )
    missing = [k for k in keys if k not in dataset.features and k not in substituted]
    if missing:
        raise KeyError(
            f"dataset {dataset.repo_id} lacks the policy's keys {missing}; it has {sorted(dataset.features)}"
        )
    has_gt = OBS_GT_ACHIEVED_GOAL in dataset.features and OBS_GT_DESIRED_GOAL in dataset.features
    # As arrow: the column alone (indexing the torch-formatted dataset decodes every image of every row).
    episode_index = np.asarray(dataset.hf_dataset.with_format("arrow")["episode_index"])
    for ep in np.unique(episode_index):
        rows = np.flatnonzero(episode_index == ep)
        if len(rows) != horizon + 1:
            raise ValueError(
                f"episode {ep} of {dataset.repo_id} has {len(rows)} frames; the env's horizon T={horizon} "
                f"needs T + 1 = {horizon + 1} (o_0..o_T, as scripts/record.py writes them)"
            )
        frames = [read_frame(dataset, int(i)) for i in rows]

        def stack(key: str, frames=frames) -> np.ndarray:
            return torch.stack([f[key] for f in frames]).float().numpy()

        obs = {k: stack(k) for k in keys if k not in substituted}
        obs |= {g: obs[observation_key(g)][-1:] for g in substituted}
        check_episode({**obs, "action": stack("action")}, int(ep), f"dataset {dataset.repo_id}")
        gt = None
        if has_gt:
            gt = {
                GT_ACHIEVED_GOAL: stack(OBS_GT_ACHIEVED_GOAL),
                GT_DESIRED_GOAL: stack(OBS_GT_DESIRED_GOAL)[0],
            }
        yield obs, stack("action")[:horizon], gt


def seed_buffer(buffer: EpisodeReplayBuffer, cfg: DatasetConfig, keys: list[str]) -> int:
    """Add every episode of the dataset to ``buffer``; returns the number of episodes added."""
    dataset = load_dataset(cfg)
    n = 0
    for episode in tqdm(
        dataset_episodes(dataset, keys, buffer.horizon), desc="seeding buffer", unit="episode"
    ):
        buffer.add_episode(*episode)
        n += 1
    logging.info("seeded the replay buffer with %d episodes of %s", n, cfg.repo_id)
    return n
