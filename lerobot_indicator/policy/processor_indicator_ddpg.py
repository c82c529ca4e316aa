"""Pre/post processors of ``indicator_ddpg``: LeRobot's default pipeline (rename, batch, device, normalise),
with the goal observations of ``--policy.goal_path`` added after batching when the config names one.

The config maps every feature type to IDENTITY: observations are normalised inside the networks (so the
indicator reward compares raw values bit for bit, and a goal is scaled with its observation key's statistics),
and actions are already in the env's [-1, 1] space.
"""

from dataclasses import dataclass, field
from typing import Any

import torch
from lerobot.configs import PipelineFeatureType, PolicyFeature
from lerobot.processor import (
    ObservationProcessorStep,
    PolicyAction,
    PolicyProcessorPipeline,
    ProcessorStepRegistry,
    make_default_pre_post_processors,
)

from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig
from lerobot_indicator.policy.goal_observations import GoalObservations


@ProcessorStepRegistry.register(name="indicator_goal_observations")
@dataclass
class GoalObservationsProcessorStep(ObservationProcessorStep):
    """Adds the goal of each compared key that an observation lacks, from ``goal_path`` (loaded once, on first
    use), bit for bit, on the observation's device and batch size. Observations with goals pass unchanged."""

    goal_path: str
    observation_keys: list[str]
    _goals: GoalObservations | None = field(default=None, init=False, repr=False)

    def observation(self, observation: dict[str, Any]) -> dict[str, Any]:
        if self._goals is None:
            self._goals = GoalObservations(self.goal_path, self.observation_keys)
        return self._goals.add(observation)

    def get_config(self) -> dict[str, Any]:
        return {"goal_path": self.goal_path, "observation_keys": list(self.observation_keys)}

    def transform_features(
        self, features: dict[PipelineFeatureType, dict[str, PolicyFeature]]
    ) -> dict[PipelineFeatureType, dict[str, PolicyFeature]]:
        return features


def make_indicator_ddpg_pre_post_processors(
    config: IndicatorDDPGConfig,
    dataset_stats: dict[str, dict[str, torch.Tensor]] | None = None,
) -> tuple[
    PolicyProcessorPipeline[dict[str, Any], dict[str, Any]],
    PolicyProcessorPipeline[PolicyAction, PolicyAction],
]:
    pre, post = make_default_pre_post_processors(config, dataset_stats)
    if config.goal_path is not None and config.observation_keys:
        # After the batch step (the goal takes the observation's batch size), before the device step.
        step = GoalObservationsProcessorStep(config.goal_path, list(config.observation_keys))
        at = next(i for i, s in enumerate(pre.steps) if type(s).__name__ == "AddBatchDimensionProcessorStep")
        pre.steps.insert(at + 1, step)
    return pre, post
