"""Sawyer rope push (the paper's RopePush): push a 15-link rope into the configuration of a goal image.

Action: one straight push (x1, y1, x2, y2) in [-1, 1]^4, mapped onto the table rectangle given by the
x/y of ``end_effector.end_effector_bounds``; its z range is [pushing height, lifted height] of the
gripper's bottom (see :mod:`lerobot_indicator.envs.rope_sim` for the push primitive). Horizon 3 pushes.

Start: straight rope plus one random push; goal: ``goal_pushes`` (2) more random pushes, hidden from the
policy. Pairs come from a cache file (``cache_path``, see :mod:`lerobot_indicator.envs.rope_cache`) or
are generated on the fly. Between pushes the pusher rests where ``pusher_rest`` says
(``rope_scene.PUSHER_RESTS``): parked outside the camera's view by default, so the camera and goal images
show the table and the rope only; or lifted above the end of the last push that ran (the start's random
push, then the policy's; in the goal image, the last hidden goal push). The goal image is rendered by
putting the simulator in the goal configuration, rendering, and restoring the exact state
(:class:`MujocoGoalEnv`).

Observations (besides the shared camera keys): ``agent_pos`` = the 15 link centres xyz (45),
``goal_state`` = the same in the goal configuration (45), ``rope_xy`` = link centres xy (30) and its goal
``goal_rope_xy`` (30): the paper's 30-d goal, and the state-based compared pair under the goal-key rule
(``observation.rope_xy`` -> ``observation.goal_rope_xy``).
``info``: ``gt_achieved_goal`` / ``gt_desired_goal`` = link xy (30), ``gt_distance`` = their plain L2
distance in metres over all 30 numbers (not divided by the link count; the authors' definition),
``is_success`` = ``gt_distance <= epsilon`` (0.1, the paper's table).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from lerobot_indicator.envs.base import MujocoGoalEnv
from lerobot_indicator.envs.hardware import EndEffectorConfig, GoalCameraConfig
from lerobot_indicator.envs.rope_cache import ARRAY_KEYS, cache_params, generate_pair, load_cache
from lerobot_indicator.envs.rope_scene import RopeGeometry, build_rope_model, check_pusher_rest
from lerobot_indicator.envs.rope_sim import PushConfig, RopeSim
from lerobot_indicator.keys import GOAL_PREFIX, GT_ACHIEVED_GOAL, GT_DESIRED_GOAL

TASK_DESCRIPTION = "Push the rope into the configuration shown in the goal image."
TABLE_TOP_Z = RopeGeometry().table_top_z
ROPE_XY = "rope_xy"  # env key of the link xy positions; its goal is GOAL_PREFIX + ROPE_XY


def rope_camera_defaults() -> dict:
    """Top-down camera over the push region (square view ~1 m wide at the D435's 58 degree fovy)."""
    return {"name": "front", "pos": [0.0, 0.0, 1.7], "lookat": [0.0, 0.0, TABLE_TOP_Z]}


def rope_camera_config(**overrides) -> GoalCameraConfig:
    return GoalCameraConfig(**{**rope_camera_defaults(), **overrides})


def rope_end_effector_config() -> EndEffectorConfig:
    """Push region x, y in [-0.45, 0.45] m around the rope centre; pusher bottom 3 mm / 6 cm above the table.

    The numbers equal :class:`PushConfig`'s defaults, so default caches and default envs match.
    """
    c = PushConfig()
    return EndEffectorConfig(
        end_effector_bounds={"min": [*c.region_low, c.push_z], "max": [*c.region_high, c.lift_z]}
    )


def push_config_for(end_effector: EndEffectorConfig, goal_pushes: int = 2) -> PushConfig:
    """Push physics/sampling parameters of an env (also what a cache file must have been made with)."""
    lo, hi = end_effector.low, end_effector.high
    return PushConfig(
        region_low=(lo[0], lo[1]),
        region_high=(hi[0], hi[1]),
        push_z=lo[2],
        lift_z=hi[2],
        goal_pushes=goal_pushes,
    )


class RopePushEnv(MujocoGoalEnv):
    """See module docstring. ``reset(options={"cache_index": i})`` picks cached pair i (needs ``cache_path``)."""

    task = "rope_push"
    task_description = TASK_DESCRIPTION
    state_dim = 45
    action_names = ("push_start_x", "push_start_y", "push_end_x", "push_end_y")

    def __init__(
        self,
        camera: GoalCameraConfig | dict | None = None,
        end_effector: EndEffectorConfig | dict | None = None,
        fps: int = 2,
        epsilon: float = 0.1,
        goal_pushes: int = 2,
        cache_path: str | None = None,
        link_colours: str = "single",
        pusher_rest: str = "out_of_view",
        **kwargs,
    ):
        """``link_colours``: how the rope's links are drawn (``rope_scene.LINK_COLOURS``). ``pusher_rest``:
        where the pusher waits between pushes (``rope_scene.PUSHER_RESTS``).
        ``kwargs``: :class:`MujocoGoalEnv`'s (obs_type, render_mode, episode_length, eval_reward)."""
        check_pusher_rest(pusher_rest)
        self.link_colours = link_colours
        self.pusher_rest = pusher_rest
        if isinstance(camera, dict) or camera is None:
            camera = rope_camera_config(**(camera or {}))
        if isinstance(end_effector, dict):
            end_effector = EndEffectorConfig(**end_effector)
        end_effector = end_effector or rope_end_effector_config()
        self.push_config = push_config_for(end_effector, goal_pushes)
        super().__init__(camera=camera, end_effector=end_effector, fps=fps, epsilon=epsilon, **kwargs)
        self.sim = RopeSim(self.model, self.data, self.push_config)
        self.sim.reset_straight()
        n = self.push_config.geometry.n_links
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32)
        xy = gym.spaces.Box(-np.inf, np.inf, shape=(2 * n,), dtype=np.float32)
        self.observation_space = gym.spaces.Dict(
            {**self.observation_space.spaces, ROPE_XY: xy, GOAL_PREFIX + ROPE_XY: xy}
        )
        self.cache = None
        if cache_path is not None:
            self.cache = load_cache(cache_path, expected=cache_params(self.push_config, self.model.nq))
        self._goal_qpos = self.data.qpos.copy()
        self._goal_actions = np.zeros((0, 4))
        self._measure_goal()

    def _rest_pusher_at(self, xy: np.ndarray) -> None:
        """With ``pusher_rest="push_end"``, show the pusher above table point ``xy``; otherwise it stays
        parked out of view."""
        if self.pusher_rest == "push_end":
            self.sim.rest_pusher_above(xy)

    def push_end(self, action: np.ndarray) -> np.ndarray:
        """The table point (x, y) where a push action ends: where the pusher then rests."""
        return self.sim.action_to_points(action)[1]

    def _build_model(self):
        cam = self.camera_cfg
        camera = (cam.name, tuple(cam.pos), tuple(cam.lookat), cam.fovy_deg)
        return build_rope_model(
            self.push_config.geometry, camera, self.push_config.timestep, self.link_colours
        )

    # --- task hooks -----------------------------------------------------------------------------
    def _agent_state(self) -> np.ndarray:
        return self.sim.link_positions().reshape(-1)

    def _achieved_goal(self) -> np.ndarray:
        return self.sim.link_positions()[:, :2].reshape(-1)

    def _start_episode(self, options: dict[str, Any]) -> None:
        if self.cache is not None:
            n = len(self.cache["start_qpos"])
            i = options.get("cache_index")
            i = int(self.np_random.integers(n)) if i is None else int(i)
            if not 0 <= i < n:
                raise ValueError(f"reset option cache_index={i} out of range [0, {n})")
            pair = {k: self.cache[k][i] for k in ARRAY_KEYS}
        elif options.get("cache_index") is not None:
            raise ValueError("reset option cache_index needs an env made with cache_path")
        else:
            pair = generate_pair(self.sim, self.np_random, self.epsilon)
        self._goal_qpos, self._goal_actions = pair["goal_qpos"].copy(), pair["goal_actions"].copy()
        self.sim.set_qpos(pair["start_qpos"])
        self._rest_pusher_at(self.push_end(pair["start_action"]))

    def _enter_goal_configuration(self) -> None:
        self.sim.set_qpos(self._goal_qpos)
        # The hidden goal pushes go across a link, so the last one ran and the pusher rests after it.
        self._rest_pusher_at(self.push_end(self._goal_actions[-1]))

    def _apply_action(self, action) -> None:
        """One push. A skipped push (it cannot touch the rope, or it was undone) leaves the pusher where it
        was: the arm does not move, as in the authors' env, which skips such pushes."""
        action = np.asarray(action, dtype=np.float64).reshape(-1)
        resting = self.data.mocap_pos[self.sim.mocap_id, :2].copy()
        ran = self.sim.push(action)  # an undone push parks the pusher with the restored state
        self._rest_pusher_at(self.push_end(action) if ran else resting)

    def feature_names(self) -> dict[str, list[str]]:
        """Link centres as ``link<i>_x``, ``link<i>_y`` (, ``link<i>_z`` in the state), link 0 at one end."""
        links = range(self.push_config.geometry.n_links)
        xy = [f"link{i}_{axis}" for i in links for axis in "xy"]
        xyz = [f"link{i}_{axis}" for i in links for axis in "xyz"]
        names = super().feature_names()
        return {**names, "agent_pos": xyz, ROPE_XY: xy, GT_ACHIEVED_GOAL: xy, GT_DESIRED_GOAL: xy}

    @property
    def goal_push_actions(self) -> np.ndarray:
        """The hidden pushes that made the goal from the start (scripted oracles and tests only)."""
        return self._goal_actions.copy()

    def scripted_action(self) -> np.ndarray:
        """Data-collection expert (recorder's ``--policy=scripted``): the next hidden goal push, then no-op
        pushes. It reads hidden ground truth, so it is for demonstrations only, never a policy input."""
        if self._elapsed < len(self._goal_actions):
            return self._goal_actions[self._elapsed].astype(np.float32)
        return np.zeros(4, dtype=np.float32)

    def _get_obs(self) -> dict[str, Any]:
        obs = super()._get_obs()
        obs[ROPE_XY] = self._achieved_goal().astype(np.float32)
        obs[GOAL_PREFIX + ROPE_XY] = self._desired_goal.astype(np.float32)
        return obs
