"""Goal distance at reset on the online trainer's evaluation goals: the score of a policy that never moves.

The reference lines for learning curves of final distance (``benchmarks/experiments/run.py``): a method is only
learning the task where its final distance falls below the start distance, and only conditioning on the goal
where it falls below the goal-blind distance (the goals' mean distance from their geometric median: the best a
policy can score that always goes to one place). Uses the trainer's evaluation seeds, so the goals are the ones
every evaluation in ``docs/results`` used.

    python -m benchmarks.experiments.start_distance --env.type=rope_push --env.cache_path=outputs/rope_cache/rope_push_4k.npz \
        --out=docs/results/experiments_rope/start_distance.json
"""

import json
from dataclasses import dataclass
from pathlib import Path

import draccus
import numpy as np
from lerobot.envs import make_env
from lerobot.envs.configs import EnvConfig

from benchmarks.records import command_line, write_json
from lerobot_indicator.keys import EVAL_SEED_OFFSET, GT_DESIRED_GOAL, GT_DISTANCE


@dataclass
class StartDistanceConfig:
    env: EnvConfig
    episodes: int = 20
    out: Path | None = None


def geometric_median(points: np.ndarray, iters: int = 200) -> np.ndarray:
    """The point minimising the summed Euclidean distance to ``points`` (N, D): Weiszfeld's iteration."""
    median = points.mean(axis=0)
    for _ in range(iters):
        dist = np.maximum(np.linalg.norm(points - median, axis=1), 1e-12)
        median = (points / dist[:, None]).sum(axis=0) / (1.0 / dist).sum()
    return median


@draccus.wrap()
def main(cfg: StartDistanceConfig) -> dict:
    vec_env = make_env(cfg.env, n_envs=1)[cfg.env.type][0]
    try:
        distances, goals = [], []
        for i in range(cfg.episodes):
            _, info = vec_env.reset(seed=[EVAL_SEED_OFFSET + i])
            distances.append(float(np.asarray(info[GT_DISTANCE]).reshape(-1)[0]))
            goals.append(np.asarray(info[GT_DESIRED_GOAL], dtype=np.float64).reshape(-1))
    finally:
        vec_env.close()
    goals = np.stack(goals)
    record = {
        "command": command_line(),
        "env": cfg.env.type,
        "episodes": cfg.episodes,
        "eval_seeds": [EVAL_SEED_OFFSET, EVAL_SEED_OFFSET + cfg.episodes - 1],
        "start_distance_mean": float(np.mean(distances)),
        "start_distance_std": float(np.std(distances)),
        "start_success_rate": float(np.mean(np.array(distances) <= cfg.env.epsilon)),
        "goal_blind_distance_mean": float(np.linalg.norm(goals - geometric_median(goals), axis=1).mean()),
        "start_distances": distances,
    }
    print(json.dumps({k: v for k, v in record.items() if k != "start_distances"}, indent=1))
    write_json(cfg.out, record)
    return record


if __name__ == "__main__":
    import lerobot_indicator  # noqa: F401  (registers the env types)

    main()
