"""How well trained runs' own encoder features locate the end effector and the goal: a linear probe on each
run's replay (``benchmarks.probes.critic_fit.feature_probe``; ground truth is the probe's target only).

    python -m benchmarks.probes.run_features --runs_dir=outputs/rgbd_reach/runs/reach_rgbd \
        --out=docs/results/experiments_rgbd/feature_probe.json
"""

import argparse
import json
from pathlib import Path

import torch

from benchmarks.probes.critic_fit import feature_probe
from benchmarks.records import command_line


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--runs_dir", type=Path, action="append", required=True, help="<runs>/<task>; repeatable"
    )
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    torch.set_num_threads(1)
    results = {}
    for runs_dir in args.runs_dir:
        for run in sorted(runs_dir.glob("*/seed_*")):
            if not (run / "checkpoints" / "last" / "pretrained_model").exists():
                print(f"{run}: no checkpoints/last yet, skipped", flush=True)
                continue
            results[str(run)] = feature_probe(run)
            r = results[str(run)]
            print(
                f"{run}: end effector {r['ee_error_mean_m']:.3f} m, goal {r['goal_error_mean_m']:.3f} m",
                flush=True,
            )
    record = {"command": command_line(), "runs": results}
    args.out.write_text(json.dumps(record, indent=2) + "\n")


if __name__ == "__main__":
    main()
