"""``--record.*``: the online trainer's behaviour-policy episodes as a LeRobotDataset.

Written in the format of ``lerobot_indicator.data.recorder`` (docs/dataset_format.md, lossless images) through
the recorder's own crash safety (data/checkpoint.py): every episode is committed as it is saved, so an
interruption of any kind loses at most the episode being saved, which the resumed run records again.
"""

from __future__ import annotations

import gymnasium as gym

from lerobot_indicator.data.checkpoint import INFO
from lerobot_indicator.data.features import dataset_features, env_feature_names, env_robot_type, unbatch
from lerobot_indicator.data.recorder import (
    RecordConfig,
    env_args,
    open_recording,
    push_dataset,
    write_card,
    write_episode,
)
from lerobot_indicator.training.config import OnlineTrainConfig
from lerobot_indicator.training.rollout import Rollouts


class RolloutRecorder:
    """Appends each cycle's episodes to the dataset, skipping those a replayed cycle recorded before a kill."""

    def __init__(self, cfg: OnlineTrainConfig, vec_env: gym.vector.VectorEnv, keys: list[str]):
        r = cfg.record
        self.keys = list(keys)
        self.cfg = RecordConfig(
            env=cfg.env,
            repo_id=r.repo_id,
            root=r.root,
            policy=f"indicator_ddpg online ({cfg.output_dir})",
            seed=cfg.seed,
            reward_keys=list(keys),
        )
        self.cfg.resume = cfg.resume and (self.cfg.root / INFO).exists()
        _, info = vec_env.reset(seed=cfg.seed)
        features = dataset_features(
            vec_env.single_observation_space, vec_env.single_action_space, unbatch(info), False,
            env_feature_names(vec_env),
        )  # fmt: skip
        self.task = str(vec_env.call("task_description")[0])
        self.session = open_recording(self.cfg, features, horizon=None, robot_type=env_robot_type(vec_env))
        # The dataset card's command: the training run whose behaviour-policy episodes these are.
        self.command = " ".join(
            ["lerobot-indicator-train --policy.type=indicator_ddpg", *env_args(cfg.env),
             f"--seed={cfg.seed}", f"--steps={cfg.steps}", f"--record.repo_id={r.repo_id}"]
        )  # fmt: skip
        self.skip = 0

    @property
    def total_episodes(self) -> int:
        return self.session.total_episodes

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
            write_episode(self.session.dataset, frames, list(actions), self.keys, self.task)
            self.session.save_episode()

    def checkpoint_if_due(self, is_last: bool) -> bool:
        """Whether the run's resume state may be saved now: always, as every episode is committed when it
        is saved (a state saved after :meth:`record` never counts an uncommitted episode)."""
        return True

    def finish(self, push_tags: list[str] | None) -> None:
        self.session.close()
        dataset = self.session.committed_dataset()
        write_card(dataset, self.cfg, self.command, push_tags)
        if push_tags is not None:
            push_dataset(dataset, self.cfg, self.command, push_tags)

    def close(self) -> None:
        """Also on a crash: stop LeRobot's writer; every committed episode stays as it is."""
        self.session.close(clean=False)
