"""Speed of stock robosuite Lift (Sawyer, default OSC controller) vs our Sawyer reach, in one run.

Measures control steps per second without cameras and with one RGB-D camera, milliseconds per RGB-D
render at 64/84/100 px (light and full-mesh render sets), and reset time. Writes a JSON result.

    MUJOCO_GL=egl .venv/bin/python scripts/bench_env_speed.py --out docs/results/reach_env_speed.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")


def _rate(fn, n: int) -> float:
    """Calls per second of ``fn`` over ``n`` calls (after one warm-up call)."""
    fn()
    t0 = time.perf_counter()
    for _ in range(n):
        fn()
    return n / (time.perf_counter() - t0)


def _ms(fn, n: int) -> float:
    return 1000.0 / _rate(fn, n)


def bench_stock_lift(size: int, camera: bool, n_steps: int) -> dict:
    import robosuite

    env = robosuite.make(
        "Lift",
        robots="Sawyer",
        has_renderer=False,
        has_offscreen_renderer=camera,
        use_camera_obs=camera,
        camera_names="agentview",
        camera_heights=size,
        camera_widths=size,
        camera_depths=camera,
        control_freq=20,
        ignore_done=True,
    )
    rng = np.random.default_rng(0)
    low, high = env.action_spec
    env.reset()
    out = {
        "steps_per_s": _rate(lambda: env.step(rng.uniform(low, high)), n_steps),
        "reset_ms": _ms(env.reset, 3),
    }
    env.close()
    return out


def bench_reach(obs_type: str, size: int, n_steps: int, light_render: bool = True) -> dict:
    from lerobot_indicator.envs.sawyer_reach import SawyerReachEnv

    env = SawyerReachEnv(obs_type=obs_type, camera={"width": size, "height": size}, light_render=light_render)
    rng = np.random.default_rng(0)
    seeds = iter(range(10**6))
    env.reset(seed=next(seeds))
    out = {
        "steps_per_s": _rate(lambda: env.step(rng.uniform(-1, 1, 3)), n_steps),
        "reset_ms": _ms(lambda: env.reset(seed=next(seeds)), 30),
    }
    env.close()
    return out


def bench_renders(sizes: list[int], n: int) -> dict:
    import mujoco

    from lerobot_indicator.envs.models import RENDER_GROUP
    from lerobot_indicator.envs.sawyer_reach import SawyerReachEnv

    out = {}
    for light in (True, False):
        key = "light" if light else "full_meshes"
        out[key] = {}
        for size in sizes:
            env = SawyerReachEnv(obs_type="rgbd", camera={"width": size, "height": size}, light_render=light)
            env.reset(seed=0)
            r = env.renderer
            out[key][str(size)] = {
                "rgbd_ms": _ms(lambda r=r, env=env: r.render(env.data, "front", depth=True), n),
                "rgb_ms": _ms(lambda r=r, env=env: r.render(env.data, "front", depth=False), n),
            }
            env.close()
    out["mesh_triangles_drawn"] = {}
    for light in (True, False):
        env = SawyerReachEnv(obs_type="state", light_render=light)
        m = env.model
        out["mesh_triangles_drawn"]["light" if light else "full_meshes"] = sum(
            int(m.mesh_facenum[m.geom_dataid[g]])
            for g in range(m.ngeom)
            if m.geom_group[g] == RENDER_GROUP and m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH
        )
        env.close()
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/results/reach_env_speed.json"))
    parser.add_argument("--size", type=int, default=100, help="camera resolution for the RGB-D comparison")
    parser.add_argument("--stock-steps", type=int, default=60)
    parser.add_argument("--reach-steps", type=int, default=400)
    parser.add_argument("--render-reps", type=int, default=30)
    args = parser.parse_args()

    result: dict = {
        "command": "MUJOCO_GL=egl .venv/bin/python scripts/bench_env_speed.py --out docs/results/reach_env_speed.json",
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
