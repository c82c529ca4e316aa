"""Sim tasks: gymnasium ids and LeRobot env types.

Importing this registers ``lerobot_indicator/SawyerReach-v0``, ``RopePush-v0``, ``Reacher-v0``,
``FetchReach-v0``, ``FetchPush-v0`` and ``FetchSlide-v0`` with gymnasium and ``sawyer_reach``, ``rope_push``,
``reacher``, ``fetch_reach``, ``fetch_push`` and ``fetch_slide`` with LeRobot's ``EnvConfig``; robosuite,
gymnasium-robotics and MuJoCo are only imported when an env is built.
"""

import gymnasium as gym

from lerobot_indicator.envs.configs import (
    FETCH_PUSH_TASK,
    FETCH_REACH_TASK,
    FETCH_SLIDE_TASK,
    GYM_NAMESPACE,
    REACHER_TASK,
    ROPE_PUSH_TASK,
    SAWYER_REACH_TASK,
    FetchPushEnvConfig,
    FetchReachEnvConfig,
    FetchSlideEnvConfig,
    GoalEnvConfig,
    GymGoalEnvConfig,
    ReacherEnvConfig,
    RopePushEnvConfig,
    SawyerGoalEnvConfig,
    SawyerReachEnvConfig,
)
from lerobot_indicator.envs.hardware import EndEffectorConfig, GoalCameraConfig
from lerobot_indicator.envs.sim_robot import (  # --robot.type=indicator_sim_reach
    SimReachRobot,
    SimReachRobotConfig,
)

SAWYER_REACH_ID = f"{GYM_NAMESPACE}/{SAWYER_REACH_TASK}"
ROPE_PUSH_ID = f"{GYM_NAMESPACE}/{ROPE_PUSH_TASK}"
REACHER_ID = f"{GYM_NAMESPACE}/{REACHER_TASK}"
FETCH_REACH_ID = f"{GYM_NAMESPACE}/{FETCH_REACH_TASK}"
FETCH_PUSH_ID = f"{GYM_NAMESPACE}/{FETCH_PUSH_TASK}"
FETCH_SLIDE_ID = f"{GYM_NAMESPACE}/{FETCH_SLIDE_TASK}"

# (gym id, env class, default horizon T): the paper's 25 steps for reach, 3 pushes for rope, 50 for the
# gymnasium tasks.
for _gym_id, _entry_point, _horizon in (
    (SAWYER_REACH_ID, "lerobot_indicator.envs.sawyer_reach:SawyerReachEnv", 25),
    (ROPE_PUSH_ID, "lerobot_indicator.envs.rope_push:RopePushEnv", 3),
    (REACHER_ID, "lerobot_indicator.envs.reacher:ReacherEnv", 50),
    (FETCH_REACH_ID, "lerobot_indicator.envs.fetch:FetchReachEnv", 50),
    (FETCH_PUSH_ID, "lerobot_indicator.envs.fetch:FetchPushEnv", 50),
    (FETCH_SLIDE_ID, "lerobot_indicator.envs.fetch:FetchSlideEnv", 50),
):
    if _gym_id not in gym.registry:
        gym.register(id=_gym_id, entry_point=_entry_point, max_episode_steps=_horizon)

__all__ = [
    "FETCH_PUSH_ID",
    "FETCH_REACH_ID",
    "FETCH_SLIDE_ID",
    "REACHER_ID",
    "ROPE_PUSH_ID",
    "SAWYER_REACH_ID",
    "EndEffectorConfig",
    "FetchPushEnvConfig",
    "FetchReachEnvConfig",
    "FetchSlideEnvConfig",
    "GoalCameraConfig",
    "GoalEnvConfig",
    "GymGoalEnvConfig",
    "ReacherEnvConfig",
    "RopePushEnvConfig",
    "SawyerGoalEnvConfig",
    "SawyerReachEnvConfig",
    "SimReachRobot",
    "SimReachRobotConfig",
]
