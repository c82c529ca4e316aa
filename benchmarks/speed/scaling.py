"""Scale-out measurements (docs/scaling.md): rollout throughput of Ray workers, bytes per episode on the
wire, learner updates/s with the Ray backend vs the local one. Every number comes from a run of the real
trainer's pieces (``OnlineTrainer``, ``RayRollouts``), interleaved so that both sides of a ratio share the
machine's load."""

from __future__ import annotations

import os
import platform
import statistics
import time
from pathlib import Path

import draccus

from lerobot_indicator.training.config import OnlineTrainConfig
from lerobot_indicator.training.rollout import EpisodeBatch


def machine() -> dict:
    """CPU model, core count and load averages: the load of other jobs on a shared machine depresses ratios."""
    model = platform.processor()
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.exists():
        names = [
            ln.split(":", 1)[1].strip()
            for ln in cpuinfo.read_text().splitlines()
            if ln.startswith("model name")
        ]
        model = names[0] if names else model
    return {"cpu_model": model, "cpu_count": os.cpu_count(), "loadavg": list(os.getloadavg())}


WORKER_NICE_ENV = "LEROBOT_INDICATOR_BENCH_NICE"


def lower_priority(nice: int) -> None:
    """``os.nice`` up to ``nice``."""
    os.nice(max(0, nice - os.nice(0)))


def lower_worker_priority() -> None:
    """Ray ``worker_process_setup_hook``: every Ray worker to the driver's ``WORKER_NICE_ENV`` priority."""
    lower_priority(int(os.environ.get(WORKER_NICE_ENV, "0")))


def start_ray(num_cpus: int, nice: int) -> None:
    """A local Ray instance whose control plane (GCS, raylet) keeps this process's priority while every
    process doing the work (this driver, the rollout actors) runs at ``nice``. On a machine whose cores other
    jobs keep busy, a niced raylet misses Ray's fixed 30 s start-up deadline."""
    import ray

    os.environ[WORKER_NICE_ENV] = str(nice)  # inherited by the raylet and so by its workers
    ray.init(
        address="local",
        num_cpus=num_cpus,
        include_dashboard=False,
        log_to_driver=False,
        runtime_env={"worker_process_setup_hook": f"{__name__}.lower_worker_priority"},
    )
    lower_priority(nice)


def make_config(args: list[str], output_dir: Path) -> OnlineTrainConfig:
    from lerobot.utils.import_utils import register_third_party_plugins

    register_third_party_plugins()
    cfg = draccus.parse(OnlineTrainConfig, args=[*args, f"--output_dir={output_dir}"])
    cfg.validate()
    return cfg


def batches(n_batches: int, n_envs: int, first_seed: int) -> list[EpisodeBatch]:
    return [
        EpisodeBatch(
            tuple(first_seed + b * n_envs + i for i in range(n_envs)), explore=True, generator_seed=b
        )
        for b in range(n_batches)
    ]


def rollout_throughput(
    args: list[str], workers: list[int], batches_per_worker: int, repeats: int, out: Path, nice: int = 0
) -> dict:
    """Env steps/s of ``RayRollouts`` with each worker count, measured in alternation ``repeats`` times.

    Every pool first runs one batch per worker (start-up: imports, env and renderer creation), untimed. Each
    timed collection gives every worker ``batches_per_worker`` batches of ``n_envs`` episodes."""
    import ray

    from lerobot_indicator.training.online import OnlineTrainer
    from lerobot_indicator.training.ray_rollouts import RayRollouts

    # One logical CPU per actor of every pool: the idle pool's actors wait while the other one collects.
    start_ray(sum(workers), nice)
    cfg = make_config(args, out)
    trainer = OnlineTrainer(cfg)  # the learner's policy, as the trainer builds it
    n_envs, horizon = cfg.online.n_envs, trainer.horizon
    before = machine()
    pools = {n: RayRollouts(cfg, n) for n in workers}
    rates: dict[int, list[float]] = {n: [] for n in workers}
    try:
        for n, pool in pools.items():
            pool.collect(batches(n, n_envs, 0), trainer.policy)
        for r in range(repeats):
            for n, pool in pools.items():
                todo = batches(n * batches_per_worker, n_envs, 1000 * (r + 1))
                t0 = time.perf_counter()
                pool.collect(todo, trainer.policy)
                rates[n].append(len(todo) * n_envs * horizon / (time.perf_counter() - t0))
        base = workers[0]
        ratios = {
            str(n): [a / b for a, b in zip(rates[n], rates[base], strict=True)] for n in workers if n != base
        }
        result = {
            "env_steps_per_s": {str(n): rates[n] for n in workers},
            "median_env_steps_per_s": {str(n): statistics.median(rates[n]) for n in workers},
            f"ratio_vs_{base}_worker_per_repeat": ratios,
            f"median_ratio_vs_{base}_worker": {n: statistics.median(v) for n, v in ratios.items()},
            "n_envs_per_worker": n_envs,
            "horizon": horizon,
            "batches_per_worker": batches_per_worker,
            "repeats": repeats,
            # Workers replaced (killed by Ray's memory monitor, crashed): a timed collection that includes a
            # replacement includes its start-up.
            "worker_replacements": {str(n): pool.replacements for n, pool in pools.items()},
        }
    finally:
        for pool in pools.values():
            pool.close()
        trainer.close()
        if ray.is_initialized():
            ray.shutdown()
    return {"machine_before": before, "machine_after": machine(), **result}


