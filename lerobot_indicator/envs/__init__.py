"""Sim tasks (Sawyer reach; shared pieces for rope push): gymnasium ids and LeRobot env types.

Importing this registers ``lerobot_indicator/SawyerReach-v0`` with gymnasium and ``sawyer_reach`` with
LeRobot's ``EnvConfig``; robosuite and MuJoCo are only imported when an env is built.
"""

import gymnasium as gym

from lerobot_indicator.envs.configs import (
    GYM_NAMESPACE,
    ROPE_PUSH_TASK,
    SAWYER_REACH_TASK,
    RopePushEnvConfig,
    SawyerGoalEnvConfig,
    SawyerReachEnvConfig,
)
from lerobot_indicator.envs.hardware import EndEffectorConfig, GoalCameraConfig

SAWYER_REACH_ID = f"{GYM_NAMESPACE}/{SAWYER_REACH_TASK}"

if SAWYER_REACH_ID not in gym.registry:
    gym.register(
        id=SAWYER_REACH_ID,
        entry_point="lerobot_indicator.envs.sawyer_reach:SawyerReachEnv",
        max_episode_steps=25,
    )

ROPE_PUSH_ID = f"{GYM_NAMESPACE}/{ROPE_PUSH_TASK}"

if ROPE_PUSH_ID not in gym.registry:
    gym.register(
        id=ROPE_PUSH_ID,
        entry_point="lerobot_indicator.envs.rope_push:RopePushEnv",
        max_episode_steps=3,
    )

__all__ = [
    "ROPE_PUSH_ID",
    "RopePushEnvConfig",
    "SAWYER_REACH_ID",
    "EndEffectorConfig",
    "GoalCameraConfig",
    "SawyerGoalEnvConfig",
    "SawyerReachEnvConfig",
]
