"""Critic loss from images vs from the ground-truth state on one run's replay, and how well the same encoder
locates the end effector when trained supervised (``benchmarks.probes.critic_fit``).

    python -m benchmarks.probes.run_critic_fit --run_dir=outputs/rgbd_reach/runs/reach_rgbd/indicator_balance_filter/seed_0 \
        --out=docs/results/critic_fit_reach_rgbd.json
"""

import argparse
import json
from pathlib import Path

import torch

from benchmarks.probes.critic_fit import fit_critic, localization_probe
from benchmarks.records import command_line

ARMS = {
    "state (ground truth, for reference)": ("state", {}),
    "images, drq encoder": ("rgbd", {}),
    "images, drq encoder, inverse dynamics 1.0": ("rgbd", {"inverse_dynamics": 1.0}),
    "images, drq encoder, no augmentation": ("rgbd", {"augment_pad": 0}),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run_dir", type=Path, required=True)
    parser.add_argument("--updates", type=int, default=1000)
    parser.add_argument("--image_size", type=int, default=64)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    torch.set_num_threads(1)
    results = {}
    for name, (inputs, config) in ARMS.items():
        results[name] = fit_critic(args.run_dir, inputs, args.updates, args.image_size, **config)
        print(name, [round(c["critic_loss"], 3) for c in results[name]["curve"]], flush=True)
    probe = localization_probe(args.run_dir, 3 * args.updates, args.image_size)
    print("supervised end-effector position from one frame:", probe["curve"], flush=True)
    record = {
        "command": command_line(),
        "run_dir": str(args.run_dir),
        "arms": results,
        "supervised_localization": probe,
    }
    args.out.write_text(json.dumps(record, indent=2) + "\n")


if __name__ == "__main__":
    main()
