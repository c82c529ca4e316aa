"""How well a trained AE / VAE baseline's learned reward ranks ground-truth distance, on its own run's episodes
(``benchmarks.probes.learned_reward``): on the policy's recent rollouts (does the reward rise
while the distance does not fall: the exploitation the paper reports) and on (observation, goal) pairs over
the whole replay buffer, per goal kind. Ground truth is only read here, never by training.

    python -m benchmarks.probes.run_learned_reward \\
        --run_dirs='[outputs/rgbd_rope/runs/rope_rgbd/ae_n3_inverse_dynamics/seed_1]' \\
        --out=docs/results/experiments_rope_rgbd/learned_reward_probe.json
"""

import draccus

from benchmarks.probes.learned_reward import LearnedRewardProbeConfig, run

if __name__ == "__main__":
    run(draccus.parse(LearnedRewardProbeConfig))
