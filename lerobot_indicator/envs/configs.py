"""LeRobot ``EnvConfig`` types of the goal tasks: ``--env.type=sawyer_reach | rope_push`` (our scenes) and
``reacher | fetch_reach | fetch_push | fetch_slide`` (gymnasium / gymnasium-robotics envs, wrapped).

Only dataclasses and LeRobot imports here: this module is imported by every LeRobot CLI through plugin
discovery, so robosuite and MuJoCo are imported when an env is built, not before.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

from lerobot.configs import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.processor import PolicyProcessorPipeline
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_IMAGES, OBS_STATE, OBS_STR

from lerobot_indicator.envs.base import EVAL_REWARDS, OBS_TYPES
from lerobot_indicator.envs.hardware import EndEffectorConfig, GoalCameraConfig
from lerobot_indicator.envs.rope_scene import check_link_colours, check_pusher_rest
from lerobot_indicator.keys import GOAL_PREFIX, depth_key, goal_key, observed_cameras

GYM_NAMESPACE = "lerobot_indicator"
SAWYER_REACH_TASK = "SawyerReach-v0"


@dataclass
class GoalEnvConfig(EnvConfig):
    """Shared base of the goal tasks: obs type, camera, horizon, evaluation reward, feature maps."""

    task: str | None = None
    fps: int = 20
    episode_length: int = 25
    obs_type: str = "state"
    # Evaluation-only env reward: "success" (the paper's +-1 per step) or "final_distance" (-distance at
    # the last step, 0 before: lerobot-eval's avg_sum_reward is then minus the mean final distance).
    eval_reward: str = "success"
    render_mode: str = "rgb_array"
    camera: GoalCameraConfig = field(default_factory=GoalCameraConfig)
    state_dim: int = 3
    action_dim: int = 3
    # Also give the previous step's images as camera <cam>_prev, compared, with the goal image as its goal.
    previous_frame: bool = False

    def __post_init__(self):
        if isinstance(self.camera, dict):  # make_env_config("sawyer_reach", camera={...})
            self.camera = GoalCameraConfig(**self.camera)
        if self.obs_type not in OBS_TYPES:
            raise ValueError(f"obs_type: unknown {self.obs_type!r}; expected one of {OBS_TYPES}")
        if self.eval_reward not in EVAL_REWARDS:
            raise ValueError(f"eval_reward: unknown {self.eval_reward!r}; expected one of {EVAL_REWARDS}")
        if self.episode_length <= 0:
            raise ValueError(f"episode_length must be > 0, got {self.episode_length}")
        if self.fps <= 0:
            raise ValueError(f"fps must be > 0, got {self.fps}")
        if self.obs_type == "rgbd" and not self.camera.use_depth:
            raise ValueError("camera.use_depth must be true for obs_type 'rgbd'")
        if self.previous_frame and self.obs_type == "state":
            raise ValueError(
                "previous_frame gives the previous step's camera images: obs_type 'state' has none"
            )
        self.features = {
            ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(self.action_dim,)),
            "agent_pos": PolicyFeature(type=FeatureType.STATE, shape=(self.state_dim,)),
            "goal_state": PolicyFeature(type=FeatureType.STATE, shape=(self.state_dim,)),
        }
        self.features_map = {ACTION: ACTION, "agent_pos": OBS_STATE, "goal_state": goal_key(OBS_STATE)}
        h, w = self.camera.height, self.camera.width
        if self.obs_type in ("rgb", "rgbd"):
            for name in self._image_names:
                self.features[f"pixels/{name}"] = PolicyFeature(type=FeatureType.VISUAL, shape=(h, w, 3))
                self.features_map[f"pixels/{name}"] = f"{OBS_IMAGES}.{name}"
        if self.obs_type == "rgbd":
            for key in self.depth_keys:
                self.features[key] = PolicyFeature(type=FeatureType.VISUAL, shape=(h, w, 1))
                self.features_map[key] = f"{OBS_IMAGES}.{key}"

    @property
    def _image_names(self) -> list[str]:
        """The env's camera names with their goals: ``front``, ``goal_front`` (and ``front_prev``,
        ``goal_front_prev`` with ``previous_frame``)."""
        return [
            n for c in observed_cameras(self.camera.name, self.previous_frame) for n in (c, GOAL_PREFIX + c)
        ]

    @property
    def depth_keys(self) -> list[str]:
        """Env observation keys of the depth maps (``front_depth``, ``goal_front_depth``, ...)."""
        if self.obs_type != "rgbd":
            return []
        return [depth_key(n) for n in self._image_names]

    @property
    def package_name(self) -> str:
        return "lerobot_indicator.envs"

    @property
    def gym_id(self) -> str:
        return f"{GYM_NAMESPACE}/{self.task}"

    @property
    def gym_kwargs(self) -> dict:
        return {
            "obs_type": self.obs_type,
            "render_mode": self.render_mode,
            "camera": self.camera,
            "fps": self.fps,
            "max_episode_steps": self.episode_length,
            "episode_length": self.episode_length,
            "eval_reward": self.eval_reward,
            "previous_frame": self.previous_frame,
        }

    def get_env_processors(self):
        from lerobot_indicator.envs.processors import DepthToImagesProcessorStep

        steps = [DepthToImagesProcessorStep(depth_keys=self.depth_keys)] if self.depth_keys else []
        return PolicyProcessorPipeline(steps=steps), PolicyProcessorPipeline(steps=[])


@dataclass
class SawyerGoalEnvConfig(GoalEnvConfig):
    """Shared base of the Sawyer goal tasks: the goal-task fields plus end-effector control."""

    # Draw the robot with its primitive collision shapes for the camera: far fewer triangles than robosuite's
    # meshes for software GL to rasterise (docs/envs.md, docs/results/reach_env_speed.json).
    light_render: bool = True
    end_effector: EndEffectorConfig = field(default_factory=EndEffectorConfig)

    def __post_init__(self):
        if isinstance(self.end_effector, dict):
            self.end_effector = EndEffectorConfig(**self.end_effector)
        super().__post_init__()

    @property
    def gym_kwargs(self) -> dict:
        return {**super().gym_kwargs, "end_effector": self.end_effector, "light_render": self.light_render}


@EnvConfig.register_subclass("sawyer_reach")
@dataclass
class SawyerReachEnvConfig(SawyerGoalEnvConfig):
    """The paper's Visual Reacher (Sawyer): T=25, success within ``epsilon`` of the goal at the end."""

    task: str | None = SAWYER_REACH_TASK
    epsilon: float = 0.05

    def __post_init__(self):
        if self.epsilon <= 0:
            raise ValueError(f"epsilon must be > 0, got {self.epsilon}")
        super().__post_init__()

    @property
    def gym_kwargs(self) -> dict:
        return {**super().gym_kwargs, "epsilon": self.epsilon}


