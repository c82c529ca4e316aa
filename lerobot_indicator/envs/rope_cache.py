"""Cached rope-push start/goal configurations: one compressed ``.npz`` plus its generation parameters.

A start/goal pair costs 3 simulated pushes, so (as the paper did, N = 10,000) pairs are generated once
by ``scripts/generate_rope_cache.py`` and sampled at reset. Sample ``i`` uses the random stream
``default_rng([seed, i])``, so the file does not depend on the number of workers or on interruptions.
Generation writes finished chunks to ``<path>.parts/`` (atomically) and merges them at the end: a rerun
after a crash only generates the missing chunks.

File keys: ``start_qpos`` (N, nq), ``goal_qpos`` (N, nq), ``start_action`` (N, 4), ``goal_actions``
(N, goal_pushes, 4), all float64, and ``params_json``: the physics/sampling parameters (must equal the
env's, else the cache is refused) plus ``n``, ``seed`` and ``format_version``.
"""

from __future__ import annotations

import json
import os
import zipfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from lerobot_indicator.envs.rope_sim import PushConfig, RopeSim

FORMAT_VERSION = 1
ARRAY_KEYS = ("start_qpos", "goal_qpos", "start_action", "goal_actions")
GENERATE_HINT = "python scripts/generate_rope_cache.py --output PATH [--n N] (with the env's parameters)"


class RopeCacheError(ValueError):
    """A cache file that cannot be used: unreadable, malformed, or made with other parameters."""


def cache_params(config: PushConfig, nq: int) -> dict:
    """The parameters a cache must have been generated with to be valid for ``config``."""
    return {"format_version": FORMAT_VERSION, "nq": int(nq), "push": config.to_dict()}


def sample_rng(seed: int, index: int) -> np.random.Generator:
    return np.random.default_rng([int(seed), int(index)])


def generate_pair(sim: RopeSim, rng: np.random.Generator, epsilon: float, max_tries: int = 20) -> dict:
    """Straight rope, one random push -> start; ``goal_pushes`` more -> goal (resampled if within epsilon)."""
    n_goal = sim.config.goal_pushes
    for _ in range(max_tries):
        sim.reset_straight()
        start_action = sim.random_push_action(rng)
        sim.push(start_action)
        start_qpos, start_xy = sim.data.qpos.copy(), sim.link_positions()[:, :2].copy()
        goal_actions = np.empty((n_goal, 4))
        for k in range(n_goal):
            goal_actions[k] = sim.random_push_action(rng)
            sim.push(goal_actions[k])
        if np.linalg.norm(sim.link_positions()[:, :2] - start_xy) > epsilon:  # never start solved
            break
    return {
        "start_qpos": start_qpos,
        "goal_qpos": sim.data.qpos.copy(),
        "start_action": start_action,
        "goal_actions": goal_actions,
    }


def _stack(pairs: list[dict]) -> dict[str, np.ndarray]:
    return {k: np.stack([p[k] for p in pairs]) for k in ARRAY_KEYS}


def _write_npz(path: Path, arrays: dict[str, np.ndarray], params: dict) -> None:
    """Atomic write: a crash leaves either the old file or the complete new one."""
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez_compressed(tmp, params_json=np.array(json.dumps(params, sort_keys=True)), **arrays)
    os.replace(tmp, path)


