"""Sawyer reach (the paper's "Visual Reacher"): move the gripper to a goal shown as an RGB-D image.

Action: end-effector displacement xyz in [-1, 1], times ``end_effector_step_sizes`` (<= 0.05 m), target
clipped to ``end_effector_bounds``; gripper orientation fixed. The mocap target is set from the
*measured* end-effector position, so the next state depends on what the camera sees, not on a hidden
target. Start and goal end-effector positions are uniform in the bounds cuboid; both are reached the same
deterministic way (home posture, mocap at the point, fixed settle), so starting at the goal reproduces the
goal observation bit for bit. Success: final distance <= ``epsilon``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from lerobot_indicator.envs.base import MujocoGoalEnv
from lerobot_indicator.envs.models import EE_SITE, MOCAP_BODY, SceneSpec, build_sawyer_table_model, home_qpos

TASK_DESCRIPTION = "Move the Sawyer's gripper to where it is in the goal image."
SETTLE_S = 0.15  # simulated time to bring the arm from home to a start / goal point (mean 1 mm error)


class SawyerReachEnv(MujocoGoalEnv):
    """See module docstring. ``agent_pos`` and ``gt_achieved_goal`` are the end-effector xyz.

    ``reset(options=...)`` may fix ``start_pos`` and/or ``goal_pos`` (xyz inside the bounds; tests, scripts).
    """

    task = "sawyer_reach"
    task_description = TASK_DESCRIPTION

    def __init__(self, light_render: bool = True, epsilon: float = 0.05, **kwargs):
        """``kwargs``: :class:`MujocoGoalEnv`'s (obs_type, camera, end_effector, fps, ...)."""
        self.light_render = light_render
        super().__init__(epsilon=epsilon, **kwargs)
        m = self.model
        self._site = m.site(EE_SITE).id
        self._mocap = m.body(MOCAP_BODY).mocapid[0]
        self._low = np.asarray(self.ee_cfg.low)
        self._high = np.asarray(self.ee_cfg.high)
        self._steps = np.asarray(self.ee_cfg.step_sizes)
        self._settle_substeps = max(1, round(SETTLE_S / m.opt.timestep))
        # Home state: arm at robosuite's home posture, mocap on the gripper with its orientation.
        mj = self._mj
        mj.mj_resetData(m, self.data)
        self.data.qpos[:] = home_qpos(m)
        mj.mj_forward(m, self.data)
        mj.mju_mat2Quat(self.data.mocap_quat[self._mocap], self.data.site_xmat[self._site])
        self.data.mocap_pos[self._mocap] = self.data.site_xpos[self._site]
        self._home_state = self.save_state()
        self._goal_target = self.data.site_xpos[self._site].copy()  # the sampled goal point (reset)
        self._measure_goal()

    def _build_model(self):
        cam = self.camera_cfg
        spec = SceneSpec(
            cameras=((cam.name, tuple(cam.pos), tuple(cam.lookat), cam.fovy_deg),),
            light_render=self.light_render,
        )
        return build_sawyer_table_model(spec)

    # --- task hooks (MujocoGoalEnv) -----------------------------------------------------------
    def _agent_state(self) -> np.ndarray:
        return self.data.site_xpos[self._site].copy()

    def _achieved_goal(self) -> np.ndarray:
        return self._agent_state()

    def _start_episode(self, options: dict[str, Any]) -> None:
        goal = self._point_option(options, "goal_pos")
        start = self._point_option(options, "start_pos")
        if goal is None:
            goal = self.np_random.uniform(self._low, self._high)
        if start is None:
            start = self.np_random.uniform(self._low, self._high)
            while np.linalg.norm(start - goal) <= self.epsilon:  # no episode starts solved
                start = self.np_random.uniform(self._low, self._high)
        self._goal_target = goal
        self._settle_at(start)

    def _enter_goal_configuration(self) -> None:
        # The goal is where the gripper settles, so goal_state is exactly what agent_pos reads there.
        self._settle_at(self._goal_target)

    def _apply_action(self, action) -> None:
        action = np.clip(np.asarray(action, dtype=np.float64).reshape(3), -1.0, 1.0)
        target = np.clip(self.data.site_xpos[self._site] + action * self._steps, self._low, self._high)
        self._glide_mocap(target, self.n_substeps)
        self._mj.mj_forward(self.model, self.data)  # derived quantities = f(state), as after a restore

    # --- helpers ------------------------------------------------------------------------------
    def _point_option(self, options: dict[str, Any], key: str) -> np.ndarray | None:
        if options.get(key) is None:
            return None
        point = np.asarray(options[key], dtype=np.float64)
        if point.shape != (3,) or np.any(point < self._low) or np.any(point > self._high):
            raise ValueError(f"reset option {key}={options[key]} must be xyz inside end_effector_bounds")
        return point

    def _settle_at(self, ee_pos: np.ndarray) -> None:
        """Home posture, mocap at ``ee_pos``, settle: one deterministic configuration per point."""
        self.restore_state(self._home_state)
        self._glide_mocap(ee_pos, self._settle_substeps)
        self.data.qvel[:] = 0.0  # episodes start at rest
        self.data.qacc_warmstart[:] = 0.0
        self.data.time = 0.0
        self._mj.mj_forward(self.model, self.data)

    def _glide_mocap(self, target: np.ndarray, n_substeps: int) -> None:
        """Move the weld target linearly to ``target`` over the first half of ``n_substeps``, then hold.

        A teleported target makes the stiff weld whip the arm through its null space.
        """
        start = self.data.mocap_pos[self._mocap].copy()
        n_ramp = max(1, n_substeps // 2)
        for k in range(1, n_ramp + 1):
            self.data.mocap_pos[self._mocap] = start + (target - start) * (k / n_ramp)
            self._mj.mj_step(self.model, self.data)
        if n_substeps > n_ramp:
            self._mj.mj_step(self.model, self.data, n_substeps - n_ramp)
