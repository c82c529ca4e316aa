"""Rope-push env speed: ms per push (state only / RGB-D), ms per reset (cache / on the fly), cache
generation rate, and a full 3-push RGB-D episode from the cache (goal: under 1 s).

    MUJOCO_GL=egl .venv/bin/python -m benchmarks.speed.run_rope_speed --out docs/results/rope_env_speed.json

Pushes are measured two ways: the authors' random push (always crosses the rope: the expensive case)
and a uniform random action (what an untrained policy sends; misses are skipped and cost ~nothing).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.speed.env_speed import bench_pushes, call_times_ms
from lerobot_indicator.envs.rope_cache import generate_cache
from lerobot_indicator.envs.rope_push import RopePushEnv

COMMAND = (
    "MUJOCO_GL=egl .venv/bin/python -m benchmarks.speed.run_rope_speed --out docs/results/rope_env_speed.json"
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--n", type=int, default=20, help="repetitions per measurement")
    parser.add_argument(
        "--cache_n", type=int, default=40, help="pairs generated for the cache-rate measurement"
    )
    args = parser.parse_args()

    result: dict = {
        "command": COMMAND,
        "machine": {
            "cpus": os.cpu_count(),
            "platform": platform.platform(),
            "mujoco_gl": os.environ.get("MUJOCO_GL"),
            "load_average_at_start": os.getloadavg(),
        },
        "camera_px": 100,
    }
    with tempfile.TemporaryDirectory() as tmp:
        cache_rates = {}
        for workers in (0, os.cpu_count() or 1):
            t0 = time.perf_counter()
            path = generate_cache(
                Path(tmp) / f"c{workers}.npz", n=args.cache_n, workers=workers, progress=False
            )
            dt = time.perf_counter() - t0
            label = "in_process" if workers == 0 else f"{workers}_workers"
            cache_rates[label] = {"pairs": args.cache_n, "seconds": dt, "pairs_per_s": args.cache_n / dt}
        result["cache_generation"] = cache_rates
        result["cache_generation"]["note"] = (
            "includes model build and (fork) worker start-up; tiny N, so a lower bound"
        )

        state = RopePushEnv(obs_type="state")
        rgbd = RopePushEnv(obs_type="rgbd")
        cached = RopePushEnv(obs_type="rgbd", cache_path=str(path))
        try:
            rgbd.reset(seed=0)
            cached.reset(seed=0)  # GL context creation is not part of the per-reset cost
            result["push_state_only"] = bench_pushes(state, args.n, seed=1)
            result["push_rgbd"] = bench_pushes(rgbd, args.n, seed=1)
            result["reset"] = {
                "rgbd_from_cache": call_times_ms(lambda: cached.reset(), args.n),
                "rgbd_on_the_fly": call_times_ms(lambda: rgbd.reset(), max(3, args.n // 4)),
                "state_on_the_fly": call_times_ms(lambda: state.reset(), max(3, args.n // 4)),
            }
            rng = np.random.default_rng(2)

            def episode_random_actions():
                cached.reset()
                for _ in range(3):
                    cached.step(rng.uniform(-1, 1, 4))

            def episode_crossing_pushes():
                cached.reset()
                for _ in range(3):
                    cached.step(cached.sim.random_push_action(rng))

            result["episode_3_pushes_rgbd_from_cache"] = {
                "uniform_random_actions": call_times_ms(episode_random_actions, args.n),
                "crossing_pushes_worst_case": call_times_ms(episode_crossing_pushes, args.n),
                "goal_ms": 1000.0,
            }
        finally:
            for env in (state, rgbd, cached):
                env.close()
    result["machine"]["load_average_at_end"] = os.getloadavg()
    text = json.dumps(result, indent=2)
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