def load_cache(path: str | Path, expected: dict | None = None) -> dict[str, np.ndarray]:
    """Read and validate a cache; ``expected`` = :func:`cache_params` of the env that will use it."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"rope cache not found: {path}. Generate it with: {GENERATE_HINT}")
    try:
        with np.load(path, allow_pickle=False) as f:
            data = {k: f[k] for k in f.files}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, KeyError) as err:
        raise RopeCacheError(
            f"rope cache {path} is unreadable or corrupt ({err}); regenerate it: {GENERATE_HINT}"
        ) from err
    missing = [k for k in (*ARRAY_KEYS, "params_json") if k not in data]
    if missing:
        raise RopeCacheError(f"rope cache {path} lacks {missing}; regenerate it: {GENERATE_HINT}")
    params = json.loads(str(data.pop("params_json")))
    n = len(data["start_qpos"])
    if (
        n == 0
        or any(len(data[k]) != n for k in ARRAY_KEYS)
        or not all(np.isfinite(data[k]).all() for k in ARRAY_KEYS)
    ):
        raise RopeCacheError(f"rope cache {path} is malformed (empty, ragged or non-finite arrays)")
    if expected is not None:
        got = {k: params.get(k) for k in expected}
        if got != expected:
            diff = _diff(expected, got)
            raise RopeCacheError(
                f"rope cache {path} was generated with different parameters ({'; '.join(diff)}); "
                f"regenerate it with the env's parameters: {GENERATE_HINT}"
            )
    data["params"] = params
    return data


def _diff(expected, got, prefix: str = "") -> list[str]:
    if isinstance(expected, dict) and isinstance(got, dict):
        out = []
        for k in sorted(set(expected) | set(got)):
            out += _diff(expected.get(k), got.get(k), f"{prefix}{k}.")
        return out
    return [] if expected == got else [f"{prefix.rstrip('.')}: cache {got!r} != env {expected!r}"]


# ----- generation ----------------------------------------------------------------------------------
_WORKER: dict = {}


def _worker_init(config: PushConfig, epsilon: float) -> None:
    import mujoco

    from lerobot_indicator.envs.rope_scene import build_rope_model

    model = build_rope_model(
        config.geometry, camera=("unused", (0, 0, 2), (0, 0, 0), 45.0), timestep=config.timestep
    )
    _WORKER.update(sim=RopeSim(model, mujoco.MjData(model), config), epsilon=epsilon)


def _generate_chunk(args: tuple[int, int, int]) -> dict[str, np.ndarray]:
    seed, lo, hi = args
    sim = _WORKER["sim"]
    return _stack([generate_pair(sim, sample_rng(seed, i), _WORKER["epsilon"]) for i in range(lo, hi)])


def _chunks(n: int, chunk_size: int) -> Iterator[tuple[int, int, int]]:
    for k, lo in enumerate(range(0, n, chunk_size)):
        yield k, lo, min(n, lo + chunk_size)


def generate_cache(
    path: str | Path,
    n: int = 10_000,
    seed: int = 0,
    config: PushConfig | None = None,
    epsilon: float = 0.1,
    workers: int = 0,
    chunk_size: int = 200,
    progress: bool = True,
) -> Path:
    """Generate ``n`` start/goal pairs into ``path`` (resumable; ``workers=0``: in this process)."""
    from lerobot_indicator.envs.rope_scene import build_rope_model

    config = config or PushConfig()
    if n <= 0 or chunk_size <= 0:
        raise ValueError(f"n and chunk_size must be > 0, got {n}, {chunk_size}")
    nq = build_rope_model(config.geometry, ("unused", (0, 0, 2), (0, 0, 0), 45.0), config.timestep).nq
    params = {**cache_params(config, nq), "n": int(n), "seed": int(seed), "epsilon": float(epsilon)}
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    parts = path.with_name(path.name + ".parts")
    parts.mkdir(exist_ok=True)
    params_file = parts / "params.json"
    if params_file.exists() and json.loads(params_file.read_text()) != {**params, "chunk_size": chunk_size}:
        raise RopeCacheError(
            f"{parts} holds chunks of a generation with other parameters; delete it or rerun with those parameters"
        )
    params_file.write_text(json.dumps({**params, "chunk_size": chunk_size}, sort_keys=True))
    todo = [c for c in _chunks(n, chunk_size) if not (parts / f"chunk_{c[0]:05d}.npz").exists()]
    done = n - sum(hi - lo for _, lo, hi in todo)

    from tqdm import tqdm

    bar = tqdm(total=n, initial=done, desc="rope start/goal pairs", unit="pair", disable=not progress)

    def save(k: int, arrays: dict[str, np.ndarray]) -> None:
        _write_npz(parts / f"chunk_{k:05d}.npz", arrays, params)
        bar.update(len(arrays["start_qpos"]))

    jobs = [(seed, lo, hi) for _, lo, hi in todo]
    if workers <= 0:
        _worker_init(config, epsilon)
        for (k, _, _), job in zip(todo, jobs, strict=True):
            save(k, _generate_chunk(job))
    elif jobs:
        import multiprocessing as mp

        # fork: workers inherit the imported modules (spawn would re-import torch/LeRobot in every worker);
        # generation uses no GL context, so forking is safe.
        method = "fork" if "fork" in mp.get_all_start_methods() else "spawn"
        with mp.get_context(method).Pool(
            workers, initializer=_worker_init, initargs=(config, epsilon)
        ) as pool:
            for (k, _, _), arrays in zip(todo, pool.imap(_generate_chunk, jobs), strict=True):
                save(k, arrays)
    bar.close()
    chunks = [load_cache(parts / f"chunk_{k:05d}.npz") for k, _, _ in _chunks(n, chunk_size)]
    _write_npz(path, {key: np.concatenate([c[key] for c in chunks]) for key in ARRAY_KEYS}, params)
    for f in parts.iterdir():
        f.unlink()
    parts.rmdir()
    return path
