"""Pre/post processors of ``indicator_ddpg``: LeRobot's default pipeline (rename, batch, device, normalise).

The config maps every feature type to IDENTITY: observations are normalised inside the networks (so the
indicator reward compares raw values bit for bit, and a goal is scaled with its observation key's statistics),
and actions are already in the env's [-1, 1] space.
"""

from typing import Any

import torch
from lerobot.processor import PolicyAction, PolicyProcessorPipeline, make_default_pre_post_processors

from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig


def make_indicator_ddpg_pre_post_processors(
    config: IndicatorDDPGConfig,
    dataset_stats: dict[str, dict[str, torch.Tensor]] | None = None,
) -> tuple[
    PolicyProcessorPipeline[dict[str, Any], dict[str, Any]],
    PolicyProcessorPipeline[PolicyAction, PolicyAction],
]:
    return make_default_pre_post_processors(config, dataset_stats)
