"""``--robot.type=indicator_sim_reach``: the Sawyer reach task as a LeRobot ``Robot``, for ``lerobot-rollout``
without hardware.

A robot gives ``lerobot-rollout`` its camera frames and joint values and takes actions; it knows no goal, so the
policy's goal comes from ``--policy.goal_path`` as on a real robot (docs/own_data.md). Observation: camera
``front`` (H x W x 3 uint8, the task's camera) and the end effector's ``x.pos``, ``y.pos``, ``z.pos`` (m); action:
``x.vel``, ``y.vel``, ``z.vel`` in [-1, 1], the task's end-effector step (``lerobot-rollout`` routes only ``.pos``
and ``.vel`` keys). A ``.pos`` action (``lerobot-rollout``'s return to the initial position) moves toward that
position by at most one step. ``trace_path``: one JSON line per action with the ground-truth distance to the
task's own goal, which never reaches the policy.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from lerobot.robots import Robot, RobotConfig

AXES = ("x", "y", "z")
CAMERA = "front"


@RobotConfig.register_subclass("indicator_sim_reach")
@dataclass
class SimReachRobotConfig(RobotConfig):
    """The simulated Sawyer reach robot (``lerobot_indicator.envs.sim_robot``)."""

    # Height and width of the camera frames (the trained policy's image size).
    camera_size: int = 100
    # Seed of the task's start (and of its own goal, used only in the trace).
    seed: int = 0
    # Where to append one JSON line per action (the action and the ground-truth distance); None = nowhere.
    trace_path: str | None = None


class SimReachRobot(Robot):
    """See module docstring."""

    config_class = SimReachRobotConfig
    name = "indicator_sim_reach"

    def __init__(self, config: SimReachRobotConfig):
        super().__init__(config)
        self.config = config
        self.env = None
        self._obs: dict | None = None

    @cached_property
    def observation_features(self) -> dict:
        size = self.config.camera_size
        return {f"{a}.pos": float for a in AXES} | {CAMERA: (size, size, 3)}

    @cached_property
    def action_features(self) -> dict:
        return {f"{a}.vel": float for a in AXES}

    @property
    def is_connected(self) -> bool:
        return self.env is not None

    def connect(self, calibrate: bool = True) -> None:
        import gymnasium as gym

        from lerobot_indicator.envs import SAWYER_REACH_ID

        size = self.config.camera_size
        camera = {"name": CAMERA, "height": size, "width": size, "use_depth": False}
        self.env = gym.make(SAWYER_REACH_ID, obs_type="rgb", camera=camera).unwrapped
        self._obs, _ = self.env.reset(seed=self.config.seed)

    @property
    def is_calibrated(self) -> bool:
        return True

    def calibrate(self) -> None:
        pass

    def configure(self) -> None:
        pass

    def get_observation(self) -> dict:
        position = self._obs["agent_pos"]
        return {f"{a}.pos": float(v) for a, v in zip(AXES, position, strict=True)} | {
            CAMERA: self._obs["pixels"][CAMERA].copy()
        }

    def send_action(self, action: dict) -> dict:
        if all(f"{a}.vel" in action for a in AXES):
            step = np.array([action[f"{a}.vel"] for a in AXES], np.float32)
        else:  # a target position: at most one step toward it
            target = np.array([action[f"{a}.pos"] for a in AXES], np.float32)
            step = (target - self._obs["agent_pos"]) / np.asarray(self.env.ee_cfg.step_sizes)
        step = np.clip(step, -1.0, 1.0)
        self._obs, _, _, _, info = self.env.step(step)
        if self.config.trace_path:
            with open(self.config.trace_path, "a") as f:
                f.write(
                    json.dumps({"action": step.tolist(), "gt_distance": float(info["gt_distance"])}) + "\n"
                )
        return {f"{a}.vel": float(v) for a, v in zip(AXES, step, strict=True)}

    def disconnect(self) -> None:
        if self.env is not None:
            self.env.close()
            self.env = None
