"""Dataset feature specs and env-step -> ``LeRobotDataset`` frame conversion (docs/dataset_format.md).

Both tasks share one gymnasium observation contract (docs/conventions.md), so the features are read
off the env's observation/action spaces instead of being hard-coded per task: whatever the env
exposes for its ``obs_type`` is recorded, under the batch key the policy will later see.
"""

from __future__ import annotations

import contextlib
from collections.abc import Mapping, Sequence

import gymnasium as gym
import numpy as np
from lerobot.utils.constants import ACTION, OBS_IMAGES, OBS_STATE, OBS_STR
from lerobot.utils.feature_utils import hw_to_dataset_features

from lerobot_indicator.keys import ACTION_IS_PAD, DEPTH_SUFFIX, GOAL_PREFIX, GT_INFO_KEYS, ground_truth_key

REWARD, DONE = "next.reward", "next.done"


def env_feature_names(vec_env) -> dict[str, list[str]]:
    """The env's per-dimension names by env key (``feature_names()`` of the tasks here; {} for other envs)."""
    with contextlib.suppress(AttributeError, NotImplementedError):
        return dict(vec_env.call("feature_names")[0])
    return {}


def env_robot_type(vec_env) -> str | None:
    """The env's ``robot_type`` (the tasks here name theirs), for the dataset's ``meta/info.json``."""
    with contextlib.suppress(AttributeError, NotImplementedError):
        return str(vec_env.call("robot_type")[0])
    return None


def _names(names: Mapping[str, Sequence[str]], env_key: str, shape: tuple[int, ...]) -> list[str]:
    """Per-dimension names of a flat vector: the env's (a ``goal_<key>`` takes those of ``<key>``), else
    ``<key>_<i>``."""
    given = names.get(env_key)
    if given is None and env_key.startswith(GOAL_PREFIX):
        base = env_key.removeprefix(GOAL_PREFIX)  # goal_state is agent_pos's goal (docs/conventions.md)
        given = names.get("agent_pos" if base == "state" else base)
    size = int(np.prod(shape))
    if given is None:
        return [f"{env_key}_{i}" for i in range(size)]
    if len(given) != size:
        raise ValueError(f"feature names of {env_key!r}: {len(given)} names for shape {tuple(shape)}")
    return [str(n) for n in given]


def observation_key(env_key: str) -> str:
    """Batch key of a flat (non-camera) env observation, as ``lerobot-eval`` maps it."""
    return OBS_STATE if env_key == "agent_pos" else f"{OBS_STR}.{env_key}"


def _is_camera(space: gym.Space) -> bool:
    return (
        isinstance(space, gym.spaces.Box)
        and len(space.shape) == 3
        and space.shape[2] in (1, 3)
        and space.dtype in (np.uint8, np.uint16)
    )


def _vector_feature(shape: tuple[int, ...], names: list[str] | None = None) -> dict:
    return {"dtype": "float32", "shape": tuple(shape), "names": names}


def dataset_features(
    observation_space: gym.spaces.Dict,
    action_space: gym.spaces.Box,
    info: Mapping[str, np.ndarray],
    use_videos: bool,
    names: Mapping[str, Sequence[str]] | None = None,
) -> dict[str, dict]:
    """LeRobot feature dict for one env (unbatched spaces) and an info dict from its ``reset``.

    ``pixels[k]`` -> ``observation.images.k`` (RGB); depth, either nested ``depth[k]`` or top-level
    ``k_depth`` (uint16 HxWx1), -> ``observation.images.k_depth`` (``is_depth_map``); ``agent_pos`` ->
    ``observation.state``; other boxes -> ``observation.<key>``; ``info["gt_*"]`` -> ``observation.gt_*``.
    Every vector carries per-dimension ``names``: ``names`` by env key (``env_feature_names``), else
    ``<key>_<i>``. ``ACTION_IS_PAD`` marks the final-observation frame (docs/dataset_format.md).
    """
    names = names or {}
    if not isinstance(observation_space, gym.spaces.Dict):
        raise TypeError(f"expected a Dict observation space (docs/conventions.md), got {observation_space}")
    features: dict[str, dict] = {}
    cameras: dict[str, tuple] = {}
    for key, space in observation_space.spaces.items():
        if key in ("pixels", "depth"):
            suffix = DEPTH_SUFFIX if key == "depth" else ""
            for cam, cam_space in space.spaces.items():
                cameras[f"{cam}{suffix}"] = tuple(cam_space.shape)
        elif _is_camera(space):  # e.g. top-level ``front_depth`` (uint16 HxWx1)
            cameras[key] = tuple(space.shape)
        elif isinstance(space, gym.spaces.Box):
            features[observation_key(key)] = _vector_feature(space.shape, _names(names, key, space.shape))
        else:
            raise TypeError(f"observation {key!r} has unsupported space {space}")
    features.update(hw_to_dataset_features(cameras, OBS_STR, use_video=use_videos))
    for key in GT_INFO_KEYS:
        if key in info:
            shape = np.atleast_1d(np.asarray(info[key])).shape
            features[ground_truth_key(key)] = _vector_feature(shape, _names(names, key, shape))
    features[ACTION] = _vector_feature(action_space.shape, _names(names, ACTION, action_space.shape))
    features[REWARD] = _vector_feature((1,), ["reward"])
    features[DONE] = {"dtype": "bool", "shape": (1,), "names": ["done"]}
    features[ACTION_IS_PAD] = {"dtype": "bool", "shape": (1,), "names": ["action_is_pad"]}
    return features


def observation_frame(observation: Mapping, info: Mapping) -> dict[str, np.ndarray]:
    """The ``observation.*`` part of a frame from one env's (unbatched) observation and info.

    Values keep the env's representation (uint8 RGB, uint16 mm depth, float32 vectors) so stored
    images are bit-exact copies of what the env rendered.
    """
    frame: dict[str, np.ndarray] = {}
    for key, value in observation.items():
        if key in ("pixels", "depth"):
            suffix = DEPTH_SUFFIX if key == "depth" else ""
            for cam, image in value.items():
                frame[f"{OBS_IMAGES}.{cam}{suffix}"] = np.asarray(image)
        elif np.asarray(value).ndim == 3:
            frame[f"{OBS_IMAGES}.{key}"] = np.asarray(value)
        else:
            frame[observation_key(key)] = np.asarray(value, dtype=np.float32)
    for key in GT_INFO_KEYS:
        if key in info:
            frame[ground_truth_key(key)] = np.atleast_1d(np.asarray(info[key], dtype=np.float32))
    return frame


def batch(tree):
    """Add a leading batch axis of 1 to a (nested dict of) single-env values, as a vector env returns them."""
    if isinstance(tree, Mapping):
        return {k: batch(v) for k, v in tree.items()}
    return np.asarray(tree)[None]


def unbatch(tree, index: int = 0):
    """Element ``index`` of a (nested dict of) vector-env arrays."""
    if isinstance(tree, Mapping):
        return {k: unbatch(v, index) for k, v in tree.items() if not k.startswith("_")}
    return np.asarray(tree)[index]
