"""Whether trained critics still depend on their input (``benchmarks.probes.policy_probe.critic_saturation``):
saturation of each hidden tanh layer and Q's spread, on frames of evaluation goals under random actions.

    MUJOCO_GL=egl python -m benchmarks.probes.run_critic_saturation --env.type=sawyer_reach --env.obs_type=rgbd \
        --env.camera.height=64 --env.camera.width=64 \
        --runs='[outputs/rgbd_reach/runs/reach_rgbd/oracle_n3_inverse_dynamics/seed_0,...]' \
        --out=docs/results/experiments_rgbd/critic_saturation.json
"""

from dataclasses import dataclass
from pathlib import Path

import draccus
import numpy as np
import torch
from lerobot.envs.configs import EnvConfig

from benchmarks.probes.policy_probe import critic_saturation, env_frames
from benchmarks.records import command_line, write_json
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy


@dataclass
class SaturationConfig:
    env: EnvConfig
    # Run directories (<method>/seed_<n>) with a checkpoints/last.
    runs: list[Path]
    out: Path
    episodes: int = 4
    steps: int = 8


@draccus.wrap()
def main(cfg: SaturationConfig) -> None:
    torch.set_num_threads(1)
    results = {}
    for run in cfg.runs:
        policy = IndicatorDDPGPolicy.from_pretrained(str(run / "checkpoints/last/pretrained_model")).to("cpu")
        policy.eval()
        obs, goal = env_frames(policy, cfg.env, cfg.episodes, cfg.steps)
        n = len(next(iter(obs.values())))
        actions = torch.from_numpy(
            np.random.default_rng(1).uniform(-1, 1, (n, policy.config.action_dim)).astype(np.float32)
        )
        results[str(run)] = r = critic_saturation(policy.critic, obs, goal, actions)
        print(
            f"{run}: Q std over the batch {r['q_std_over_batch']:.3g}, saturated per layer "
            f"{[round(h['saturated_fraction'], 3) for h in r['hidden_layers']]}",
            flush=True,
        )
    write_json(cfg.out, {"command": command_line(), "runs": results})


if __name__ == "__main__":
    main()