def bytes_per_episode(args: list[str], out: Path) -> dict:
    """Serialised size of what a worker returns, per episode, from a real batch of the run's env."""
    from lerobot_indicator.training.online import OnlineTrainer
    from lerobot_indicator.training.ray_rollouts import WireRollouts, actor_weights
    from lerobot_indicator.training.rollout import stored_keys

    cfg = make_config(args, out)
    trainer = OnlineTrainer(cfg)
    try:
        [spec] = batches(1, cfg.online.n_envs, 0)
        rollouts = spec.run(
            trainer.vec_env, trainer.policy, trainer.processors, stored_keys(trainer.keys), trainer.horizon
        )
        wire = WireRollouts.of(rollouts)
        n = rollouts.actions.shape[0]
        float32_bytes = sum(v.nbytes for v in rollouts.observations.values())
        weights = actor_weights(trainer.policy)
        return {
            "horizon": trainer.horizon,
            "episodes": n,
            "bytes_per_episode": wire.nbytes() / n,
            "float32_observation_bytes_per_episode": float32_bytes / n,
            "per_key": {
                k: {
                    "dtype": str(v.data.dtype),
                    "once_per_episode": v.per_episode,
                    "bytes_per_episode": v.data.nbytes / n,
                }
                for k, v in wire.observations.items()
            },
            "actor_weight_bytes_per_cycle_and_worker": sum(
                t.numel() * t.element_size() for t in weights.values()
            ),
        }
    finally:
        trainer.close()


def learner_updates(args: list[str], backends: list[str], repeats: int, out: Path, nice: int = 0) -> dict:
    """Optimisation steps per second of wall time in ``OnlineTrainer.optimise``, per backend, in alternating
    short runs of the real trainer (``train()``); also whole-cycle rates (collection included)."""
    import ray

    from lerobot_indicator.training.online import OnlineTrainer, apply_process_settings

    if "ray" in backends:
        start_ray(2, nice)  # the trainers' pools use it (RayRollouts joins a running instance)
    lower_priority(nice)
    before = machine()
    rates: dict[str, list[float]] = {b: [] for b in backends}
    cycle_rates: dict[str, list[float]] = {b: [] for b in backends}
    for r in range(repeats):
        for backend in backends:
            cfg = make_config([*args, f"--online.backend={backend}"], out / f"{backend}_{r}")
            trainer = OnlineTrainer(cfg)
            apply_process_settings(cfg)  # as lerobot-indicator-train does
            spent, optimise = [], trainer.optimise

            def timed(rng, generator, optimise=optimise, spent=spent):
                t0 = time.perf_counter()
                stats = optimise(rng, generator)
                spent.append(time.perf_counter() - t0)
                return stats

            trainer.optimise = timed
            try:
                trainer.train()
            finally:
                trainer.close()
            updates = cfg.online.updates_per_cycle
            # The first cycle warms up (first batch shapes, a Ray pool's start-up): left out.
            rates[backend].append(updates * (len(spent) - 1) / sum(spent[1:]))
            cycle_rates[backend].append(trainer.progress.step / trainer.progress.wall_time_s)
    if ray.is_initialized():
        ray.shutdown()
    base = backends[0]
    ratio = {b: [x / y for x, y in zip(rates[b], rates[base], strict=True)] for b in backends if b != base}
    return {
        "machine_before": before,
        "machine_after": machine(),
        "updates_per_s_in_optimise": rates,
        "median_updates_per_s_in_optimise": {b: statistics.median(v) for b, v in rates.items()},
        f"ratio_vs_{base}_per_repeat": ratio,
        f"median_ratio_vs_{base}": {b: statistics.median(v) for b, v in ratio.items()},
        "whole_run_steps_per_wall_s": cycle_rates,
    }
