"""Shared gymnasium base for goal-conditioned MuJoCo tasks with image goals (reach, rope push, and the
gymnasium goal envs wrapped by :mod:`lerobot_indicator.envs.gym_goal`).

What every task shares lives here: ``reset()`` / ``step()``, the observation dict of docs/conventions.md,
the ground-truth ``info``, RGB-D camera rendering, rendering the goal observation by putting the simulator
in the goal configuration and restoring the exact state afterwards, seeding, and ``render()`` for eval
videos. A task fills the hooks of :class:`MujocoGoalEnv`: the model (or a model and data it already has),
the episode's start and goal, the goal configuration, the action, and what its state and achieved goal are.

Observation dict (``obs_type``: ``state`` | ``rgb`` | ``rgbd``):
    agent_pos            float32 (D,)      proprio (reach: end-effector xyz)
    goal_state           float32 (D,)      the same quantity in the goal configuration
    pixels/<cam>         uint8 HxWx3       rgb, rgbd
    pixels/goal_<cam>    uint8 HxWx3       rgb, rgbd
    <cam>_depth          uint16 HxWx1 mm   rgbd (top level: LeRobot's preprocess_observation drops nested
    goal_<cam>_depth     uint16 HxWx1 mm    non-``pixels`` dicts; the env processor moves them to images)

With ``previous_frame`` the images of the step before (at reset: the start's own) come too, as camera
``<cam>_prev`` (``pixels/<cam>_prev``, ``<cam>_prev_depth``), with the goal image again as its goal: a compared
key like the current one, so the compared observation holds the motion that one image of a torque-driven arm
lacks, and the goal asks for the goal configuration at rest.
"""

from __future__ import annotations

import abc
from typing import Any

import gymnasium as gym
import numpy as np

from lerobot_indicator.envs.hardware import EndEffectorConfig, GoalCameraConfig
from lerobot_indicator.envs.models import RENDER_GROUP
from lerobot_indicator.keys import (
    GOAL_PREFIX,
    GT_ACHIEVED_GOAL,
    GT_DESIRED_GOAL,
    GT_DISTANCE,
    depth_key,
    observed_cameras,
)

OBS_TYPES = ("state", "rgb", "rgbd")
# Evaluation-only env reward (training never uses it: the indicator reward comes from observations).
# "success": R+ within epsilon else R- at every step (the paper's evaluation reward).
# "final_distance": 0, then -gt_distance at step episode_length, so lerobot-eval's avg_sum_reward is
# minus the mean final distance to the goal.
EVAL_REWARDS = ("success", "final_distance")


def _as(cls, value):
    if value is None:
        return cls()
    if isinstance(value, dict):
        return cls(**value)
    if not isinstance(value, cls):
        raise TypeError(f"expected {cls.__name__} or dict, got {type(value).__name__}")
    return value


