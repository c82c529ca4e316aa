"""Side-by-side benchmark: Stable-Baselines3 DDPG + HER vs our online trainer on a state-based goal task.

The learners, protocol and timing are ``benchmarks.experiments.vs_sb3``'s; this CLI picks the task
(``--task reach_state``: the Sawyer reach, the default; ``--task fetch_reach_state`` / ``fetch_push_state``:
gymnasium-robotics' ``FetchReach-v4`` / ``FetchPush-v4`` for SB3, ``--env.type=fetch_reach`` / ``fetch_push``
with ``--env.obs_type=state`` for ours), seeds, budget and output.
Writes ``vs_sb3.json`` and ``vs_sb3.png`` (``--skip-training``: ``vs_sb3_updates.json``; ``--so-far``: the
runs of ``--runs-dir`` as far as they got, ``vs_sb3_so_far.json`` / ``.png``).

    python -m benchmarks.experiments.run_vs_sb3 [--task reach_state] [--seeds 0 1 2] [--env-steps 5000] \
        [--eval-every 250] [--threads 1]
    python -m benchmarks.experiments.run_vs_sb3 --task fetch_reach_state --env-steps 5000 --eval-every 200 \
        --out-dir docs/results/gym_tasks/fetch_reach_state
"""

import argparse
import dataclasses
import json
from pathlib import Path

from benchmarks.experiments.vs_sb3 import ALL_LEARNERS, LEARNERS, VS_TASKS, Settings, run_benchmark
from benchmarks.records import command_line


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--methods", nargs="+", default=list(LEARNERS), choices=ALL_LEARNERS)
    for f in dataclasses.fields(Settings):
        flag = "--" + f.name.replace("_", "-")
        if f.type == "bool":
            p.add_argument(flag, action="store_true")
        elif f.name == "task":
            p.add_argument(flag, default=f.default, choices=list(VS_TASKS))
        else:
            p.add_argument(flag, type={"int": int, "float": float}[f.type], default=f.default)
    p.add_argument("--skip-training", action="store_true", help="only the update-throughput benchmark")
    p.add_argument(
        "--so-far",
        action="store_true",
        help="train nothing: gather the runs of --runs-dir as far as they got (vs_sb3_so_far.json / .png)",
    )
    p.add_argument("--out-dir", type=Path, default=Path("docs/results"))
    p.add_argument(
        "--runs-dir",
        type=Path,
        help="keep every run's resume state and result here: the same command continues an interrupted "
        "benchmark, and runs split over several commands (--seeds, --methods) are gathered by one more",
    )
    args = p.parse_args()
    settings = Settings(**{f.name: getattr(args, f.name) for f in dataclasses.fields(Settings)})
    try:
        settings.validate()
    except ValueError as e:
        p.error(str(e))
    if args.so_far and args.runs_dir is None:
        p.error("--so-far gathers the runs of --runs-dir: name it")
    command = command_line()
    record = run_benchmark(
        args.seeds,
        args.methods,
        settings,
        args.out_dir,
        command,
        args.skip_training,
        args.runs_dir,
        args.so_far,
    )
    print(json.dumps(record["summary"], indent=1))


if __name__ == "__main__":
    main()
