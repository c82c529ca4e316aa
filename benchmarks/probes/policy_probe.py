"""Where a trained goal-conditioned policy stops short, and whether its critic or its actor is to blame.

Runs the policy greedily on evaluation goals (``keys.EVAL_SEED_OFFSET`` seeds, the trainer's) and reports,
per axis of the end effector: the final error (signed mean, absolute mean, and its correlation with the goal
coordinate: a policy that ignores the goal's value regresses to the mean, correlation near -1), and, at every
step of the episode's second half that is more than ``epsilon`` from the goal on that axis, which way the
actor moves and which way the critic's best action on a {-1, 0, 1}^A grid moves: toward the goal, away, or
not at all. Ground truth is used to *measure* only. Also: how saturated a critic's hidden layers are
(``critic_saturation``) and which goal inputs the encoder's normalisation clips (``clipped_goal_dims``, for
``benchmarks/probes/run_eval_goals.py``).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import torch
from lerobot.envs import make_env
from lerobot.envs.configs import EnvConfig
from lerobot.envs.factory import make_env_pre_post_processors
from torch import Tensor

from benchmarks.records import command_line, write_json
from lerobot_indicator.keys import EVAL_SEED_OFFSET, GT_ACHIEVED_GOAL, GT_DESIRED_GOAL, goal_key
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy
from lerobot_indicator.training.rollout import env_batch


@contextmanager
def eval_env(policy: IndicatorDDPGPolicy, env_cfg: EnvConfig) -> Iterator[tuple]:
    """One env of ``env_cfg`` and its pre-processor for ``policy`` (``(vec_env, env_pre)``), closed on exit."""
    vec_env = make_env(env_cfg, n_envs=1)[env_cfg.type][0]
    env_pre, _ = make_env_pre_post_processors(env_cfg, policy.config)
    try:
        yield vec_env, env_pre
    finally:
        vec_env.close()


def trained_policies(runs_dirs: list[Path]) -> Iterator[tuple[Path, IndicatorDDPGPolicy]]:
    """Every ``<method>/seed_<n>`` run below ``runs_dirs`` with a final checkpoint, and its policy on the CPU;
    a run without one yet is named and skipped."""
    for run in sorted(run for runs_dir in runs_dirs for run in Path(runs_dir).glob("*/seed_*")):
        path = run / "checkpoints" / "last" / "pretrained_model"
        if not path.exists():
            print(f"{run}: no checkpoints/last yet, skipped", flush=True)
            continue
        yield run, IndicatorDDPGPolicy.from_pretrained(str(path)).to("cpu")


def probe_trained_runs(
    runs_dirs: list[Path],
    out: Path,
    probe: Callable[[IndicatorDDPGPolicy], dict],
    describe: Callable[[dict], str],
) -> None:
    """``probe`` every trained run below ``runs_dirs`` (``trained_policies``), print ``describe`` of each
    result, and write them to ``out`` with the command line that made them."""
    results = {}
    for run, policy in trained_policies(runs_dirs):
        results[str(run)] = result = probe(policy)
        print(f"{run}: {describe(result)}", flush=True)
    write_json(out, {"command": command_line(), "runs": results})


def stuck_state_probe(
    policy: IndicatorDDPGPolicy, env_cfg: EnvConfig, episodes: int = 20, epsilon: float = 0.05
) -> dict:
    policy.eval()
    keys = policy.config.observation_keys
    action_dim = policy.config.action_dim
    grid = torch.tensor(list(itertools.product([-1.0, 0.0, 1.0], repeat=action_dim)))
    counts = {
        name: np.zeros(action_dim) for name in ("states", "actor_toward", "critic_toward", "critic_zero")
    }
    counts["critic_away"] = np.zeros(action_dim)
    final_error, goals, start_distance = [], [], []
    with eval_env(policy, env_cfg) as (vec_env, env_pre):
        for episode in range(episodes):
            obs, info = vec_env.reset(seed=EVAL_SEED_OFFSET + episode)
            start_distance.append(float(np.linalg.norm(info[GT_DESIRED_GOAL][0] - info[GT_ACHIEVED_GOAL][0])))
            horizon = int(vec_env.call("_max_episode_steps")[0])
            for t in range(horizon):
                batch = env_batch(obs, vec_env, env_pre)
                o = {k: batch[k] for k in keys}
                g = {k: batch[goal_key(k)] for k in keys}
                with torch.no_grad():
                    action = policy.actor(o, g)[0]
                    n = len(grid)
                    q = policy.critic(
                        {k: v.expand(n, *v.shape[1:]) for k, v in o.items()},
                        {k: v.expand(n, *v.shape[1:]) for k, v in g.items()},
                        grid,
                    )
                error = info[GT_DESIRED_GOAL][0] - info[GT_ACHIEVED_GOAL][0]
                if t >= horizon // 2:
                    best = grid[q.argmax()].numpy()
                    far = np.abs(error) > epsilon
                    sign = np.sign(error)
                    counts["states"] += far
                    counts["actor_toward"] += far & (np.sign(action.numpy()) == sign)
                    counts["critic_toward"] += far & (np.sign(best) == sign)
                    counts["critic_away"] += far & (np.sign(best) == -sign)
                    counts["critic_zero"] += far & (best == 0)
                obs, _, _, _, info = vec_env.step(action.numpy()[None])
            # Gymnasium's same-step autoreset: the last step's info is final_info, the top level is the next reset's.
            info = info.get("final_info", info)
            final_error.append(info[GT_ACHIEVED_GOAL][0] - info[GT_DESIRED_GOAL][0])
            goals.append(info[GT_DESIRED_GOAL][0])
    final_error, goals = np.array(final_error, dtype=np.float64), np.array(goals, dtype=np.float64)
    states = np.maximum(counts["states"], 1)
    distance = np.linalg.norm(final_error, axis=1)
    return {
        "episodes": episodes,
        "success_rate": float((distance <= epsilon).mean()),
        "final_distance_mean_m": float(distance.mean()),
        "start_distance_mean_m": float(np.mean(start_distance)),
        "final_error_signed_mean_m": final_error.mean(0).tolist(),
        "final_error_abs_mean_m": np.abs(final_error).mean(0).tolist(),
        "corr_final_error_vs_goal": [
            float(np.corrcoef(final_error[:, i], goals[:, i])[0, 1]) for i in range(3)
        ],
        "far_states_second_half": counts["states"].tolist(),
        "actor_moves_toward_goal": (counts["actor_toward"] / states).tolist(),
        "critic_best_moves_toward_goal": (counts["critic_toward"] / states).tolist(),
        "critic_best_moves_away": (counts["critic_away"] / states).tolist(),
        "critic_best_stays": (counts["critic_zero"] / states).tolist(),
    }


def critic_saturation(critic: torch.nn.Module, obs: dict, goal: dict, actions: Tensor) -> dict:
    """Whether the critic's Q still depends on its input: per hidden tanh layer, the fraction of units at
    |h| > 0.99 over the batch and their mean std across it; Q's std over the batch (row i with ``actions[i]``)
    and over all of ``actions`` for the first (o, g). A layer whose units are all saturated passes no gradient."""
    layers: dict[str, Tensor] = {}
    hooks = [
        m.register_forward_hook(lambda _m, _i, out, name=name: layers.__setitem__(name, out))
        for name, m in critic.net.named_children()
        if isinstance(m, torch.nn.Tanh)
    ]
    try:
        with torch.no_grad():
            features = critic.encode(obs, goal)
            n = len(features)
            q_actions = critic.head(features[:1].expand(n, -1), actions)
            q_rows = critic.head(features, actions)  # last, so the hooks hold the batch's activations
    finally:
        for h in hooks:
            h.remove()
    return {
        "frames": n,
        "q_mean": float(q_rows.mean()),
        "q_std_over_batch": float(q_rows.std(unbiased=False)),
        "q_std_over_actions": float(q_actions.std(unbiased=False)),
        "hidden_layers": [
            {"saturated_fraction": float((h.abs() > 0.99).float().mean()), "unit_std": float(h.std(0).mean())}
            for h in layers.values()
        ],
    }


def env_frames(policy: IndicatorDDPGPolicy, env_cfg: EnvConfig, episodes: int, steps: int, seed: int = 0):
    """(obs, goal) dicts of ``episodes`` x ``steps`` frames on evaluation goals, under uniform random actions."""
    keys = policy.config.observation_keys
    rng = np.random.default_rng(seed)
    frames = []
    with eval_env(policy, env_cfg) as (vec_env, env_pre):
        for episode in range(episodes):
            obs, _ = vec_env.reset(seed=EVAL_SEED_OFFSET + episode)
            for _ in range(steps):
                frames.append(env_batch(obs, vec_env, env_pre))
                action = rng.uniform(-1, 1, (1, policy.config.action_dim)).astype(np.float32)
                obs, *_ = vec_env.step(action)
    return (
        {k: torch.cat([f[k] for f in frames]) for k in keys},
        {k: torch.cat([f[goal_key(k)] for f in frames]) for k in keys},
    )


def clipped_goal_dims(policy: IndicatorDDPGPolicy, goals: dict[str, np.ndarray]) -> list[list[str]]:
    """Per episode, ``"<key>[<dim>]"`` for every goal dimension (channel, for images: any of its pixels)
    whose normalised value the actor's encoder clips."""
    encoder = policy.actor.encoder
    out: list[list[str]] = [[] for _ in range(next(iter(goals.values())).shape[0])]
    for key, goal in goals.items():
        with torch.no_grad():
            beyond = encoder.standardize(key, torch.as_tensor(goal)).abs() > encoder.input_clip
        beyond = beyond.flatten(2).any(-1) if beyond.ndim > 2 else beyond
        for episode, dims in enumerate(beyond.numpy()):
            out[episode] += [f"{key}[{d}]" for d in np.flatnonzero(dims)]
    return out
