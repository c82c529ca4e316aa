#!/usr/bin/env python
"""Measure recording throughput (frames/s) per task and observation type -> docs/results/record_throughput.json.

    MUJOCO_GL=egl python scripts/record_throughput.py --episodes=20 [--tasks sawyer_reach rope_push]

Times ``record()`` end to end (env construction, stepping, rendering, LeRobotDataset writing and
finalizing, checkpoint every 30 s) and, separately, the env set-up alone (construction + first reset,
i.e. model compilation and the EGL context, after a warm-up build), so ``loop_frames_per_s`` excludes
that per-recording constant. The 2 CPU cores are shared with other jobs: expect +-30 % between runs.
The dataset goes to a temporary directory.
"""

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

from lerobot.envs.configs import EnvConfig

import lerobot_indicator.envs  # noqa: F401  (registers the tasks)
from lerobot_indicator.data.recorder import RecordConfig, make_single_env, record

OUT = Path(__file__).resolve().parents[1] / "docs" / "results" / "record_throughput.json"
POLICY = {"sawyer_reach": "noisy_scripted", "rope_push": "noisy_scripted"}


def measure(task: str, obs_type: str, episodes: int, use_videos: bool) -> dict:
    env = EnvConfig.get_choice_class(task)(obs_type=obs_type)
    load_before = os.getloadavg()[0]
    make_single_env(env).close()  # warm-up: imports and caches are one-off costs, not per-recording ones
    start = time.perf_counter()
    vec_env = make_single_env(env)
    vec_env.reset(seed=0)
    setup_s = time.perf_counter() - start
    vec_env.close()
    with tempfile.TemporaryDirectory() as tmp:
        cfg = RecordConfig(
            env=env,
            repo_id=f"bench/{task}_{obs_type}",
            root=Path(tmp) / "ds",
            policy=POLICY[task],
            num_episodes=episodes,
            use_videos=use_videos,
        )
        start = time.perf_counter()
        dataset = record(cfg)
        seconds = time.perf_counter() - start
        frames = dataset.meta.total_frames
        size_mb = sum(p.stat().st_size for p in cfg.root.rglob("*") if p.is_file()) / 2**20
    return {
        "task": task,
        "obs_type": obs_type,
        "use_videos": use_videos,
        "policy": POLICY[task],
        "episodes": episodes,
        "frames": frames,
        "seconds": round(seconds, 2),
        "frames_per_s": round(frames / seconds, 1),
        "env_setup_seconds": round(setup_s, 2),
        "loop_frames_per_s": round(frames / (seconds - setup_s), 1),
        "dataset_mb": round(size_mb, 2),
        "load_average_1min_before": round(load_before, 2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--tasks", nargs="+", default=["sawyer_reach"])
    args = parser.parse_args()
    runs = []
    for task in args.tasks:
        for obs_type, use_videos in (("state", False), ("rgbd", False), ("rgbd", True)):
            runs.append(measure(task, obs_type, args.episodes, use_videos))
            print(json.dumps(runs[-1]))
    OUT.write_text(
        json.dumps(
            {
                "command": f"MUJOCO_GL={os.environ.get('MUJOCO_GL', '')} python scripts/record_throughput.py "
                f"--episodes={args.episodes} --tasks {' '.join(args.tasks)}",
                "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPU cores (shared), no GPU rendering",
                "runs": runs,
            },
            indent=2,
        )
        + "\n"
    )
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
