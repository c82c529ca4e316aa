"""Gradient updates/s of ``indicator_ddpg`` (loss + backward + Adam step + target update), no data loading.

Two settings of the paper's appendix: state inputs with batch 256, and 100x100 RGB-D inputs with batch 128
(4 conv layers + 3x256). ``--dataset-cost`` also times what fetching future frames costs in lerobot-train:
``LeRobotDataset.__getitem__`` on a synthetic 100x100 RGB-D dataset (lossless image storage) with
``observation_delta_indices`` = [0] (no relabeling), [0, 1, 2] (one future offset) and the default
[0, 1, 2, 4, 8, 16]. Writes a JSON record (default ``docs/results/policy_updates.json``).

    python scripts/bench_policy_updates.py [--device cpu] [--seconds 20] [--dataset-cost] [--compile] [--out ...]
"""

import argparse
import json
import os
import platform
import time
from pathlib import Path

import torch
from lerobot.configs import FeatureType, PolicyFeature

from lerobot_indicator.keys import goal_key
from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

SETTINGS = {
    "state_b256": {"batch_size": 256, "features": {"observation.state": (FeatureType.STATE, (3,))}},
    "rgbd_100x100_b128": {
        "batch_size": 128,
        "features": {
            "observation.images.front": (FeatureType.VISUAL, (3, 100, 100)),
            "observation.images.front_depth": (FeatureType.VISUAL, (1, 100, 100)),
        },
    },
}


def make_policy(features: dict, device: str, compile_model: bool = False) -> IndicatorDDPGPolicy:
    cfg = IndicatorDDPGConfig(device=device, observation_keys=list(features), compile_model=compile_model)
    cfg.input_features = {}
    for key, (ftype, shape) in features.items():
        cfg.input_features[key] = cfg.input_features[goal_key(key)] = PolicyFeature(ftype, shape)
    cfg.output_features = {"action": PolicyFeature(FeatureType.ACTION, (3,))}
    return IndicatorDDPGPolicy(cfg).to(device)


def make_batch(features: dict, batch_size: int, device: str) -> dict[str, torch.Tensor]:
    batch = {
        "action": torch.rand(batch_size, 3) * 2 - 1,
        core.HAS_FUTURE: torch.ones(batch_size, dtype=torch.bool),
    }
    for key, (_, shape) in features.items():
        for name in (key, core.NEXT + key, core.FUTURE + key, goal_key(key)):
            batch[name] = torch.rand(batch_size, *shape)
    return {k: v.to(device) for k, v in batch.items()}


def bench(name: str, device: str, seconds: float, compile_model: bool = False) -> dict:
    setting = SETTINGS[name]
    policy = make_policy(setting["features"], device, compile_model)
    batch = make_batch(setting["features"], setting["batch_size"], device)
    optimizer = policy.config.get_optimizer_preset().build(policy.get_optim_params())

    def step() -> None:
        loss, _ = policy.forward(batch)
        loss.backward()
        optimizer.step()
        optimizer.zero_grad()
        policy.update()

    t0 = time.perf_counter()
    for _ in range(3):  # warm-up (and compilation)
        step()
    warmup_s = time.perf_counter() - t0
    if device.startswith("cuda"):
        torch.cuda.synchronize()
    n, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        step()
        n += 1
    if device.startswith("cuda"):
        torch.cuda.synchronize()
    elapsed = time.perf_counter() - start
    return {
        "batch_size": setting["batch_size"],
        "updates": n,
        "seconds": elapsed,
        "updates_per_s": n / elapsed,
        "compile_model": compile_model,
        "warmup_s": warmup_s,
    }


