"""Gradient updates/s of ``indicator_ddpg`` on synthetic batches, interleaved with peer updates.

A batch looks like what the online trainer's replay buffer hands the learning core: RGB frames as uint8,
depth as float32 millimetres, about half the goals equal to o_{t+1} after relabeling. Arms are timed in
interleaved rounds so that load from other jobs on a shared machine hits every arm alike; ratios from one
run are the reliable numbers.
"""

from __future__ import annotations

import resource
import time
from collections.abc import Callable

import torch
from lerobot.configs import FeatureType, PolicyFeature

from lerobot_indicator.keys import goal_key
from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

Features = dict[str, tuple[FeatureType, tuple[int, ...]]]


def rgbd_features(size: int) -> Features:
    return {
        "observation.images.front": (FeatureType.VISUAL, (3, size, size)),
        "observation.images.front_depth": (FeatureType.VISUAL, (1, size, size)),
    }


STATE_FEATURES: Features = {"observation.state": (FeatureType.STATE, (3,))}


def make_policy(features: Features, device: str = "cpu", **config: object) -> IndicatorDDPGPolicy:
    """A policy for ``features`` with ``config``'s fields over the paper's preset: each arm names what it adds
    (n_step, inverse_dynamics), so its batch and its committed numbers keep their meaning."""
    cfg = IndicatorDDPGConfig(
        device=device, observation_keys=list(features), **{"horizon": 25, "preset": "paper", **config}
    )
    cfg.input_features = {}
    for key, (ftype, shape) in features.items():
        cfg.input_features[key] = cfg.input_features[goal_key(key)] = PolicyFeature(ftype, shape)
    cfg.output_features = {"action": PolicyFeature(FeatureType.ACTION, (3,))}
    return IndicatorDDPGPolicy(cfg).to(device)


def make_batch(
    features: Features, batch_size: int, device: str = "cpu", seed: int = 0, n_step: int = 1
) -> dict:
    """A transition batch with random frames: 3-channel images uint8, other keys float32; with ``n_step`` > 1
    also the path frames o_{t+2..t+n} (all inside the episode)."""
    gen = torch.Generator().manual_seed(seed)
    batch = {
        "action": torch.rand(batch_size, 3, generator=gen) * 2 - 1,
        core.HAS_FUTURE: torch.ones(batch_size, dtype=torch.bool),
    }
    path = (n_step - 1,) if n_step > 1 else None
    if path:
        batch[core.PATH_VALID] = torch.ones(batch_size, *path, dtype=torch.bool)
    for key, (ftype, shape) in features.items():
        names = [key, core.NEXT + key, core.FUTURE + key, goal_key(key)] + ([core.PATH + key] if path else [])
        for name in names:
            size = (batch_size, *(path if name.startswith(core.PATH) else ()), *shape)
            if ftype is FeatureType.VISUAL and shape[0] == 3:
                batch[name] = torch.randint(0, 256, size, generator=gen, dtype=torch.uint8)
            elif ftype is FeatureType.VISUAL:
                batch[name] = torch.randint(300, 2000, size, generator=gen).float()
            else:
                batch[name] = torch.randn(*size, generator=gen)
    return {k: v.to(device) for k, v in batch.items()}


def policy_update(policy: IndicatorDDPGPolicy, batch: dict) -> Callable[[], None]:
    """One update as both trainers run it: loss, backward, Adam step, target update."""
    optimizer = policy.config.get_optimizer_preset().build(policy.get_optim_params())
    policy.train()

    def step() -> None:
        loss, _ = policy.forward(batch)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
        policy.update()
        if batch["action"].device.type == "cuda":
            torch.cuda.synchronize()

    return step


def interleaved_rates(
    arms: dict[str, Callable[[], None]], seconds: float, rounds: int = 3, warmup: int = 2
) -> dict[str, dict]:
    """Updates/s of each arm, timed in ``rounds`` interleaved rounds of ``seconds / rounds`` per arm.

    Returns per arm the median over rounds (``updates_per_s``), every round's rate, the warm-up time, and the
    minor page faults and system CPU seconds per timed update: on a VM that hands freed memory back to its
    host, every large tensor allocated afresh page-faults, which shows up as system time, not compute.
    """
    warmup_s = {}
    for name, step in arms.items():
        t0 = time.perf_counter()
        for _ in range(warmup):
            step()
        warmup_s[name] = time.perf_counter() - t0
    rates: dict[str, list[float]] = {name: [] for name in arms}
    counts = {name: {"updates": 0, "faults": 0, "system_s": 0.0} for name in arms}
    for _ in range(rounds):
        for name, step in arms.items():
            n, start, usage = 0, time.perf_counter(), resource.getrusage(resource.RUSAGE_SELF)
            while time.perf_counter() - start < seconds / rounds or n == 0:
                step()
                n += 1
            rates[name].append(n / (time.perf_counter() - start))
            after = resource.getrusage(resource.RUSAGE_SELF)
            counts[name]["updates"] += n
            counts[name]["faults"] += after.ru_minflt - usage.ru_minflt
            counts[name]["system_s"] += after.ru_stime - usage.ru_stime
    return {
        name: {
            "updates_per_s": sorted(r)[len(r) // 2],
            "rounds_updates_per_s": r,
            "warmup_s": warmup_s[name],
            "minor_faults_per_update": counts[name]["faults"] / counts[name]["updates"],
            "system_s_per_update": counts[name]["system_s"] / counts[name]["updates"],
        }
        for name, r in rates.items()
    }