ROPE_PUSH_TASK = "RopePush-v0"


def _rope_camera() -> GoalCameraConfig:
    from lerobot_indicator.envs.rope_push import rope_camera_config

    return rope_camera_config()


def _rope_end_effector() -> EndEffectorConfig:
    from lerobot_indicator.envs.rope_push import rope_end_effector_config

    return rope_end_effector_config()


@EnvConfig.register_subclass("rope_push")
@dataclass
class RopePushEnvConfig(SawyerGoalEnvConfig):
    """The paper's RopePush: 3 pushes (x1, y1, x2, y2); success when the 30 link-xy numbers are within
    ``epsilon`` (plain L2, metres) of the goal's. ``end_effector`` bounds are the push region (x, y) and
    the pusher's [pushing, lifted] height (z). ``cache_path``: start/goal pairs from
    ``scripts/generate_rope_cache.py`` (generated on the fly when unset). ``link_colours``: "single" (one
    colour) or "tab20" (each link its own colour, as one version of the authors' env; render-only).
    ``pusher_rest``: "out_of_view" (the pusher is parked outside the images) or "push_end" (it rests above
    the end of the last push, so the images show it; render-only)."""

    task: str | None = ROPE_PUSH_TASK
    fps: int = 2
    episode_length: int = 3
    camera: GoalCameraConfig = field(default_factory=_rope_camera)
    end_effector: EndEffectorConfig = field(default_factory=_rope_end_effector)
    state_dim: int = 45
    action_dim: int = 4
    epsilon: float = 0.1
    goal_pushes: int = 2
    cache_path: str | None = None
    link_colours: str = "single"
    pusher_rest: str = "out_of_view"

    def __post_init__(self):
        check_link_colours(self.link_colours)
        check_pusher_rest(self.pusher_rest)
        if self.epsilon <= 0:
            raise ValueError(f"epsilon must be > 0, got {self.epsilon}")
        if self.goal_pushes < 1:
            raise ValueError(f"goal_pushes must be >= 1, got {self.goal_pushes}")
        if self.state_dim != 45 or self.action_dim != 4:
            raise ValueError(
                f"rope_push has state_dim 45 and action_dim 4, got {self.state_dim}, {self.action_dim}"
            )
        super().__post_init__()
        # Link xy (30) and its goal: the state-based compared pair under the goal-key rule.
        xy = PolicyFeature(type=FeatureType.STATE, shape=(30,))
        for key in ("rope_xy", GOAL_PREFIX + "rope_xy"):
            self.features[key] = xy
        self.features_map["rope_xy"] = f"{OBS_STR}.rope_xy"
        self.features_map[GOAL_PREFIX + "rope_xy"] = goal_key(f"{OBS_STR}.rope_xy")

    @property
    def gym_kwargs(self) -> dict:
        kwargs = {k: v for k, v in super().gym_kwargs.items() if k != "light_render"}
        return {
            **kwargs,
            "epsilon": self.epsilon,
            "goal_pushes": self.goal_pushes,
            "cache_path": self.cache_path,
            "link_colours": self.link_colours,
            "pusher_rest": self.pusher_rest,
        }


