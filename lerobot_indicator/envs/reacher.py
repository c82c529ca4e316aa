"""The paper's Reacher: gymnasium's ``Reacher-v5`` (a torque-driven two-link arm in the plane) as a goal task.

Start and goal are what ``Reacher-v5``'s reset draws (arm near straight, target uniform in a disk of radius
0.2 m); a start already within ``epsilon`` of the goal is redrawn. Action: the two joint torques in
[-1, 1] (``Reacher-v5``'s ``step``, 2 substeps of 0.01 s: 50 steps/s). The goal configuration puts the arm's
joints at the goal's two-link inverse kinematics (one fixed elbow branch, elbow angle >= 0: the other branch
reaches the same point and renders differently), so the goal image shows the arm touching the target. The
red target sphere is never drawn.

Observations (besides the shared camera keys): ``agent_pos`` = the fingertip xy (m), ``goal_state`` = the
fingertip xy in the goal configuration (the paper's 2-d goal); with ``obs_type="state"`` or
``env_state_with_images`` also
``environment_state`` = cos and sin of the two joint angles and their velocities (6): never compared, the
policy's default context input (a torque-driven arm's velocities). ``info``:
``gt_achieved_goal`` / ``gt_desired_goal`` = fingertip xy now / in the goal configuration, ``gt_distance``
their distance, ``is_success`` = ``gt_distance <= epsilon`` (0.01 m, the paper's table).
"""

from __future__ import annotations

import numpy as np

from lerobot_indicator.envs.gym_goal import GymGoalEnv

TASK_DESCRIPTION = "Move the arm's fingertip to where it is in the goal image."
# Nearly top-down over the arm's reach disk (0.21 m), the image's up towards +y.
REACHER_CAMERA = {"name": "front", "pos": [0.0, -0.07, 0.45], "lookat": [0.0, 0.0, 0.0], "use_depth": True}


def two_link_ik(target_xy: np.ndarray, l1: float, l2: float, elbow_limit: float) -> np.ndarray:
    """Joint angles (shoulder, elbow) putting a planar two-link arm's tip at ``target_xy`` (base at the origin).

    The elbow branch is fixed (elbow angle in [0, pi]); a target closer than the elbow's joint limit allows is
    reached as closely as the limit lets, and one beyond the arm's reach on the line towards it.
    """
    x, y = float(target_xy[0]), float(target_xy[1])
    cos_elbow = (x * x + y * y - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
    elbow = min(float(np.arccos(np.clip(cos_elbow, -1.0, 1.0))), elbow_limit)
    shoulder = np.arctan2(y, x) - np.arctan2(l2 * np.sin(elbow), l1 + l2 * np.cos(elbow))
    return np.array([shoulder, elbow])


class ReacherEnv(GymGoalEnv):
    """See module docstring."""

    task = "reacher"
    task_description = TASK_DESCRIPTION
    wrapped_id = "Reacher-v5"
    state_dim = 2
    action_dim = 2
    env_state_dim = 6
    robot_type = "reacher"
    state_names = achieved_goal_names = ("x", "y")
    action_names = ("joint0_torque", "joint1_torque")
    environment_state_names = (
        "cos_joint0", "cos_joint1", "sin_joint0", "sin_joint1", "joint0_vel", "joint1_vel"
    )  # fmt: skip
    marker_geoms = ("target",)
    default_camera = REACHER_CAMERA

    def __init__(self, obs_type: str = "rgb", epsilon: float = 0.01, **kwargs):
        """``kwargs``: :class:`GymGoalEnv`'s (camera, fps, env_state_with_images, render_mode, episode_length,
        eval_reward)."""
        super().__init__(obs_type=obs_type, epsilon=epsilon, **kwargs)
        m = self.model
        self._tip = m.body("fingertip").id
        self._base_xy = m.body("body0").pos[:2].copy()
        self._l1 = float(np.linalg.norm(m.body("body1").pos[:2]))
        self._l2 = float(np.linalg.norm(m.body("fingertip").pos[:2]))
        self._elbow_limit = float(m.jnt_range[m.joint("joint1").id, 1])
        self._arm_qpos = [m.joint(name).qposadr[0] for name in ("joint0", "joint1")]
        self._arm_qvel = [m.joint(name).dofadr[0] for name in ("joint0", "joint1")]
        self._measure_goal()

    def _agent_state(self) -> np.ndarray:
        return self.data.xpos[self._tip, :2].copy()

    def _achieved_goal(self) -> np.ndarray:
        return self._agent_state()

    def joints_reaching(self, xy: np.ndarray) -> np.ndarray:
        """Joint angles (shoulder, elbow) putting the fingertip at world ``xy``: the goal configuration's IK."""
        return two_link_ik(np.asarray(xy) - self._base_xy, self._l1, self._l2, self._elbow_limit)

    def _enter_goal_configuration(self) -> None:
        self.data.qpos[self._arm_qpos] = self.joints_reaching(self._sampled_goal())
        self.data.qvel[self._arm_qvel] = 0.0
        self._mj.mj_forward(self.model, self.data)

    def environment_state(self) -> np.ndarray:
        angles = self.data.qpos[self._arm_qpos]
        return np.concatenate([np.cos(angles), np.sin(angles), self.data.qvel[self._arm_qvel]])