def make_rgbd_dataset(root: Path, episodes: int = 4, horizon: int = 25) -> Path:
    """Random 100x100 RGB-D frames with the conventions' keys (docs/conventions.md), stored as PNG images."""
    import numpy as np
    from lerobot.datasets import LeRobotDataset

    rgb = {"dtype": "image", "shape": (100, 100, 3), "names": ["height", "width", "channels"]}
    depth = {
        "dtype": "image",
        "shape": (100, 100, 1),
        "names": ["height", "width", "channels"],
        "info": {"is_depth_map": True},
    }
    vec = {"dtype": "float32", "shape": (3,), "names": ["x", "y", "z"]}
    features = {
        "observation.images.front": rgb,
        "observation.images.front_depth": depth,
        "observation.images.goal_front": rgb,
        "observation.images.goal_front_depth": depth,
        "observation.state": vec,
        "action": vec,
    }
    ds = LeRobotDataset.create("bench/rgbd", fps=10, features=features, root=root, use_videos=False)
    rng = np.random.default_rng(0)
    for _ in range(episodes):
        goal_rgb = rng.integers(0, 256, (100, 100, 3), dtype=np.uint8)
        goal_depth = rng.uniform(0.3, 2.0, (100, 100, 1)).astype(np.float32)
        for _ in range(horizon):
            ds.add_frame(
                {
                    "observation.images.front": rng.integers(0, 256, (100, 100, 3), dtype=np.uint8),
                    "observation.images.front_depth": rng.uniform(0.3, 2.0, (100, 100, 1)).astype(np.float32),
                    "observation.images.goal_front": goal_rgb,
                    "observation.images.goal_front_depth": goal_depth,
                    "observation.state": rng.normal(size=3).astype(np.float32),
                    "action": rng.uniform(-1, 1, 3).astype(np.float32),
                    "task": "reach",
                }
            )
        ds.save_episode()
    ds.finalize()
    return root


def bench_dataset(seconds: float) -> dict:
    """Samples/s of LeRobotDataset.__getitem__ for growing observation_delta_indices (4 image keys)."""
    import tempfile

    from lerobot.datasets import LeRobotDataset

    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        root = make_rgbd_dataset(Path(tmp) / "rgbd")
        for deltas in ([0], [0, 1, 2], [0, 1, 2, 4, 8, 16]):
            keys = ["observation.images.front", "observation.images.front_depth"]
            keys += [
                "observation.images.goal_front",
                "observation.images.goal_front_depth",
                "observation.state",
            ]
            delta_timestamps = {k: [d / 10 for d in deltas] for k in keys}
            ds = LeRobotDataset("bench/rgbd", root=root, delta_timestamps=delta_timestamps)
            n, start = 0, time.perf_counter()
            while time.perf_counter() - start < seconds:
                ds[n % len(ds)]
                n += 1
            elapsed = time.perf_counter() - start
            out[str(deltas)] = {"samples_per_s": n / elapsed, "frames_per_sample_per_image_key": len(deltas)}
    return out


def cpu_model() -> str:
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--dataset-cost", action="store_true")
    parser.add_argument("--threads", type=int, default=None, help="torch.set_num_threads (default: torch's)")
    parser.add_argument("--out", type=Path, default=Path("docs/results/policy_updates.json"))
    parser.add_argument("--compile", action="store_true", help="also time --policy.compile_model=true")
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    results = {name: bench(name, args.device, args.seconds) for name in SETTINGS}
    if args.compile:
        results |= {f"{name}_compiled": bench(name, args.device, args.seconds, True) for name in SETTINGS}
    device_name = torch.cuda.get_device_name() if args.device.startswith("cuda") else cpu_model()
    record = {
        "device": args.device,
        "device_name": device_name,
        "cpu_count": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "load_average_1_5_15_min_after": os.getloadavg(),
        "torch": torch.__version__,
        "results": results,
    }
    for name, r in results.items():
        print(f"{name}: {r['updates_per_s']:.1f} updates/s ({r['updates']} in {r['seconds']:.1f} s)")
    if args.dataset_cost:
        record["dataset_getitem_rgbd_100x100"] = bench_dataset(args.seconds)
        for deltas, r in record["dataset_getitem_rgbd_100x100"].items():
            print(f"dataset deltas {deltas}: {r['samples_per_s']:.1f} samples/s")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    existing = json.loads(args.out.read_text()) if args.out.exists() else {}
    existing[f"{args.device if args.device == 'cpu' else device_name}_threads{torch.get_num_threads()}"] = (
        record
    )
    args.out.write_text(json.dumps(existing, indent=2) + "\n")


if __name__ == "__main__":
    main()
