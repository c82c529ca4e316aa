"""Device probe: the rope RGB-D env renders through EGL and torch sees CUDA; prints ms per env step."""

import time

import numpy as np
import torch
from lerobot.envs.factory import make_env

import lerobot_indicator.envs  # noqa: F401  (registers the envs)
from lerobot_indicator.envs.configs import RopePushEnvConfig

N_STEPS = 12

print("cuda", torch.cuda.is_available(), torch.cuda.get_device_name() if torch.cuda.is_available() else "-")
cfg = RopePushEnvConfig(obs_type="rgbd", cache_path="outputs/rope_cache/rope_push_10k.npz")
env = next(iter(next(iter(make_env(cfg, n_envs=1).values())).values()))
obs, _ = env.reset(seed=1)
print({k: v.shape for k, v in obs["pixels"].items()}, "mean front pixel", obs["pixels"]["front"].mean())
rng = np.random.default_rng(0)
start = time.perf_counter()
for _ in range(N_STEPS):
    env.step(rng.uniform(-1, 1, size=(1, 4)).astype(np.float32))
print(f"ms per env step (1 env, random pushes): {1000 * (time.perf_counter() - start) / N_STEPS:.1f}")
env.close()
