"""``--record.*``: the online trainer's behaviour-policy episodes as a LeRobotDataset.

Written in the format of ``lerobot_indicator.data.recorder`` (docs/dataset_format.md, lossless images) and
checkpointed every ``--record.checkpoint_every_s``; a killed run's dataset rolls back to its last checkpoint.
"""

from __future__ import annotations

import math
import time

import gymnasium as gym
from lerobot.datasets import LeRobotDataset

from lerobot_indicator.data.checkpoint import clear_checkpoint, write_checkpoint
from lerobot_indicator.data.features import dataset_features, unbatch
from lerobot_indicator.data.recorder import RecordConfig, checkpoint_dataset, open_dataset, write_episode
from lerobot_indicator.training.config import OnlineTrainConfig
from lerobot_indicator.training.rollout import Rollouts


class RolloutRecorder:
    """Appends each cycle's episodes to the dataset, skipping those a replayed cycle recorded before a kill."""

    def __init__(self, cfg: OnlineTrainConfig, vec_env: gym.vector.VectorEnv, keys: list[str]):
        r = cfg.record
        self.checkpoint_every_s = r.checkpoint_every_s
        self.keys = list(keys)
        self.cfg = RecordConfig(
            env=cfg.env,
            repo_id=r.repo_id,
            root=r.root,
            policy=f"indicator_ddpg online ({cfg.output_dir})",
            seed=cfg.seed,
            reward_keys=list(keys),
        )
        self.cfg.resume = cfg.resume and self.cfg.root.exists()
        _, info = vec_env.reset(seed=cfg.seed)
        features = dataset_features(
            vec_env.single_observation_space, vec_env.single_action_space, unbatch(info), False
        )
        self.task = str(vec_env.call("task_description")[0])
        self.dataset: LeRobotDataset = open_dataset(self.cfg, features)  # rolls back to the last checkpoint
        write_checkpoint(self.cfg.root, self.dataset.meta.total_episodes)
        self.skip = 0
        self.last_checkpoint_t = -math.inf  # the first cycle always checkpoints

    @property
    def total_episodes(self) -> int:
        return self.dataset.meta.total_episodes

    def start(self, expected_episodes: int) -> None:
        """``expected_episodes``: what the resume state recorded; episodes beyond it are replayed, not rewritten."""
        ahead = self.total_episodes - expected_episodes
        if ahead < 0:
            raise ValueError(
                f"the --record dataset at {self.cfg.root} has {self.total_episodes} episodes but this run's "
                f"resume state expects {expected_episodes}: it was changed outside this run"
            )
        self.skip = ahead

    def record(self, rollouts: list[Rollouts]) -> None:
        episodes = [e for r in rollouts for e in zip(r.dataset_frames, r.actions, strict=True)]
        skip = min(self.skip, len(episodes))
        self.skip -= skip
        for frames, actions in episodes[skip:]:
            write_episode(self.dataset, frames, list(actions), self.keys, self.task)
            self.dataset.save_episode()

    def checkpoint_if_due(self, is_last: bool) -> bool:
        """Checkpoint when ``checkpoint_every_s`` has passed (or at the end); True if it did."""
        if not (is_last or time.monotonic() - self.last_checkpoint_t >= self.checkpoint_every_s):
            return False
        self.dataset = checkpoint_dataset(self.cfg, self.dataset)
        self.last_checkpoint_t = time.monotonic()
        return True

    def finish(self, push_tags: list[str] | None) -> None:
        self.dataset.finalize()
        clear_checkpoint(self.cfg.root)  # complete and consistent: nothing to roll back to
        if push_tags is not None:
            self.dataset.push_to_hub(tags=push_tags)

    def close(self) -> None:
        """Finalize so every saved episode stays readable; the checkpoint journal stays, so ``--resume=true``
        rolls the dataset back to the resume state."""
        self.dataset.finalize()