REACHER_TASK = "Reacher-v0"
FETCH_REACH_TASK = "FetchReach-v0"
FETCH_PUSH_TASK = "FetchPush-v0"
FETCH_SLIDE_TASK = "FetchSlide-v0"


def wrapped_task_camera(preset: str, **overrides) -> GoalCameraConfig:
    """Default camera of a wrapped gymnasium task (``preset``: reacher | fetch | fetch_slide), with overrides."""
    from lerobot_indicator.envs import fetch, reacher

    presets = {
        "reacher": reacher.REACHER_CAMERA,
        "fetch": fetch.FETCH_CAMERA,
        "fetch_slide": fetch.FETCH_SLIDE_CAMERA,
    }
    return GoalCameraConfig(**{**presets[preset], **overrides})


@dataclass
class GymGoalEnvConfig(GoalEnvConfig):
    """Shared base of the wrapped gymnasium goal tasks (``lerobot_indicator/envs/gym_goal.py``): the paper's
    T = 50; success when the ground-truth distance is within ``epsilon`` (m). ``fps`` is the wrapped env's
    control rate (fixed by it). With ``obs_type`` "state", or with images and ``env_state_with_images``, the env
    also gives ``observation.environment_state``: the wrapped env's observation without its goal
    (``env_state_dim`` numbers), never compared."""

    # What a task fixes: (state_dim, action_dim, env_state_dim) and its camera preset (wrapped_task_camera).
    dims: ClassVar[tuple[int, int, int]] = (3, 3, 10)
    camera_preset: ClassVar[str] = "fetch"
    episode_length: int = 50
    epsilon: float = 0.05
    env_state_dim: int = 10
    # Also give observation.environment_state with rgb / rgbd observations (a context input; never compared).
    env_state_with_images: bool = False

    def __post_init__(self):
        if isinstance(self.camera, dict):  # make_env_config("reacher", camera={...}) keeps the task's pose
            self.camera = wrapped_task_camera(self.camera_preset, **self.camera)
        if self.epsilon <= 0:
            raise ValueError(f"epsilon must be > 0, got {self.epsilon}")
        if (self.state_dim, self.action_dim, self.env_state_dim) != self.dims:
            raise ValueError(
                f"{self.type} has (state_dim, action_dim, env_state_dim) = {self.dims}, got "
                f"{(self.state_dim, self.action_dim, self.env_state_dim)}"
            )
        super().__post_init__()
        if self.obs_type == "state" or self.env_state_with_images:
            self.features["environment_state"] = PolicyFeature(
                type=FeatureType.ENV, shape=(self.env_state_dim,)
            )
            self.features_map["environment_state"] = OBS_ENV_STATE

    @property
    def gym_kwargs(self) -> dict:
        return {
            **super().gym_kwargs,
            "epsilon": self.epsilon,
            "env_state_with_images": self.env_state_with_images,
        }


