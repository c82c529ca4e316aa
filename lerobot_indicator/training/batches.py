"""Replay-buffer samples as the learning core's transition batches (``indicator_core`` docstring)."""

import numpy as np
import torch

from lerobot_indicator.keys import goal_key
from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy.networks_indicator_ddpg import as_float


def to_transition_batch(
    sample: dict,
    keys: list[str],
    horizon: int,
    device: torch.device | str,
    context_keys: list[str] | None = None,
) -> dict[str, torch.Tensor]:
    """Replay-buffer sample -> the learning core's transition batch.

    ``keys`` are the compared keys; ``context_keys`` come with o_t, o_{t+1} and the n-step path (the frames
    the networks read), never with the future frame, which is only ever a goal.
    ``future.count`` = |{t+2..T}| lets the unbalanced (HER-style) mode pick o_{t+1} with the right
    probability, so its future goal is uniform over {t+1..T}."""

    def t(x: np.ndarray) -> torch.Tensor:
        x = torch.from_numpy(np.ascontiguousarray(x)).to(device)
        # uint8 frames stay uint8 (the networks convert them); torch has few uint16 kernels, so packed depth
        # becomes its float32 value here.
        return x.float() if x.dtype == torch.uint16 else x

    batch = {
        core.ACTION: t(sample["action"]),
        core.HAS_FUTURE: t(sample["has_future"]),
        core.FUTURE_COUNT: t(np.maximum(horizon - sample["t"] - 1, 0)),
    }
    for k in keys:
        batch[k] = t(sample["obs"][k])
        batch[core.NEXT + k] = t(sample["next_obs"][k])
        batch[core.FUTURE + k] = t(sample["future_obs"][k])
        if "path_obs" in sample:
            batch[core.PATH + k] = t(sample["path_obs"][k])
    for k in context_keys or []:
        batch[k] = t(sample["obs"][k])
        batch[core.NEXT + k] = t(sample["next_obs"][k])
        if "path_obs" in sample:
            batch[core.PATH + k] = t(sample["path_obs"][k])
    if "path_obs" in sample:
        batch[core.PATH_VALID] = t(sample["path_valid"])
    for k in (k for k in sample["obs"] if k not in batch):
        batch[k] = t(sample["obs"][k])  # the recorded goals
    for k in keys:
        # The buffer packs an observation key and its goal key separately: where one was widened to float32
        # and the other is still uint8, compare and encode both as their float32 values.
        group = [k, core.NEXT + k, core.FUTURE + k, goal_key(k)] + (
            [core.PATH + k] if "path_obs" in sample else []
        )
        if len({batch[g].dtype for g in group}) > 1:
            batch.update({g: as_float(batch[g]) for g in group})
    if "gt_next_achieved" in sample:
        batch[core.GT_NEXT_ACHIEVED] = t(sample["gt_next_achieved"])
        batch[core.GT_FUTURE_ACHIEVED] = t(sample["gt_future_achieved"])
        batch[core.GT_DESIRED] = t(sample["gt_desired"])
    if "gt_path_achieved" in sample:
        batch[core.GT_PATH_ACHIEVED] = t(sample["gt_path_achieved"])
    return batch
