"""Speed of stock robosuite Lift (Sawyer, default OSC controller) vs our Sawyer reach, in one run.

Measures control steps per second without cameras and with one RGB-D camera, milliseconds per RGB-D
render at 64/84/100 px (light and full-mesh render sets), and reset time. Writes a JSON result.

    MUJOCO_GL=egl .venv/bin/python -m benchmarks.speed.run_env_speed --out docs/results/reach_env_speed.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

from benchmarks.speed.env_speed import bench_reach, bench_renders, bench_stock_lift  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/results/reach_env_speed.json"))
    parser.add_argument("--size", type=int, default=100, help="camera resolution for the RGB-D comparison")
    parser.add_argument("--stock-steps", type=int, default=60)
    parser.add_argument("--reach-steps", type=int, default=400)
    parser.add_argument("--render-reps", type=int, default=30)
    args = parser.parse_args()

    result: dict = {
        "command": "MUJOCO_GL=egl .venv/bin/python -m benchmarks.speed.run_env_speed --out docs/results/reach_env_speed.json",
        "machine": {
            "cpus": os.cpu_count(),
            "platform": platform.platform(),
            "mujoco_gl": os.environ["MUJOCO_GL"],
        },
        "camera_px": args.size,
    }
    result["stock_lift_sawyer"] = {
        "no_camera": bench_stock_lift(args.size, camera=False, n_steps=args.stock_steps),
        "rgbd_camera": bench_stock_lift(args.size, camera=True, n_steps=max(10, args.stock_steps // 4)),
    }
    result["sawyer_reach"] = {
        "no_camera": bench_reach("state", args.size, args.reach_steps),
        "rgbd_camera": bench_reach("rgbd", args.size, args.reach_steps // 4),
        "rgbd_camera_full_meshes": bench_reach("rgbd", args.size, 20, light_render=False),
    }
    result["render_ms"] = bench_renders([64, 84, 100], args.render_reps)
    stock, ours = result["stock_lift_sawyer"], result["sawyer_reach"]
    result["speedup"] = {
        "no_camera": ours["no_camera"]["steps_per_s"] / stock["no_camera"]["steps_per_s"],
        "rgbd_camera": ours["rgbd_camera"]["steps_per_s"] / stock["rgbd_camera"]["steps_per_s"],
    }
    result["targets_met"] = {
        "no_camera_speedup_ge_5": result["speedup"]["no_camera"] >= 5,
        "rgbd_speedup_ge_3": result["speedup"]["rgbd_camera"] >= 3,
        "state_reset_lt_10ms": ours["no_camera"]["reset_ms"] < 10,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
