"""The paper's FetchReach and FetchPush: gymnasium-robotics' ``FetchReach-v4`` / ``FetchPush-v4`` as goal tasks
(and ``FetchSlide-v4``, the same adapter with another id).

Start and goal are what the wrapped env's reset draws (a fixed arm posture; FetchPush: the block somewhere
on the table; the goal within 0.15 m of the gripper's start); a start already within ``epsilon`` of the goal
is redrawn. Action: the wrapped env's ``step``, gripper displacement xyz in [-1, 1] times 0.05 m through its
mocap weld, 20 substeps of 2 ms (25 steps/s); the gripper is blocked, so FetchReach takes 3 numbers and
FetchPush the wrapped env's 4 (the 4th has no effect). The target site and the mocap body (a crosshair
that shows the last action) are never drawn.

Goal configuration. FetchReach: from the start state, the wrapped env's own steps drive the gripper to the
goal (each step asks for the rest of the way, at most 0.05 m per axis) until it moves less than 0.1 mm in a
step, so the goal image shows the arm as its own dynamics bring it there. The goal is where the gripper
settles: the sampled point up to the weld's steady-state error, or, for a point lower than the blocked
fingers can go above the table, where they stop. FetchPush / FetchSlide: the block is put at the goal (at
rest), the arm stays where it starts.

Observations (besides the shared camera keys): ``agent_pos`` = the compared state, the paper's 3-d goal
space: the gripper's grip point xyz (FetchReach) or the block's centre xyz (FetchPush); ``goal_state`` = the
same in the goal configuration; with ``obs_type="state"`` also ``environment_state`` = the wrapped env's
``observation`` vector (10 / 25; it holds no goal): never compared, the policy's default context input
(FetchPush's gripper, which the compared block position does not show). ``info``: ``gt_achieved_goal`` / ``gt_desired_goal`` =
``agent_pos`` / ``goal_state`` in float64 before the cast, ``gt_distance`` their distance, ``is_success`` =
``gt_distance <= epsilon`` (0.05 m, the paper's table).
"""

from __future__ import annotations

import numpy as np

from lerobot_indicator.envs.gym_goal import GymGoalEnv

# Facing the robot from the front right across the table (gymnasium's viewing direction, closer): the arm,
# the reach box and FetchPush's table top. FetchSlide: from the side, over the long table.
FETCH_CAMERA = {"name": "front", "pos": [2.0, 0.3, 1.25], "lookat": [1.3, 0.75, 0.55], "fovy_deg": 45.0}
FETCH_SLIDE_CAMERA = {
    "name": "front",
    "pos": [1.7, -0.45, 1.5],
    "lookat": [1.6, 0.75, 0.42],
    "fovy_deg": 50.0,
}
GRIP_SITE = "robot0:grip"
OBJECT_SITE, OBJECT_JOINT = "object0", "object0:joint"
MOCAP_BODY = "robot0:mocap"
ACTION_SCALE_M = 0.05  # the wrapped env's gripper displacement per unit action
SETTLE_TOL_M = 1e-4  # the goal configuration is reached when a step moves the gripper less than this
MAX_SETTLE_STEPS = 200


def _xyz(prefix: str) -> tuple[str, ...]:
    return tuple(f"{prefix}_{axis}" for axis in "xyz")


# gymnasium-robotics' Fetch ``observation`` (fetch_env.py), in its order; the object parts are empty for FetchReach.
FINGERS_POS, FINGERS_VEL = ("right_finger_pos", "left_finger_pos"), ("right_finger_vel", "left_finger_vel")
FETCH_REACH_STATE_NAMES = (*_xyz("grip"), *FINGERS_POS, *_xyz("grip_vel"), *FINGERS_VEL)
FETCH_PUSH_STATE_NAMES = (
    *_xyz("grip"), *_xyz("object"), *_xyz("object_rel"), *FINGERS_POS, *_xyz("object_rot"),
    *_xyz("object_vel"), *_xyz("object_angvel"), *_xyz("grip_vel"), *FINGERS_VEL,
)  # fmt: skip


