"""Evaluation videos of the online trainer: each frame is the observation beside its goal, upscaled.

Observation frames are small (32-100 px); a video of them is hard to watch, and without the goal it does not
show what the policy was asked to reach. :func:`video_frames` enlarges both by the same whole factor
(nearest neighbour, so every camera pixel stays a square of identical pixels) to at least
:data:`MIN_HEIGHT` rows and puts the goal on the right. Only RGB inputs can be shown: a policy compared on
states or depth alone gets no video.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from lerobot_indicator.keys import goal_key

MIN_HEIGHT = 256


def scale_factor(height: int, min_height: int = MIN_HEIGHT) -> int:
    """The smallest even whole factor (even: the yuv420p chroma planes then lose nothing) that makes ``height``
    at least ``min_height``."""
    factor = max(2, math.ceil(min_height / height))
    return factor + factor % 2


def to_uint8_hwc(images: np.ndarray) -> np.ndarray:
    """``(..., 3, H, W)`` floats in [0, 1] (a policy batch's images) -> ``(..., H, W, 3)`` uint8, exactly the
    camera's values."""
    return np.moveaxis(np.rint(np.asarray(images, dtype=np.float32) * 255.0), -3, -1).astype(np.uint8)


def video_frames(observations: np.ndarray, goal: np.ndarray, min_height: int = MIN_HEIGHT) -> np.ndarray:
    """``(T, H, W, 3)`` uint8 observations and their ``(H, W, 3)`` (or per-frame ``(T, H, W, 3)``) goal ->
    ``(T, k*H, 2*k*W, 3)``: observation left, goal right, each pixel a k x k square."""
    goal = np.broadcast_to(goal, observations.shape)
    k = scale_factor(observations.shape[1], min_height)
    side_by_side = np.concatenate([observations, goal], axis=2)
    return side_by_side.repeat(k, axis=1).repeat(k, axis=2)


def rgb_key(observation_keys: list[str], observations: dict[str, np.ndarray]) -> str | None:
    """The first compared key holding RGB images (3 channels) whose goal the rollout kept, else None."""
    for key in observation_keys:
        value = observations.get(key)
        if value is not None and value.ndim >= 4 and value.shape[-3] == 3 and goal_key(key) in observations:
            return key
    return None


def write_eval_videos(
    rollouts: list, observation_keys: list[str], out_dir: Path, n_videos: int, fps: int
) -> list[Path]:
    """The first ``n_videos`` evaluation episodes of ``rollouts`` as ``out_dir/episode_<i>.mp4``; none when the
    policy compares no RGB key."""
    from lerobot.utils.io_utils import write_video

    written: list[Path] = []
    for r in rollouts:
        key = rgb_key(observation_keys, r.observations)
        if key is None:
            return written
        for obs, goal in zip(r.observations[key], r.observations[goal_key(key)], strict=True):
            if len(written) >= n_videos:
                return written
            out_dir.mkdir(parents=True, exist_ok=True)
            path = out_dir / f"episode_{len(written)}.mp4"
            write_video(path, list(video_frames(to_uint8_hwc(obs), to_uint8_hwc(goal))), fps)
            written.append(path)
    return written
