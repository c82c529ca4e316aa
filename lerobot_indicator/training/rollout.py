"""Fixed-horizon rollouts over a gymnasium vector env, through LeRobot's own observation path.

Observations go through exactly what ``lerobot-eval`` applies (``preprocess_observation``, the
env's pre-processor, the policy's pre-processor), so what the replay buffer stores is what eval and
``lerobot-train`` batches contain, bit for bit (the indicator reward depends on it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from lerobot.envs.utils import preprocess_observation
from lerobot.utils.constants import ACTION

from lerobot_indicator.data.features import observation_frame, unbatch
from lerobot_indicator.keys import GT_ACHIEVED_GOAL, GT_DESIRED_GOAL, GT_DISTANCE, goal_key


@dataclass
class Processors:
    """The four pipelines between an env and a policy, in the order ``lerobot-eval`` applies them."""

    env_pre: Any
    env_post: Any
    pre: Any
    post: Any


@dataclass
class Rollouts:
    """``n`` episodes of horizon ``T`` collected in parallel."""

    observations: dict[str, np.ndarray]  # policy key -> (n, T + 1, ...) float32, before normalisation
    actions: np.ndarray  # (n, T, A)
    success: np.ndarray  # (n,) ground-truth success at the final step
    final_distance: np.ndarray  # (n,) ground-truth distance at the final step
    gt_achieved: np.ndarray | None  # (n, T + 1, g)
    gt_desired: np.ndarray | None  # (n, g)
    # Per env, the T + 1 dataset frames (``observation_frame``) when asked for (``--record.*``).
    dataset_frames: list[list[dict[str, np.ndarray]]] | None = None

    def episodes(self):
        """Yield ``(observations, actions, ground_truth)`` per episode, as the replay buffer takes them."""
        for i in range(self.actions.shape[0]):
            gt = None
            if self.gt_achieved is not None:
                gt = {GT_ACHIEVED_GOAL: self.gt_achieved[i], GT_DESIRED_GOAL: self.gt_desired[i]}
            yield {k: v[i] for k, v in self.observations.items()}, self.actions[i], gt


@dataclass(frozen=True)
class EpisodeBatch:
    """What decides one batch of episodes, one per sub-env, besides the weights: the same spec gives the
    same episodes on the learner's vector env and on a Ray worker's (``ray_rollouts``).

    Exploration noise comes from a generator of its own, seeded from ``generator_seed``, so a batch does not
    depend on which batches ran before it or where."""

    seeds: tuple[int, ...]
    explore: bool
    generator_seed: int | None = None
    random_eps: float | None = None
    keep_dataset_frames: bool = False

    def run(
        self, vec_env: gym.vector.VectorEnv, policy, processors: Processors, keys: list[str], horizon: int
    ) -> Rollouts:
        generator = None
        if self.generator_seed is not None:
            generator = torch.Generator().manual_seed(self.generator_seed)
        return run_episodes(
            vec_env, policy, processors, keys, horizon, seeds=list(self.seeds), explore=self.explore,
            generator=generator, random_eps=self.random_eps, keep_dataset_frames=self.keep_dataset_frames,
        )  # fmt: skip


def stored_keys(observation_keys: list[str], context_keys: list[str] | None = None) -> list[str]:
    """What a rollout keeps: the compared keys, their goals and the context keys (never ground truth or
    unused cameras)."""
    return [*observation_keys, *(goal_key(k) for k in observation_keys), *(context_keys or [])]


def env_batch(obs: dict, vec_env: gym.vector.VectorEnv, env_pre: Any) -> dict:
    """Env observation -> LeRobot batch, as lerobot-eval's ``rollout`` builds it."""
    batch = preprocess_observation(obs)
    try:
        batch["task"] = list(vec_env.call("task_description"))
    except (AttributeError, NotImplementedError):
        batch["task"] = [""] * vec_env.num_envs
    return env_pre(batch)


def _stack_per_env(items) -> dict:
    """Gymnasium's SAME_STEP autoreset gives ``final_obs`` as an object array with one observation per
    sub-env (``final_info`` is already vectorised); stack it back into the vectorised layout."""
    items = list(items)
    if isinstance(items[0], dict):
        return {k: _stack_per_env([it[k] for it in items]) for k in items[0]}
    return np.stack([np.asarray(it) for it in items])


