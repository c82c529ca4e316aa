"""What drives the robot while recording: random, a scripted expert (optionally noisy), or a checkpoint.

Randomness (random actions, ``noisy_scripted``'s noise, a stochastic checkpoint policy) is reseeded at
the start of every episode from ``(seed, episode index)`` (:func:`episode_seed`), so episode ``e`` gets
the same actions whether it is recorded in one run or after any number of ``--resume`` runs.

The scripted expert reads the env's *ground truth* (``gt_achieved_goal``/``gt_desired_goal``), so it
is only a data-collection expert (demonstrations, coverage): nothing trained from images may use it.
An env can provide its own expert as a ``scripted_action()`` method; otherwise the proportional
end-effector controller below is used for envs whose action is an end-effector displacement.
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

import gymnasium as gym
import numpy as np
import torch

from lerobot_indicator.keys import GT_ACHIEVED_GOAL, GT_DESIRED_GOAL

BUILTIN_POLICIES = ("random", "scripted", "noisy_scripted")


def episode_seed(seed: int, episode: int) -> int:
    """The action-noise seed of episode ``episode``: a stream of its own, independent of the env's reset
    seed ``seed + episode`` (which seeds the env's own generator with that very integer)."""
    return int(np.random.SeedSequence([seed, episode]).generate_state(1)[0])


class ActionSource(Protocol):
    def reset(self, seed: int | None = None) -> None:
        """Start an episode; ``seed`` (see :func:`episode_seed`) reseeds any randomness."""

    def __call__(self, observation: dict, info: dict) -> np.ndarray:
        """Batched env observation/info (one env) -> action of shape (1, action_dim)."""


class RandomActions:
    def __init__(self, action_space: gym.spaces.Box, seed: int):
        self.space = action_space
        self.space.seed(seed)

    def reset(self, seed: int | None = None) -> None:
        if seed is not None:
            self.space.seed(seed)

    def __call__(self, observation: dict, info: dict) -> np.ndarray:
        return self.space.sample()


class ScriptedActions:
    """Proportional controller toward the goal (``gain`` * error / step size, clipped), plus noise.

    ``noise_std`` adds Gaussian noise in action units (``noisy_scripted``), for state coverage.
    """

    def __init__(self, vec_env: gym.vector.VectorEnv, noise_std: float, seed: int, gain: float = 1.0):
        self.vec_env, self.noise_std, self.gain = vec_env, noise_std, gain
        self.rng = np.random.default_rng(seed)
        self.low, self.high = vec_env.single_action_space.low, vec_env.single_action_space.high
        self.env_expert = _has_method(vec_env, "scripted_action")
        self.steps = None
        if not self.env_expert:
            try:
                ee_cfg = vec_env.get_attr("ee_cfg")[0]
            except AttributeError:
                raise ValueError(
                    "policy=scripted needs an env that exposes scripted_action() or an end-effector "
                    "config (ee_cfg with step_sizes); this env has neither"
                ) from None
            self.steps = np.asarray(ee_cfg.step_sizes, dtype=np.float64)

    def reset(self, seed: int | None = None) -> None:
        if seed is not None:
            self.rng = np.random.default_rng(seed)

    def __call__(self, observation: dict, info: dict) -> np.ndarray:
        if self.env_expert:
            action = np.asarray(self.vec_env.call("scripted_action"), dtype=np.float64)
        else:
            error = np.asarray(info[GT_DESIRED_GOAL], np.float64) - np.asarray(
                info[GT_ACHIEVED_GOAL], np.float64
            )
            action = self.gain * error / self.steps
        if self.noise_std > 0:
            action = action + self.rng.normal(0.0, self.noise_std, size=action.shape)
        return np.clip(action, self.low, self.high).astype(np.float32)


class CheckpointActions:
    """A trained LeRobot policy, fed exactly as ``lerobot-eval`` feeds it (same processors, same keys)."""

    def __init__(self, path: str | Path, env_cfg, vec_env: gym.vector.VectorEnv, device: str):
        from lerobot.configs.policies import PreTrainedConfig
        from lerobot.envs.factory import make_env_pre_post_processors
        from lerobot.policies.factory import get_policy_class, make_pre_post_processors

        from lerobot_indicator.training.rollout import env_batch

        self.env_batch, self.vec_env = env_batch, vec_env
        policy_cfg = PreTrainedConfig.from_pretrained(path)
        policy_cfg.pretrained_path = Path(path)
        policy_cfg.device = device
        self.policy = get_policy_class(policy_cfg.type).from_pretrained(path, config=policy_cfg)
        self.policy.to(device).eval()
        overrides = {"device_processor": {"device": device}}
        self.pre, self.post = make_pre_post_processors(
            policy_cfg, pretrained_path=str(path), preprocessor_overrides=overrides
        )
        self.env_pre, self.env_post = make_env_pre_post_processors(env_cfg=env_cfg, policy_cfg=policy_cfg)

    def reset(self, seed: int | None = None) -> None:
        self.policy.reset()
        if seed is not None:  # a stochastic policy samples from torch's global generator
            torch.manual_seed(seed)

    @torch.no_grad()
    def __call__(self, observation: dict, info: dict) -> np.ndarray:
        batch = self.pre(self.env_batch(observation, self.vec_env, self.env_pre))
        action = self.post(self.policy.select_action(batch))
        action = self.env_post({"action": action})["action"]
        return action.to("cpu").numpy()


def _has_method(vec_env: gym.vector.VectorEnv, name: str) -> bool:
    # Not get_attr: in gymnasium 1.x it *calls* a method attribute and returns the result.
    return bool(vec_env.call("has_wrapper_attr", name)[0])


def make_action_source(
    policy: str, env_cfg, vec_env: gym.vector.VectorEnv, seed: int, noise_std: float, device: str
):
    """``random`` | ``scripted`` | ``noisy_scripted`` | path of a pretrained policy directory."""
    if policy == "random":
        return RandomActions(vec_env.action_space, seed)
    if policy == "scripted":
        return ScriptedActions(vec_env, noise_std=0.0, seed=seed)
    if policy == "noisy_scripted":
        if noise_std <= 0:
            raise ValueError(f"noise_std must be > 0 for policy=noisy_scripted, got {noise_std}")
        return ScriptedActions(vec_env, noise_std=noise_std, seed=seed)
    if Path(policy).is_dir():
        return CheckpointActions(policy, env_cfg, vec_env, device)
    raise ValueError(
        f"policy: {policy!r} is neither one of {BUILTIN_POLICIES} nor a directory holding a pretrained policy"
    )
