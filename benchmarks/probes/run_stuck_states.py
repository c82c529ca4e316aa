"""Where trained policies stop short on evaluation goals, per axis, and whether the critic's best action points
toward the goal there (``benchmarks.probes.policy_probe``).

    python -m benchmarks.probes.run_stuck_states --env.type=sawyer_reach --env.obs_type=rgbd --env.camera.height=64 \
        --env.camera.width=64 --runs_dirs='[outputs/rgbd_reach/runs/reach_rgbd,outputs/rgbd_reach/runs/reach_rgbd_low_utd]' \
        --out=docs/results/experiments_rgbd/stuck_states.json
"""

from dataclasses import dataclass
from pathlib import Path

import draccus
import torch
from lerobot.envs.configs import EnvConfig

from benchmarks.probes.policy_probe import probe_trained_runs, stuck_state_probe


@dataclass
class ProbeConfig:
    env: EnvConfig
    # Every <method>/seed_<n> below each with a final checkpoint is probed.
    runs_dirs: list[Path]
    out: Path
    episodes: int = 20


@draccus.wrap()
def main(cfg: ProbeConfig) -> None:
    torch.set_num_threads(1)
    probe_trained_runs(
        cfg.runs_dirs,
        cfg.out,
        lambda policy: stuck_state_probe(policy, cfg.env, cfg.episodes),
        lambda r: (
            f"final error per axis {[round(e, 3) for e in r['final_error_abs_mean_m']]} m, critic's best "
            f"action stays {[round(x, 2) for x in r['critic_best_stays']]}"
        ),
    )


if __name__ == "__main__":
    main()
