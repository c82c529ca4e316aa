"""Goal observations for deployment: one goal per compared key, saved once, added to every observation.

LeRobot's robot CLIs (``lerobot-rollout``, ``lerobot-record --policy.path``) deliver the robot's observations
and have no goal input. A goal directory (``--policy.goal_path``) holds ``goal.safetensors``: for each compared
key ``k`` the tensor ``goal_key(k)`` in the policy's layout without a batch axis (an image: float32 (C, H, W) in
[0, 1], as ``LeRobotDataset`` and ``prepare_observation_for_inference`` give it; a state: its vector), so the
goal the policy sees is bit for bit the frame it was saved from.

Save one from a dataset frame (``python -m lerobot_indicator.policy.goal_observations --dataset.repo_id=...
--dataset.root=... --episode=0 --frame=-1 --output_dir=goal``), or from a camera image with ``save_goal``
(docs/own_data.md).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import draccus
import numpy as np
import torch
from lerobot.configs.default import DatasetConfig
from lerobot.policies.utils import prepare_observation_for_inference
from safetensors.torch import load_file, save_file
from torch import Tensor

from lerobot_indicator.keys import GT_PREFIX, OBS_PREFIX, goal_key, is_goal_key, observation_key

GOAL_FILE = "goal.safetensors"


class GoalObservationError(ValueError):
    """A goal directory or goal tensor that does not fit the policy."""


def goal_file(goal_path: str | Path) -> Path:
    """The goal file of ``goal_path``: a directory holding ``goal.safetensors``, or that file itself."""
    path = Path(goal_path)
    return path / GOAL_FILE if path.is_dir() or path.suffix != ".safetensors" else path


def save_goal(goal_path: str | Path, observation: dict[str, Tensor | np.ndarray], keys: list[str]) -> Path:
    """Save ``observation[k]`` as the goal of each of ``keys`` (policy layout, one frame: a leading batch axis
    of 1 is dropped); returns the file written."""
    goals = {}
    for key in keys:
        if key not in observation:
            raise GoalObservationError(
                f"observation has no {key!r} to save as its goal (has {sorted(observation)})"
            )
        value = torch.as_tensor(observation[key])
        if value.dim() > 1 and value.shape[0] == 1:
            value = value[0]
        goals[goal_key(key)] = value.detach().cpu().contiguous()
    path = goal_file(goal_path)
    path.parent.mkdir(parents=True, exist_ok=True)
    save_file(goals, str(path))
    return path


def camera_observation(frames: dict[str, np.ndarray]) -> dict[str, Tensor]:
    """Robot frames (``{"observation.images.front": HxWx3 uint8, ...}``, as ``build_dataset_frame`` names them)
    in the policy layout, converted by the function ``lerobot-rollout`` uses on every tick."""
    batch = prepare_observation_for_inference(dict(frames), torch.device("cpu"))
    return {k: v for k, v in batch.items() if isinstance(v, Tensor)}


def dataset_frame(dataset, episode: int, frame: int) -> dict[str, Tensor]:
    """Frame ``frame`` of episode ``episode`` of a ``LeRobotDataset`` (negative counts from the episode's end)."""
    episodes = dataset.meta.episodes
    n_episodes = len(episodes["episode_index"])
    if not 0 <= episode < n_episodes:
        raise GoalObservationError(
            f"dataset {dataset.repo_id} has episodes 0..{n_episodes - 1}, not {episode}"
        )
    start, stop = int(episodes["dataset_from_index"][episode]), int(episodes["dataset_to_index"][episode])
    length = stop - start
    if not -length <= frame < length:
        raise GoalObservationError(
            f"episode {episode} of dataset {dataset.repo_id} has {length} frames, not frame {frame}"
        )
    return dataset[start + frame % length]


def dataset_camera_keys(dataset) -> list[str]:
    """The keys a goal-free policy compares by default: the dataset's cameras (else its state keys)."""
    features = {k: ft for k, ft in dataset.meta.features.items() if k.startswith(OBS_PREFIX)}
    observed = [k for k in features if not is_goal_key(k) and not k.startswith(GT_PREFIX)]
    cameras = [k for k in observed if features[k]["dtype"] in ("image", "video")]
    return cameras or observed


class GoalObservations:
    """The goals of ``observation_keys``, loaded once from ``goal_path``, added to observations without them."""

    def __init__(self, goal_path: str | Path, observation_keys: list[str]):
        path = goal_file(goal_path)
        if not path.is_file():
            raise GoalObservationError(
                f"goal file {path} does not exist: save one with lerobot_indicator.policy.goal_observations "
                "(docs/own_data.md)"
            )
        stored = load_file(str(path))
        self.path = path
        self.goals: dict[str, Tensor] = {}
        for key in observation_keys:
            gkey = goal_key(key)
            if gkey not in stored:
                raise GoalObservationError(
                    f"goal file {path} has no goal {gkey!r} for the compared key {key!r} (holds {sorted(stored)})"
                )
            self.goals[gkey] = stored[gkey]
        logging.info("indicator_ddpg goal observations %s from %s", sorted(self.goals), path)

    def add(self, observation: dict) -> dict:
        """``observation`` with every goal it lacks, on its observation key's device and batch size."""
        out = dict(observation)
        for gkey, goal in self.goals.items():
            if gkey in out:
                continue
            key = observation_key(gkey)
            frame = observation.get(key)
            if frame is None:
                continue  # the policy names the missing observation key
            frame = torch.as_tensor(frame)
            batched = frame.dim() == goal.dim() + 1
            if tuple(frame.shape[batched:]) != tuple(goal.shape):
                raise GoalObservationError(
                    f"goal {gkey!r} in {self.path} has shape {tuple(goal.shape)} but the observation {key!r} has "
                    f"{tuple(frame.shape[batched:])}: save a goal from this camera / state"
                )
            goal = goal.to(frame.device)
            out[gkey] = goal.expand(frame.shape[0], *goal.shape).contiguous() if batched else goal
        return out


@dataclass
class SaveGoalConfig:
    """``python -m lerobot_indicator.policy.goal_observations``: save one dataset frame as the goal."""

    dataset: DatasetConfig
    # Episode and frame of the goal (negative frames count from the episode's end: -1 = its last frame).
    episode: int = 0
    frame: int = -1
    # Compared keys to save goals of; None = the dataset's cameras (else its state keys), as a goal-free policy.
    keys: list[str] | None = None
    # Directory written (goal.safetensors), passed to the policy as --policy.goal_path.
    output_dir: str = "goal"


def main() -> None:
    from lerobot.datasets import LeRobotDataset

    cfg = draccus.parse(SaveGoalConfig)
    dataset = LeRobotDataset(cfg.dataset.repo_id, root=cfg.dataset.root, revision=cfg.dataset.revision)
    keys = cfg.keys or dataset_camera_keys(dataset)
    path = save_goal(cfg.output_dir, dataset_frame(dataset, cfg.episode, cfg.frame), keys)
    print(f"saved the goals of {keys} (episode {cfg.episode}, frame {cfg.frame}) to {path}")


if __name__ == "__main__":
    main()
