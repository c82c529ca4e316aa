"""Whether trained rope-push policies end their pushes where the goal image shows the pusher resting
(``benchmarks.probes.pusher_cue``).

    python -m benchmarks.probes.run_pusher_cue --env.type=rope_push --env.obs_type=rgbd --env.pusher_rest=push_end \
        --env.cache_path=outputs/rope_cache/rope_push_10k.npz --runs_dirs='[outputs/rgbd_rope/runs/rope_rgbd_pusher_visible]' \
        --out=docs/results/experiments_rope_rgbd/pusher_visible/pusher_cue.json
"""

from dataclasses import dataclass
from pathlib import Path

import draccus
import torch
from lerobot.envs.configs import EnvConfig

from benchmarks.probes.policy_probe import probe_trained_runs
from benchmarks.probes.pusher_cue import pusher_cue_probe


@dataclass
class PusherCueConfig:
    env: EnvConfig
    # Every <method>/seed_<n> below each with a final checkpoint is probed.
    runs_dirs: list[Path]
    out: Path
    episodes: int = 30


@draccus.wrap()
def main(cfg: PusherCueConfig) -> None:
    torch.set_num_threads(1)
    probe_trained_runs(
        cfg.runs_dirs,
        cfg.out,
        lambda policy: pusher_cue_probe(policy, cfg.env, cfg.episodes),
        lambda r: (
            f"last push ends {r['last_push_end_to_goal_pusher_m']:.3f} m from the goal's pusher "
            f"(random {r['random_push_end_to_goal_pusher_m']:.3f}), rope distance {r['final_distance_mean']:.3f}"
        ),
    )


if __name__ == "__main__":
    main()
