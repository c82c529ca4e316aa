"""Env processor: depth maps from the env reach the policy as images, as a LeRobotDataset returns them.

LeRobot's ``preprocess_observation`` turns only ``pixels`` into images (uint8 -> float /255) and passes
other arrays through as ``observation.<key>`` floats. Depth (uint16 mm, HxWx1) therefore arrives as
``observation.front_depth`` float32 (B, H, W, 1) in millimetres; this step moves it to
``observation.images.front_depth`` float32 (B, 1, H, W), still millimetres -- what ``LeRobotDataset``
returns for a feature stored with ``info: {"is_depth_map": True}`` from uint16 frames (its default
``depth_output_unit`` is mm).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import torch
from lerobot.configs import FeatureType, PipelineFeatureType, PolicyFeature
from lerobot.processor import ObservationProcessorStep, ProcessorStepRegistry
from lerobot.utils.constants import OBS_IMAGES, OBS_STR


@ProcessorStepRegistry.register(name="indicator_depth_to_images")
@dataclass
class DepthToImagesProcessorStep(ObservationProcessorStep):
    """``observation.<k>`` (B, H, W, 1) -> ``observation.images.<k>`` float32 (B, 1, H, W), same units."""

    depth_keys: list[str] = field(default_factory=list)

    def observation(self, observation: dict[str, Any]) -> dict[str, Any]:
        for key in self.depth_keys:
            src = f"{OBS_STR}.{key}"
            if src not in observation:
                continue
            depth = observation.pop(src)
            if not isinstance(depth, torch.Tensor):
                depth = torch.as_tensor(depth)
            if depth.ndim == 3:  # unbatched (H, W, 1)
                depth = depth.unsqueeze(0)
            if depth.ndim != 4 or depth.shape[-1] != 1:
                raise ValueError(f"{src}: expected depth shaped (B, H, W, 1), got {tuple(depth.shape)}")
            observation[f"{OBS_IMAGES}.{key}"] = depth.permute(0, 3, 1, 2).contiguous().to(torch.float32)
        return observation

    def transform_features(
        self, features: dict[PipelineFeatureType, dict[str, PolicyFeature]]
    ) -> dict[PipelineFeatureType, dict[str, PolicyFeature]]:
        obs = dict(features.get(PipelineFeatureType.OBSERVATION, {}))
        for key in self.depth_keys:
            ft = obs.pop(f"{OBS_STR}.{key}", None)
            if ft is not None:
                h, w = ft.shape[:2] if ft.shape[-1] == 1 else ft.shape[1:]
                obs[f"{OBS_IMAGES}.{key}"] = PolicyFeature(type=FeatureType.VISUAL, shape=(1, h, w))
        return {**features, PipelineFeatureType.OBSERVATION: obs}

    def get_config(self) -> dict[str, Any]:
        return {"depth_keys": list(self.depth_keys)}
