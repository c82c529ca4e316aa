"""Goal envs of gymnasium / gymnasium-robotics under this plugin's task contract (docs/conventions.md).

:class:`GymGoalEnv` wraps a MuJoCo env that already exists (``gym.make(<id>).unwrapped``): it runs on that
env's own ``MjModel`` / ``MjData``, draws start and goal with that env's ``reset`` and moves it with that
env's ``step``, and adds what :class:`~lerobot_indicator.envs.base.MujocoGoalEnv` gives every task here:
the observation dict (state, RGB or RGB-D through the same renderer and uint16-mm depth as the Sawyer
task), goal images rendered in the goal configuration with the exact state restored afterwards, and the
ground-truth ``info``. The wrapped env's own goal markers (a target geom, a target site, a mocap body's
geoms) are never drawn, in observations and goals alike: they would show the goal in every observation.

A task names the wrapped env and its markers and fills four hooks: ``_agent_state`` (the compared state),
``_achieved_goal`` (ground truth), ``_enter_goal_configuration`` and ``environment_state`` (the wrapped
env's observation without its goal part, given with ``obs_type="state"`` or ``env_state_with_images``: no
goal key, so never compared; the policy's default context input with state, docs/conventions.md).
"""

from __future__ import annotations

import abc
import contextlib
import io
from typing import Any

import gymnasium as gym
import numpy as np

from lerobot_indicator.envs.base import MujocoGoalEnv, _as
from lerobot_indicator.envs.hardware import GoalCameraConfig

# Geom groups gymnasium's own renderer draws (MuJoCo's default ``mjvOption``) and the group markers move to.
GYM_GEOM_GROUPS = (0, 1, 2)
MARKER_GROUP = 5
# Redraws of the wrapped env's reset before giving up on a start that is not already within epsilon.
MAX_START_DRAWS = 100


def make_wrapped_env(env_id: str, **kwargs) -> gym.Env:
    """``gym.make(env_id, **kwargs).unwrapped`` without rendering; gymnasium-robotics ids are registered first.

    gymnasium-robotics 1.4.2 prints a notice about its Adroit hand envs on import (always, for that version);
    it concerns none of the envs used here, so the import's stderr is discarded.
    """
    if env_id not in gym.registry:
        with contextlib.redirect_stderr(io.StringIO()):
            import gymnasium_robotics

        gym.register_envs(gymnasium_robotics)
    return gym.make(env_id, render_mode=None, **kwargs).unwrapped


class GymGoalEnv(MujocoGoalEnv):
    """A wrapped gymnasium MuJoCo env as a goal task (module docstring).

    Class attributes a task sets: ``wrapped_id`` (gymnasium id), ``state_dim`` (``agent_pos``),
    ``action_dim``, ``env_state_dim`` (``environment_state``), ``marker_geoms`` /
    ``marker_bodies`` (geoms, or all geoms of bodies, hidden from the camera) and ``default_camera``
    (``GoalCameraConfig`` fields). The camera is a free camera placed by ``camera.pos`` / ``camera.lookat``
    with ``camera.fovy_deg``. ``fps`` is the wrapped env's control rate, ``1 / dt``.
    """

    wrapped_id: str
    action_dim: int
    env_state_dim: int
    # Per-dimension names of ``environment_state`` (the wrapped env's observation vector, in its order).
    environment_state_names: tuple[str, ...]
    marker_geoms: tuple[str, ...] = ()
    marker_bodies: tuple[str, ...] = ()
    default_camera: dict[str, Any] = {}
    render_geom_groups = GYM_GEOM_GROUPS

    def __init__(
        self,
        obs_type: str = "state",
        camera: GoalCameraConfig | dict | None = None,
        fps: int | None = None,
        epsilon: float = 0.05,
        env_state_with_images: bool = False,
        **kwargs,
    ):
        """``env_state_with_images``: give ``environment_state`` with rgb / rgbd observations too.
        ``kwargs``: :class:`MujocoGoalEnv`'s (render_mode, episode_length, eval_reward)."""
        from lerobot_indicator.envs.rendering import FreeCamera

        self.inner = make_wrapped_env(self.wrapped_id)
        rate = round(1.0 / self.inner.dt)
        if fps is not None and fps != rate:
            raise ValueError(f"fps: {self.wrapped_id} runs at {rate} steps/s (1 / dt), got fps={fps}")
        if camera is None or isinstance(camera, dict):
            camera = GoalCameraConfig(**{**self.default_camera, **(camera or {})})
        camera = _as(GoalCameraConfig, camera)
        super().__init__(obs_type=obs_type, camera=camera, fps=rate, epsilon=epsilon, **kwargs)
        self._free_camera = FreeCamera.looking_from(self.camera_cfg.pos, self.camera_cfg.lookat)
        self.model.vis.global_.fovy = self.camera_cfg.fovy_deg  # the free camera's field of view
        for name in self.marker_geoms:
            self.model.geom_group[self.model.geom(name).id] = MARKER_GROUP
        for name in self.marker_bodies:
            self.model.geom_group[self.model.geom_bodyid == self.model.body(name).id] = MARKER_GROUP
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(self.action_dim,), dtype=np.float32)
        self.gives_env_state = obs_type == "state" or env_state_with_images
        if self.gives_env_state:
            env_state = gym.spaces.Box(-np.inf, np.inf, shape=(self.env_state_dim,), dtype=np.float32)
            self.observation_space = gym.spaces.Dict(
                {**self.observation_space.spaces, "environment_state": env_state}
            )
        # A defined state before the first reset; a task's __init__ ends with _measure_goal(), as the others do.
        self._inner_obs = self.inner.reset(seed=0)[0]

    # --- what a wrapped task provides -------------------------------------------------------------
    @abc.abstractmethod
    def environment_state(self) -> np.ndarray:
        """The wrapped env's observation of the current state without its goal part (float64)."""

    def _sampled_goal(self) -> np.ndarray:
        """The goal the wrapped env drew at its last reset."""
        return np.asarray(self.inner.goal, dtype=np.float64)

    def _inner_action(self, action: np.ndarray) -> np.ndarray:
        """Our action (``action_dim``, clipped to [-1, 1]) as the wrapped env's ``step`` takes it."""
        return action

    # --- MujocoGoalEnv hooks ----------------------------------------------------------------------
    def _build_simulation(self):
        return self.inner.model, self.inner.data

    def _camera(self):
        return self._free_camera

    def _start_episode(self, options: dict[str, Any]) -> None:
        # The wrapped env draws from this env's generator, so reset(seed=...) fixes its draws too.
        self.inner.np_random = self.np_random
        for _ in range(MAX_START_DRAWS):
            self._inner_obs = self.inner.reset()[0]
            if np.linalg.norm(self._achieved_goal() - self._sampled_goal()) > self.epsilon:
                return
        raise RuntimeError(
            f"{self.wrapped_id}: {MAX_START_DRAWS} resets all started within epsilon of the goal"
        )

    def _apply_action(self, action) -> None:
        action = np.clip(np.asarray(action, dtype=np.float32).reshape(self.action_dim), -1.0, 1.0)
        self._inner_obs = self.inner.step(self._inner_action(action))[0]

    def feature_names(self) -> dict[str, list[str]]:
        names = super().feature_names()
        return {**names, "environment_state": list(self.environment_state_names)}

    def _get_obs(self) -> dict[str, Any]:
        obs = super()._get_obs()
        if self.gives_env_state:
            obs["environment_state"] = self.environment_state().astype(np.float32)
        return obs

    def close(self) -> None:
        super().close()
        self.inner.close()
