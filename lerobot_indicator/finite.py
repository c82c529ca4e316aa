"""Guards that keep NaN / Inf out of training and out of saved files.

A non-finite value in a dataset, a batch or a loss raises :class:`NonFiniteError` with one line that names
where it is (key, episode, frame; or the loss terms), before an optimizer step or a save could spread it.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor, nn


class NonFiniteError(ValueError):
    """A NaN or Inf where training needs finite numbers."""


def first_non_finite(x: np.ndarray | Tensor) -> tuple[int, ...] | None:
    """Index of the first NaN/Inf of a float array, or None (integer arrays are always finite)."""
    x = torch.as_tensor(x)
    if not x.is_floating_point():
        return None
    # A sum is finite only if every term is (NaN and Inf propagate), and it reads each element once where
    # isfinite makes several passes; only a non-finite sum (or an overflowing one) needs the per-element look.
    # Accumulated in float32 (float64 inputs: float64): a float64 sum of float32 frames is about 10x slower on
    # CPU, and an overflow only sends the check to the per-element look.
    if torch.isfinite(x.sum(dtype=torch.promote_types(x.dtype, torch.float32))):
        return None
    bad = ~torch.isfinite(x)
    if not bad.any():
        return None
    return tuple(int(i) for i in bad.nonzero()[0])


def check_episode(arrays: dict[str, np.ndarray], episode: int, source: str) -> None:
    """Per-frame arrays ``(T + 1, ...)`` of one episode: name the key, episode and frame of a NaN/Inf."""
    for key, value in arrays.items():
        where = first_non_finite(value)
        if where is not None:
            frame = where[0] if np.ndim(value) > 1 else 0
            raise NonFiniteError(f"{source}: {key} is {value[where]} at episode {episode}, frame {frame}")


def check_batch(batch: dict[str, Tensor]) -> None:
    """A training batch: name the key and, for dataset batches, the episode and dataset index of a NaN/Inf."""
    for key, value in batch.items():
        if not isinstance(value, Tensor):
            continue
        where = first_non_finite(value)
        if where is None:
            continue
        row = where[0]
        place = f"batch row {row}"
        if "episode_index" in batch and "index" in batch:
            place = f"episode {int(batch['episode_index'][row])}, dataset index {int(batch['index'][row])}"
        raise NonFiniteError(f"{key} is {value[where].item()} in the training batch ({place})")


def check_loss(loss: Tensor, stats: dict[str, Tensor]) -> None:
    """A loss and its logged terms (``indicator_core`` stats): raise before backward if any is not finite."""
    if torch.isfinite(loss):
        return
    bad = [k for k, v in stats.items() if not torch.isfinite(v)]
    raise NonFiniteError(f"the loss is {loss.item()} (non-finite terms: {bad or 'none logged'})")


def check_module(module: nn.Module, what: str) -> None:
    """Every parameter and buffer of ``module``: never save a NaN/Inf as a checkpoint."""
    for name, tensor in module.state_dict().items():
        if first_non_finite(tensor) is not None:
            raise NonFiniteError(
                f"{what}: {name} holds NaN/Inf; not saved (the last good checkpoint is kept)"
            )
