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
ROPE_PUSH_ID = f"{GYM_NAMESPACE}/{ROPE_PUSH_TASK}"

# (gym id, env class, default horizon T): the paper's 25 steps for reach, 3 pushes for rope.
for _gym_id, _entry_point, _horizon in (
    (SAWYER_REACH_ID, "lerobot_indicator.envs.sawyer_reach:SawyerReachEnv", 25),
    (ROPE_PUSH_ID, "lerobot_indicator.envs.rope_push:RopePushEnv", 3),
):
    if _gym_id not in gym.registry:
        gym.register(id=_gym_id, entry_point=_entry_point, max_episode_steps=_horizon)

__all__ = [
    "ROPE_PUSH_ID",
    "RopePushEnvConfig",
    "SAWYER_REACH_ID",
    "EndEffectorConfig",
    "GoalCameraConfig",
    "SawyerGoalEnvConfig",
    "SawyerReachEnvConfig",
]
