"""Whether a rope-push policy aims its pushes at the pusher it sees in the goal image.

With ``--env.pusher_rest=push_end`` the goal image shows the pusher resting where the last hidden goal push
ended: a 6 x 9 cm palm, a cue far plainer than the 2 cm rope. A policy that ends its own pushes there uses
that cue, which says where to push but not how the rope should lie. This runs the policy greedily on evaluation goals
(``keys.EVAL_SEED_OFFSET`` seeds, the trainer's) and reports how far the end point of each of its pushes is
from that resting point, beside the same for uniformly random pushes (chance), and the ground-truth final
rope distance. It runs on either ``pusher_rest``: with the pusher out of view the policy cannot see the
cue, so its miss is what reading the rope alone gives. The hidden goal pushes and ground truth are read
here only, to measure.
"""

from __future__ import annotations

import numpy as np
import torch
from lerobot.envs.configs import EnvConfig
from scipy.stats import spearmanr

from benchmarks.probes.policy_probe import eval_env
from lerobot_indicator.keys import EVAL_SEED_OFFSET, GT_DISTANCE, goal_key
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy
from lerobot_indicator.training.rollout import env_batch


def pusher_cue_probe(
    policy: IndicatorDDPGPolicy, env_cfg: EnvConfig, episodes: int = 30, random_pushes: int = 1000
) -> dict:
    if env_cfg.type != "rope_push":
        raise ValueError(f"the pusher-cue probe needs --env.type=rope_push, got --env.type={env_cfg.type}")
    policy.eval()
    keys = policy.config.observation_keys
    misses, chance, final_distance = [], [], []
    with eval_env(policy, env_cfg) as (vec_env, env_pre):
        env = vec_env.envs[0].unwrapped
        rng = np.random.default_rng(0)
        random_ends = np.stack([env.push_end(a) for a in rng.uniform(-1, 1, (random_pushes, 4))])
        horizon = int(vec_env.call("_max_episode_steps")[0])
        for episode in range(episodes):
            obs, _ = vec_env.reset(seed=EVAL_SEED_OFFSET + episode)
            goal_rest = env.push_end(env.goal_push_actions[-1])
            ends = []
            for _ in range(horizon):
                batch = env_batch(obs, vec_env, env_pre)
                with torch.no_grad():
                    action = policy.actor({k: batch[k] for k in keys}, {k: batch[goal_key(k)] for k in keys})
                action = action[0].numpy()
                ends.append(env.push_end(action))
                obs, _, _, _, info = vec_env.step(action[None])
            # Gymnasium's same-step autoreset: the last step's info is final_info.
            final_distance.append(float(info.get("final_info", info)[GT_DISTANCE][0]))
            misses.append(np.linalg.norm(np.stack(ends) - goal_rest, axis=1))
            chance.append(float(np.linalg.norm(random_ends - goal_rest, axis=1).mean()))
    return summarise(np.stack(misses), np.array(chance), np.array(final_distance))


def summarise(misses: np.ndarray, chance: np.ndarray, final_distance: np.ndarray) -> dict:
    """``misses`` (episodes, T): metres from each push's end to the goal's resting pusher; ``chance``
    (episodes,): the mean of that over random pushes; ``final_distance`` (episodes,): the rope's."""
    last = misses[:, -1]
    return {
        "episodes": len(last),
        "final_distance_mean": float(final_distance.mean()),
        "push_end_to_goal_pusher_m_per_step": misses.mean(0).tolist(),
        "last_push_end_to_goal_pusher_m": float(last.mean()),
        "random_push_end_to_goal_pusher_m": float(chance.mean()),
        "last_push_within_5cm_of_goal_pusher": float((last <= 0.05).mean()),
        "spearman_last_push_miss_vs_final_distance": float(spearmanr(last, final_distance).statistic),
    }