class MujocoGoalEnv(gym.Env, abc.ABC):
    """Goal-conditioned MuJoCo env whose goal observation is rendered from the goal configuration.

    The base class runs the episode and a task fills the hooks, as robosuite's tasks fill
    ``_load_model`` / ``_reset_internal``:

    ``reset(seed, options)``: seed ``np_random``; ``_start_episode(options)`` (the task draws start and
    goal and puts the simulator in the start configuration); ``_render_goal_observation()`` (enter the
    goal configuration with ``_enter_goal_configuration()``, measure ``goal_state`` = ``_agent_state()``
    and ``gt_desired_goal`` = ``_achieved_goal()`` there, render the goal images, restore the exact
    state); return the observation and ``info``.

    ``step(action)``: ``_apply_action(action)``; return the observation, the evaluation reward
    (``EVAL_REWARDS``), never ``terminated`` (the time limit truncates) and ``info``: ``gt_achieved_goal`` =
    ``_achieved_goal()``, ``gt_desired_goal``, ``gt_distance`` (their L2 distance) and ``is_success``
    (``gt_distance <= epsilon``).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}
    state_dim: int = 3
    # Geom groups the task camera draws (sites are never drawn).
    render_geom_groups: tuple[int, ...] = (RENDER_GROUP,)
    # The robot a recorded dataset names in its meta/info.json (``robot_type``).
    robot_type: str = "sawyer"
    # Per-dimension names of agent_pos, of the ground-truth achieved goal and of the action (dataset ``names``).
    state_names: tuple[str, ...] = ("x", "y", "z")
    achieved_goal_names: tuple[str, ...] = ("x", "y", "z")
    action_names: tuple[str, ...] = ("delta_x", "delta_y", "delta_z")

    def __init__(
        self,
        obs_type: str = "state",
        camera: GoalCameraConfig | dict | None = None,
        end_effector: EndEffectorConfig | dict | None = None,
        fps: int = 20,
        render_mode: str | None = "rgb_array",
        episode_length: int | None = None,
        eval_reward: str = "success",
        epsilon: float = 0.05,
        previous_frame: bool = False,
    ):
        if epsilon <= 0:
            raise ValueError(f"epsilon must be > 0, got {epsilon}")
        self.epsilon = float(epsilon)  # success: gt_distance <= epsilon
        if obs_type not in OBS_TYPES:
            raise ValueError(f"obs_type: unknown {obs_type!r}; expected one of {OBS_TYPES}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode: only 'rgb_array' is supported, got {render_mode!r}")
        if fps <= 0:
            raise ValueError(f"fps must be > 0, got {fps}")
        if eval_reward not in EVAL_REWARDS:
            raise ValueError(f"eval_reward: unknown {eval_reward!r}; expected one of {EVAL_REWARDS}")
        if eval_reward == "final_distance" and not episode_length:
            raise ValueError("eval_reward 'final_distance' needs episode_length")
        self.episode_length, self.eval_reward = episode_length, eval_reward
        self._elapsed = 0
        self.camera_cfg = _as(GoalCameraConfig, camera)
        self.ee_cfg = _as(EndEffectorConfig, end_effector)
        if obs_type == "rgbd" and not self.camera_cfg.use_depth:
            raise ValueError("obs_type 'rgbd' needs camera.use_depth: true")
        if previous_frame and obs_type == "state":
            raise ValueError(
                "previous_frame gives the previous step's camera images: obs_type 'state' has none"
            )
        self.obs_type = obs_type
        self.previous_frame = previous_frame
        # Camera images of the last observation given, and those the next observation shows as the previous.
        self._latest_frames: dict[str, np.ndarray] | None = None
        self._previous_frames: dict[str, np.ndarray] | None = None
        self.render_mode = render_mode
        self.fps = fps
        self.metadata = {**self.metadata, "render_fps": fps}

        import mujoco

        from lerobot_indicator.envs.rendering import RGBDRenderer

        self._mj = mujoco
        self.model, self.data = self._build_simulation()
        self.n_substeps = max(1, round(1.0 / (fps * self.model.opt.timestep)))
        self._state_spec = mujoco.mjtState.mjSTATE_INTEGRATION
        self._state_buf = np.empty(mujoco.mj_stateSize(self.model, self._state_spec))
        self._renderer: RGBDRenderer | None = None
        self._renderer_cls = RGBDRenderer
        # The goal, measured in the goal configuration (_measure_goal); a task's __init__ measures its
        # initial configuration, so state observations and info are defined before the first reset.
        self._goal_obs: dict[str, np.ndarray] = {}
        self._goal_state: np.ndarray | None = None
        self._desired_goal: np.ndarray | None = None

        cam = self.camera_cfg
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
        spaces: dict[str, gym.Space] = {
            "agent_pos": gym.spaces.Box(-np.inf, np.inf, shape=(self.state_dim,), dtype=np.float32),
            "goal_state": gym.spaces.Box(-np.inf, np.inf, shape=(self.state_dim,), dtype=np.float32),
        }
        names = [n for c in self.camera_names for n in (c, GOAL_PREFIX + c)]
        if obs_type in ("rgb", "rgbd"):
            img = gym.spaces.Box(0, 255, shape=(cam.height, cam.width, 3), dtype=np.uint8)
            spaces["pixels"] = gym.spaces.Dict(dict.fromkeys(names, img))
        if obs_type == "rgbd":
            depth = gym.spaces.Box(
                0, np.iinfo(np.uint16).max, shape=(cam.height, cam.width, 1), dtype=np.uint16
            )
            spaces.update({depth_key(n): depth for n in names})
        self.observation_space = gym.spaces.Dict(spaces)

    @property
    def camera_names(self) -> list[str]:
        """The observation's camera names: the task camera, and ``<cam>_prev`` with ``previous_frame``."""
        return observed_cameras(self.camera_cfg.name, self.previous_frame)

    # --- what a task provides -------------------------------------------------------------------
    def _build_model(self):
        """Compiled MjModel with a fixed camera named ``camera_cfg.name`` (or see :meth:`_camera`)."""
        raise NotImplementedError(f"{type(self).__name__} must implement _build_model or _build_simulation")

    def _build_simulation(self):
        """(MjModel, MjData) the task runs on: a fresh ``MjData`` of :meth:`_build_model` by default; a task
        wrapping a simulator that already exists returns that simulator's model and data."""
        model = self._build_model()
        return model, self._mj.MjData(model)

    def _camera(self):
        """What the task camera looks through: the name of a fixed camera of the model (by default
        ``camera_cfg.name``) or a :class:`~lerobot_indicator.envs.rendering.FreeCamera`."""
        return self.camera_cfg.name

    @abc.abstractmethod
    def _start_episode(self, options: dict[str, Any]) -> None:
        """Draw this episode's start and goal (from ``self.np_random`` and the reset ``options``) and put
        the simulator in the start configuration."""

    @abc.abstractmethod
    def _enter_goal_configuration(self) -> None:
        """Put the simulator in this episode's goal configuration (the caller restores the state)."""

    @abc.abstractmethod
    def _apply_action(self, action: np.ndarray) -> None:
        """Move the simulator by one action."""

    @abc.abstractmethod
    def _agent_state(self) -> np.ndarray:
        """``agent_pos`` of the current configuration (float64); ``goal_state`` is its value at the goal."""

    @abc.abstractmethod
    def _achieved_goal(self) -> np.ndarray:
        """Ground-truth achieved goal of the current configuration (float64); ``gt_desired_goal`` is its
        value at the goal."""

    # --- gymnasium API ---------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self._elapsed = 0
        self._previous_frames = None
        self._start_episode(options or {})
        self._render_goal_observation()
        return self._get_obs(), self._info()

    def step(self, action):
        self._previous_frames = self._latest_frames
        self._apply_action(action)
        self._elapsed += 1
        info = self._info()
        if self.eval_reward == "final_distance":
            reward = -float(info[GT_DISTANCE]) if self._elapsed == self.episode_length else 0.0
        else:
            reward = 1.0 if info["is_success"] else -1.0
        return self._get_obs(), reward, False, False, info

    # --- shared machinery ------------------------------------------------------------------------
    @property
    def renderer(self):
        if self._renderer is None:
            s = self.camera_cfg.supersample
            self._renderer = self._renderer_cls(
                self.model,
                self.camera_cfg.width * s,
                self.camera_cfg.height * s,
                geom_groups=self.render_geom_groups,
            )
        return self._renderer

    def save_state(self) -> np.ndarray:
        """Full integration state (qpos, qvel, act, mocap, ctrl, warm start, time, ...)."""
        self._mj.mj_getState(self.model, self.data, self._state_buf, self._state_spec)
        return self._state_buf.copy()

    def restore_state(self, state: np.ndarray) -> None:
        """Restore a :meth:`save_state` snapshot; derived quantities are recomputed by ``mj_forward``."""
        self._mj.mj_setState(self.model, self.data, state, self._state_spec)
        self._mj.mj_forward(self.model, self.data)

    def camera_observation(self) -> dict[str, np.ndarray]:
        """The camera images of the current simulator state, keyed as in the observation (no goal images)."""
        return self._camera_obs()

    def _render_camera(self, depth: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """(RGB, depth in metres or None) at the camera's size: rendered ``supersample`` times larger and
        area-averaged down when asked (depth averaged in metres, before the sensor's range test).

        ``mj_forward`` first: after ``mj_step`` the derived positions MuJoCo draws from are one substep
        older than the state, so a render without it would not be a function of the state alone."""
        from lerobot_indicator.envs.rendering import area_downsample

        s = self.camera_cfg.supersample
        self._mj.mj_forward(self.model, self.data)
        rgb, depth_m = self.renderer.render(self.data, self._camera(), depth=depth)
        return area_downsample(rgb, s), None if depth_m is None else area_downsample(depth_m, s)

    def _camera_obs(self, prefix: str = "") -> dict[str, np.ndarray]:
        if self.obs_type == "state":
            return {}
        cam = self.camera_cfg
        rgb, depth_m = self._render_camera(depth=self.obs_type == "rgbd")
        out = {prefix + cam.name: rgb}
        if depth_m is not None:
            from lerobot_indicator.envs.rendering import metres_to_uint16_mm

            mm = metres_to_uint16_mm(depth_m, cam.depth_min_m, cam.depth_max_m)
            out[depth_key(prefix + cam.name)] = mm[..., None]
        return out

    def _render_goal_observation(self) -> None:
        """In the goal configuration, measure the goal (``goal_state``, ``gt_desired_goal``) and render the
        goal camera images; then restore the exact simulator state."""
        state = self.save_state()
        self._enter_goal_configuration()
        self._measure_goal()
        self._goal_obs = self._camera_obs(prefix=GOAL_PREFIX)
        self.restore_state(state)

    def _measure_goal(self) -> None:
        """Take the current configuration as the goal's: ``goal_state`` and ``gt_desired_goal``."""
        self._goal_state = self._agent_state()
        self._desired_goal = self._achieved_goal()

    def _get_obs(self) -> dict[str, Any]:
        obs: dict[str, Any] = {
            "agent_pos": self._agent_state().astype(np.float32),
            "goal_state": self._goal_state.astype(np.float32),
        }
        if self.obs_type == "state":
            return obs
        current = self._camera_obs()
        shown = [current]
        if self.previous_frame:  # the images before this step's action; at reset, the start's own
            shown.append(current if self._previous_frames is None else self._previous_frames)
        self._latest_frames = current
        cam, goal_cam = self.camera_cfg.name, GOAL_PREFIX + self.camera_cfg.name
        obs["pixels"] = {}
        for name, images in zip(self.camera_names, shown, strict=True):
            obs["pixels"][name] = images[cam]
            obs["pixels"][GOAL_PREFIX + name] = self._goal_obs[goal_cam].copy()
            if self.obs_type == "rgbd":
                obs[depth_key(name)] = images[depth_key(cam)]
                obs[depth_key(GOAL_PREFIX + name)] = self._goal_obs[depth_key(goal_cam)].copy()
        return obs

    def _info(self) -> dict[str, Any]:
        achieved = self._achieved_goal()
        distance = float(np.linalg.norm(achieved - self._desired_goal))
        return {
            GT_ACHIEVED_GOAL: achieved.astype(np.float32),
            GT_DESIRED_GOAL: self._desired_goal.astype(np.float32),
            GT_DISTANCE: np.float32(distance),
            "is_success": bool(distance <= self.epsilon),
        }

    def feature_names(self) -> dict[str, list[str]]:
        """Per-dimension names of the vector observations, the ground truth and the action, by env key (the
        recorder's dataset ``names``; a ``goal_<key>`` takes the names of ``<key>``)."""
        return {
            "agent_pos": list(self.state_names),
            GT_ACHIEVED_GOAL: list(self.achieved_goal_names),
            GT_DESIRED_GOAL: list(self.achieved_goal_names),
            GT_DISTANCE: ["distance"],
            "action": list(self.action_names),
        }

    def render(self) -> np.ndarray:
        """HxWx3 uint8 frame of the task camera (eval videos)."""
        rgb, _ = self._render_camera(depth=False)
        return rgb

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