@EnvConfig.register_subclass("reacher")
@dataclass
class ReacherEnvConfig(GymGoalEnvConfig):
    """The paper's Reacher: gymnasium's Reacher-v5, 100x100 RGB, T = 50, success within 0.01 m (fingertip)."""

    dims: ClassVar[tuple[int, int, int]] = (2, 2, 6)
    camera_preset: ClassVar[str] = "reacher"
    task: str | None = REACHER_TASK
    fps: int = 50
    obs_type: str = "rgb"
    epsilon: float = 0.01
    camera: GoalCameraConfig = field(default_factory=lambda: wrapped_task_camera("reacher"))
    state_dim: int = 2
    action_dim: int = 2
    env_state_dim: int = 6


@EnvConfig.register_subclass("fetch_reach")
@dataclass
class FetchReachEnvConfig(GymGoalEnvConfig):
    """The paper's FetchReach: gymnasium-robotics' FetchReach-v4, 100x100 RGB-D, T = 50, success within 0.05 m
    (grip point)."""

    task: str | None = FETCH_REACH_TASK
    fps: int = 25
    obs_type: str = "rgbd"
    camera: GoalCameraConfig = field(default_factory=lambda: wrapped_task_camera("fetch"))


@EnvConfig.register_subclass("fetch_push")
@dataclass
class FetchPushEnvConfig(GymGoalEnvConfig):
    """The paper's FetchPush: gymnasium-robotics' FetchPush-v4, state (block xyz compared), T = 50, success within
    0.05 m (block)."""

    dims: ClassVar[tuple[int, int, int]] = (3, 4, 25)
    task: str | None = FETCH_PUSH_TASK
    fps: int = 25
    camera: GoalCameraConfig = field(default_factory=lambda: wrapped_task_camera("fetch"))
    action_dim: int = 4
    env_state_dim: int = 25


@EnvConfig.register_subclass("fetch_slide")
@dataclass
class FetchSlideEnvConfig(FetchPushEnvConfig):
    """gymnasium-robotics' FetchSlide-v4 with FetchPush's adapter (not in the paper)."""

    camera_preset: ClassVar[str] = "fetch_slide"
    task: str | None = FETCH_SLIDE_TASK
    camera: GoalCameraConfig = field(default_factory=lambda: wrapped_task_camera("fetch_slide"))


__all__ = [
    "EndEffectorConfig",
    "EnvConfigFile",
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
    "load_env_config",
    "save_env_config",
]


# Derived in __post_init__, so never written to / read from a config file.
_DERIVED_FIELDS = ("features", "features_map")


@dataclass
class EnvConfigFile:
    """What an ``env_configs/*.yaml`` holds: the ``env`` section of a LeRobot pipeline config.

    The same file works as ``lerobot-eval --config_path=...`` / ``lerobot-train --config_path=...``
    (other sections come from the command line).
    """

    env: EnvConfig


def load_env_config(path: str | Path) -> EnvConfig:
    """Parse and validate an env config file; errors name the offending field."""
    import draccus

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"env config file not found: {path}")
    try:
        return draccus.parse(EnvConfigFile, config_path=str(path), args=[]).env
    except (draccus.utils.ParsingError, draccus.utils.DecodingError) as err:
        cause = err.__cause__ or err.__context__
        detail = f"{err}" + (f": {cause}" if cause is not None else "")
        raise ValueError(f"{path}: invalid env config: {detail}") from err


def save_env_config(cfg: EnvConfig, path: str | Path) -> None:
    """Write ``cfg`` as a config file :func:`load_env_config` (and ``--config_path``) reads back."""
    import draccus
    import yaml

    encoded = draccus.encode(cfg)
    for key in _DERIVED_FIELDS:
        encoded.pop(key, None)
    encoded = {"type": cfg.type, **encoded}
    Path(path).write_text(yaml.safe_dump({"env": encoded}, sort_keys=False))
