"""Env speed benchmarks: stock robosuite Lift vs our Sawyer reach, RGB-D render cost, rope pushes.

``benchmarks/speed/run_env_speed.py`` and ``benchmarks/speed/run_rope_speed.py`` assemble these into their JSON records.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from lerobot_indicator.envs.rope_push import RopePushEnv


def calls_per_s(fn, n: int) -> float:
    """Calls per second of ``fn`` over ``n`` calls (after one warm-up call)."""
    fn()
    t0 = time.perf_counter()
    for _ in range(n):
        fn()
    return n / (time.perf_counter() - t0)


def ms_per_call(fn, n: int) -> float:
    return 1000.0 / calls_per_s(fn, n)


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
        "steps_per_s": calls_per_s(lambda: env.step(rng.uniform(low, high)), n_steps),
        "reset_ms": ms_per_call(env.reset, 3),
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
        "steps_per_s": calls_per_s(lambda: env.step(rng.uniform(-1, 1, 3)), n_steps),
        "reset_ms": ms_per_call(lambda: env.reset(seed=next(seeds)), 30),
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
                "rgbd_ms": ms_per_call(lambda r=r, env=env: r.render(env.data, "front", depth=True), n),
                "rgb_ms": ms_per_call(lambda r=r, env=env: r.render(env.data, "front", depth=False), n),
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


def call_times_ms(fn, n: int) -> dict:
    """Mean, median and max milliseconds of ``n`` calls of ``fn``."""
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return {
        "mean_ms": statistics.fmean(times),
        "median_ms": statistics.median(times),
        "max_ms": max(times),
        "n": n,
    }


def bench_pushes(env: RopePushEnv, n: int, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)

    def crossing():
        if env.sim.push(env.sim.random_push_action(rng)) is False:  # rare: clipped at the region edge
            env.reset()
        env.camera_observation()  # the rendering a step returns

    def uniform():
        env.step(rng.uniform(-1, 1, 4))

    return {"crossing_push": call_times_ms(crossing, n), "uniform_random_action": call_times_ms(uniform, n)}