def _info_array(info: dict, key: str) -> np.ndarray | None:
    value = info.get(key)
    return None if value is None else np.asarray(value, dtype=np.float32)


@torch.no_grad()
def run_episodes(
    vec_env: gym.vector.VectorEnv,
    policy,
    processors: Processors,
    keys: list[str],
    horizon: int,
    seeds: list[int],
    explore: bool,
    generator: torch.Generator | None = None,
    random_eps: float | None = None,
    keep_dataset_frames: bool = False,
) -> Rollouts:
    """Run one episode per sub-env from ``reset(seed=seeds)`` for exactly ``horizon`` steps.

    ``explore`` uses the policy's behaviour policy (actor + Gaussian noise, random actions with
    probability ``random_eps``, the config's unless given: 1.0 for warm-up); otherwise the
    deterministic actor, as in evaluation. ``keep_dataset_frames`` also keeps every raw observation
    as a LeRobotDataset frame, for writing the rollouts to a dataset.
    """
    policy.eval()
    obs, info = vec_env.reset(seed=seeds)
    frames: list[dict[str, np.ndarray]] = []
    actions, achieved = [], []
    desired = _info_array(info, GT_DESIRED_GOAL)
    n_envs = vec_env.num_envs
    dataset_frames = [[] for _ in range(n_envs)] if keep_dataset_frames else None

    def keep_frames(obs: dict, info: dict) -> None:
        for i in range(n_envs if keep_dataset_frames else 0):
            dataset_frames[i].append(observation_frame(unbatch(obs, i), unbatch(info, i)))

    for t in range(horizon):
        batch = env_batch(obs, vec_env, processors.env_pre)
        frames.append({k: batch[k].cpu().numpy() for k in keys})
        achieved.append(_info_array(info, GT_ACHIEVED_GOAL))
        keep_frames(obs, info)
        policy_batch = processors.pre(batch)
        if explore:
            action = policy.select_exploration_action(
                policy_batch, random_eps=random_eps, generator=generator
            )
        else:
            action = policy.select_action(policy_batch)
        action = processors.env_post({ACTION: processors.post(action)})[ACTION]
        action_np = action.cpu().numpy()
        obs, _, terminated, truncated, info = vec_env.step(action_np)
        actions.append(action_np)
        done = np.logical_or(terminated, truncated)
        if t < horizon - 1 and done.any():
            raise RuntimeError(
                f"an episode ended at step {t + 1} < horizon {horizon}: tasks must be fixed-horizon"
            )
    if not done.all():
        raise RuntimeError(
            f"episodes did not end after horizon={horizon} steps: is the env's horizon different?"
        )
    # With gymnasium's SAME_STEP autoreset (LeRobot's default) the last observation and info live in
    # final_obs / final_info; the top-level ones already belong to the next episode.
    final_obs, final_info = obs, info
    if "final_obs" in info:
        final_obs, final_info = _stack_per_env(info["final_obs"]), info["final_info"]
    batch = env_batch(final_obs, vec_env, processors.env_pre)
    frames.append({k: batch[k].cpu().numpy() for k in keys})
    keep_frames(final_obs, final_info)
    achieved.append(_info_array(final_info, GT_ACHIEVED_GOAL))
    distance = _info_array(final_info, GT_DISTANCE)
    success = np.asarray(final_info.get("is_success", np.zeros(len(seeds), bool)), dtype=bool)
    has_gt = desired is not None and all(a is not None for a in achieved)
    return Rollouts(
        observations={k: np.stack([f[k] for f in frames], axis=1) for k in keys},
        actions=np.stack(actions, axis=1).astype(np.float32),
        success=success,
        final_distance=distance if distance is not None else np.full(len(seeds), np.nan, np.float32),
        gt_achieved=np.stack(achieved, axis=1) if has_gt else None,
        gt_desired=desired if has_gt else None,
        dataset_frames=dataset_frames,
    )
