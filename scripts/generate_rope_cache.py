"""Generate cached rope-push start/goal configurations (the paper pre-computed 10,000).

    python scripts/generate_rope_cache.py --output outputs/rope_cache/rope_push_10k.npz --n 10000

Parallel worker processes, a progress bar, resumable (finished chunks survive a crash; rerun the same
command). Use the file with ``--env.cache_path=PATH`` (or ``RopePushEnv(cache_path=PATH)``). The push
parameters come from the rope env defaults, or from ``--env_config`` (an ``env_configs/*.yaml`` of type
``rope_push``) so that a non-default push region or ``goal_pushes`` gives a cache the env accepts.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from lerobot_indicator.envs.configs import RopePushEnvConfig, load_env_config
from lerobot_indicator.envs.rope_cache import generate_cache
from lerobot_indicator.envs.rope_push import push_config_for


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--output", type=Path, required=True, help="the .npz file to write")
    parser.add_argument("--n", type=int, default=10_000, help="number of start/goal pairs")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="0: no worker processes")
    parser.add_argument("--chunk_size", type=int, default=200, help="pairs per resumable chunk")
    parser.add_argument("--env_config", type=Path, default=None, help="rope_push env config file")
    parser.add_argument("--goal_pushes", type=int, default=None, help="overrides the env config's")
    args = parser.parse_args()

    env_cfg = load_env_config(args.env_config) if args.env_config else RopePushEnvConfig()
    if not isinstance(env_cfg, RopePushEnvConfig):
        raise SystemExit(
            f"--env_config {args.env_config} is a {type(env_cfg).__name__}, not a rope_push config"
        )
    goal_pushes = args.goal_pushes if args.goal_pushes is not None else env_cfg.goal_pushes
    config = push_config_for(env_cfg.end_effector, goal_pushes)
    t0 = time.perf_counter()
    path = generate_cache(
        args.output,
        n=args.n,
        seed=args.seed,
        config=config,
        epsilon=env_cfg.epsilon,
        workers=args.workers,
        chunk_size=args.chunk_size,
    )
    dt = time.perf_counter() - t0
    print(f"wrote {path} ({args.n} pairs, {dt:.1f} s this run, {path.stat().st_size / 1e6:.1f} MB)")


if __name__ == "__main__":
    main()
