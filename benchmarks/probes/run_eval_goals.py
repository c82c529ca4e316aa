"""Per-goal evaluation of a trained policy: which of the trainer's evaluation goals it misses, and whether
those goals lie outside its input normalisation (clipped at ``input_clip`` standard deviations, so the
networks cannot tell them apart).

``lerobot-eval`` reports per-episode success; this adds the ground-truth start, goal and final positions
and the clipping check, the two things needed to see *why* a success rate plateaus (e.g. goals outside
a too narrow input normalisation, docs/policy.md). Uses the trainer's evaluation seeds.

    python -m benchmarks.probes.run_eval_goals --env.type=sawyer_reach --env.obs_type=state \
        --policy_path=outputs/train/.../checkpoints/last/pretrained_model --out=eval_goals.json
"""

import json
from dataclasses import dataclass
from pathlib import Path

import draccus
import numpy as np
from lerobot.envs import make_env
from lerobot.envs.configs import EnvConfig
from lerobot.envs.factory import make_env_pre_post_processors
from lerobot.policies.factory import make_pre_post_processors

from benchmarks.probes.policy_probe import clipped_goal_dims
from benchmarks.records import command_line, write_json
from lerobot_indicator.keys import EVAL_SEED_OFFSET, goal_key
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy
from lerobot_indicator.training.rollout import Processors, run_episodes, stored_keys


@dataclass
class EvalGoalsConfig:
    env: EnvConfig
    policy_path: Path
    episodes: int = 40
    out: Path | None = None


@draccus.wrap()
def main(cfg: EvalGoalsConfig) -> dict:
    policy = IndicatorDDPGPolicy.from_pretrained(cfg.policy_path).to("cpu")
    keys = policy.config.observation_keys
    pre, post = make_pre_post_processors(policy.config, pretrained_path=str(cfg.policy_path))
    env_pre, env_post = make_env_pre_post_processors(cfg.env, policy.config)
    processors = Processors(env_pre=env_pre, env_post=env_post, pre=pre, post=post)
    vec_env = make_env(cfg.env, n_envs=1)[cfg.env.type][0]
    horizon = int(vec_env.call("_max_episode_steps")[0])
    rows = []
    try:
        for i in range(cfg.episodes):
            seed = EVAL_SEED_OFFSET + i
            r = run_episodes(
                vec_env, policy, processors, stored_keys(keys), horizon, seeds=[seed], explore=False
            )
            goals = {k: r.observations[goal_key(k)][:, 0] for k in keys}
            start, goal, final = r.gt_achieved[0, 0], r.gt_desired[0], r.gt_achieved[0, -1]
            rows.append(
                {
                    "seed": seed,
                    "success": bool(r.success[0]),
                    "start_distance": float(np.linalg.norm(goal - start)),
                    "final_distance": float(r.final_distance[0]),
                    "gt_start": start.round(4).tolist(),
                    "gt_goal": goal.round(4).tolist(),
                    "gt_final": final.round(4).tolist(),
                    "clipped_goal_dims": clipped_goal_dims(policy, goals)[0],
                }
            )
    finally:
        vec_env.close()
    clipped = np.array([bool(r["clipped_goal_dims"]) for r in rows])
    success = np.array([r["success"] for r in rows])
    encoder = policy.actor.encoder
    record = {
        "command": command_line(),
        "policy_path": str(cfg.policy_path),
        "env": cfg.env.type,
        "success_rate": float(success.mean()),
        "final_distance_mean": float(np.mean([r["final_distance"] for r in rows])),
        "goals_clipped": int(clipped.sum()),
        "success_rate_clipped_goals": float(success[clipped].mean()) if clipped.any() else None,
        "success_rate_other_goals": float(success[~clipped].mean()) if (~clipped).any() else None,
        "input_stats": {
            k: {name: v.flatten().tolist() for name, v in stats.items()}
            for k, stats in encoder.stats().items()
        },
        "input_clip": encoder.input_clip,
        "episodes": rows,
    }
    print(json.dumps({k: v for k, v in record.items() if k != "episodes"}, indent=1))
    for r in sorted(rows, key=lambda r: r["final_distance"], reverse=True)[:10]:
        print(
            f"seed {r['seed']}: final {r['final_distance']:.3f} goal {r['gt_goal']} clipped {r['clipped_goal_dims']}"
        )
    write_json(cfg.out, record)
    return record


if __name__ == "__main__":
    import lerobot_indicator  # noqa: F401  (registers the env types)

    main()