class FetchEnv(GymGoalEnv):
    """Fetch tasks: markers, camera and the wrapped env's observation as ``environment_state``."""

    robot_type = "fetch"

    marker_bodies = (MOCAP_BODY,)
    default_camera = FETCH_CAMERA

    def _bind(self) -> None:
        self._grip = self.model.site(GRIP_SITE).id

    def environment_state(self) -> np.ndarray:
        return np.asarray(self._inner_obs["observation"], dtype=np.float64)

    def _inner_action(self, action: np.ndarray) -> np.ndarray:
        return np.concatenate([action, np.zeros(4 - self.action_dim, dtype=np.float32)])

    def _grip_pos(self) -> np.ndarray:
        return self.data.site_xpos[self._grip].copy()


class FetchReachEnv(FetchEnv):
    """See module docstring: move the gripper to where it is in the goal image."""

    task = "fetch_reach"
    task_description = "Move the gripper to where it is in the goal image."
    wrapped_id = "FetchReach-v4"
    state_dim = 3
    action_dim = 3
    env_state_dim = 10
    environment_state_names = FETCH_REACH_STATE_NAMES

    def __init__(self, obs_type: str = "rgbd", epsilon: float = 0.05, **kwargs):
        """``kwargs``: :class:`GymGoalEnv`'s (camera, fps, env_state_with_images, render_mode, episode_length,
        eval_reward)."""
        super().__init__(obs_type=obs_type, epsilon=epsilon, **kwargs)
        self._bind()
        self._measure_goal()

    def _agent_state(self) -> np.ndarray:
        return self._grip_pos()

    def _achieved_goal(self) -> np.ndarray:
        return self._grip_pos()

    def _enter_goal_configuration(self) -> None:
        goal = self._sampled_goal()
        for _ in range(MAX_SETTLE_STEPS):
            before = self._grip_pos()
            action = np.clip((goal - before) / ACTION_SCALE_M, -1.0, 1.0)
            self.inner.step(self._inner_action(action.astype(np.float32)))
            if np.linalg.norm(self._grip_pos() - before) < SETTLE_TOL_M:
                break
        self._mj.mj_forward(self.model, self.data)


class FetchPushEnv(FetchEnv):
    """See module docstring: push the block to where it is in the goal."""

    task = "fetch_push"
    task_description = "Push the block to where it is in the goal."
    wrapped_id = "FetchPush-v4"
    state_dim = 3
    action_dim = 4
    env_state_dim = 25
    environment_state_names = FETCH_PUSH_STATE_NAMES
    action_names = ("delta_x", "delta_y", "delta_z", "gripper")

    def __init__(self, obs_type: str = "state", epsilon: float = 0.05, **kwargs):
        """``kwargs``: :class:`GymGoalEnv`'s (camera, fps, env_state_with_images, render_mode, episode_length,
        eval_reward)."""
        super().__init__(obs_type=obs_type, epsilon=epsilon, **kwargs)
        self._bind()
        joint = self.model.joint(OBJECT_JOINT)
        self._object = self.model.site(OBJECT_SITE).id
        self._object_qpos = slice(joint.qposadr[0], joint.qposadr[0] + 3)
        self._object_qvel = slice(joint.dofadr[0], joint.dofadr[0] + 6)
        self._measure_goal()

    def _agent_state(self) -> np.ndarray:
        return self.data.site_xpos[self._object].copy()

    def _achieved_goal(self) -> np.ndarray:
        return self._agent_state()

    def _enter_goal_configuration(self) -> None:
        self.data.qpos[self._object_qpos] += self._sampled_goal() - self.data.site_xpos[self._object]
        self.data.qvel[self._object_qvel] = 0.0
        self._mj.mj_forward(self.model, self.data)


class FetchSlideEnv(FetchPushEnv):
    """``FetchSlide-v4`` (slide the puck to a goal beyond the arm's reach) with FetchPush's adapter."""

    task = "fetch_slide"
    task_description = "Slide the puck to where it is in the goal."
    wrapped_id = "FetchSlide-v4"
    default_camera = FETCH_SLIDE_CAMERA
