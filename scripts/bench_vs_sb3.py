"""Side-by-side benchmark: Stable-Baselines3 DDPG + HER vs our online trainer on the state-based Sawyer reach.

Three learners, same simulator, same hyper-parameters where both have them (3x256 tanh MLPs, batch 256,
Adam lr 1e-3, gamma = 1 - 1/T = 0.96, target smoothing 0.98 (SB3 tau 0.02), one env, 2 episodes then 40
gradient steps per cycle, the same env-step budget):

* ``sb3_ddpg_her``: SB3 ``DDPG`` + ``HerReplayBuffer`` (``future``, 4 sampled goals), ground-truth sparse
  reward +1/-1 through ``GoalEnvAdapter.compute_reward`` (``lerobot_indicator/envs/goal_env_adapter.py``);
* ``ours_oracle``: ``lerobot-indicator-train --policy.reward=oracle --policy.balance=false --policy.filter=false``
  (the paper's Oracle: the same ground-truth reward, HER-style relabeling);
* ``ours_indicator``: ``--policy.reward=indicator --policy.balance=true --policy.filter=true`` (no ground truth).

Evaluation is the same for all: the deterministic actor on the N fixed eval episodes of our trainer
(``reset(seed=EVAL_SEED_OFFSET + i)``), success = ground-truth distance <= epsilon at the last step. Every training run is
a fresh subprocess, runs are interleaved seed by seed (SB3, oracle, indicator, next seed...) so machine noise
hits all learners alike, and wall-clock excludes evaluation. Update throughput is measured separately in one
process on equally filled buffers, blocks interleaved A/B/B/A. Writes ``vs_sb3.json`` and ``vs_sb3.png``.

    python scripts/bench_vs_sb3.py [--seeds 0 1 2] [--env-steps 5000] [--eval-every 250] [--threads 1]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from torch.utils.flop_counter import FlopCounterMode

from lerobot_indicator.keys import EVAL_SEED_OFFSET, GT_DISTANCE

# What differs between the SB3 and our learners beyond the shared hyper-parameters (each library's defaults).
PROTOCOL_DIFFERENCES = [
    "inputs: SB3 concatenates observation, achieved_goal (== observation) and desired_goal (9-d); ours "
    "observation and goal (6-d)",
    "exploration: SB3 Gaussian noise std 0.2; ours Gaussian 0.2 plus a uniform random action with p=0.3 "
    "(baselines' HER)",
    "losses: ours adds action_l2=1 on the actor output and clips TD targets to [R-/(1-gamma), R+/(1-gamma)], "
    "critic bias initialised at R-/(1-gamma); SB3 has neither",
    "relabeling: SB3 'future' with 4 sampled goals (80% relabeled); ours oracle HER-style p=0.9 uniform over "
    "{t+1..T}; ours indicator balanced 0.45 next / 0.45 future (t'>=t+2) / 0.1 recorded, plus filtering",
    "input normalisation: ours mean/std of the replay buffer's frames and goals, refreshed every cycle, "
    "clipped to +-5 (baselines' HER); SB3 none",
    "optimiser: SB3 one Adam per network (critic step then actor step); ours one Adam over both, one backward",
    "ours writes its resume state (weights, optimizer, new episodes) after every cycle; that time counts",
]
METHODS = ("sb3_ddpg_her", "ours_oracle", "ours_indicator")
HORIZON = 25
SUCCESS_TARGET = 0.9


# ----------------------------------------------------------------------------------------------------------
# SB3 side
# ----------------------------------------------------------------------------------------------------------
def make_sb3(seed: int, args: argparse.Namespace, learning_starts: int = 0):
    from stable_baselines3 import DDPG, HerReplayBuffer
    from stable_baselines3.common.noise import NormalActionNoise
    from torch import nn

    from lerobot_indicator.envs.goal_env_adapter import make_goal_env

    env = make_goal_env()
    return DDPG(
        "MultiInputPolicy",
        env,
        learning_rate=args.lr,
        buffer_size=1_000_000,
        learning_starts=learning_starts,
        batch_size=args.batch_size,
        tau=0.02,
        gamma=1 - 1 / HORIZON,
        train_freq=(args.episodes_per_cycle, "episode"),
        gradient_steps=args.updates_per_cycle,
        action_noise=NormalActionNoise(np.zeros(3), args.noise * np.ones(3)),
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"},
        policy_kwargs={"net_arch": [256, 256, 256], "activation_fn": nn.Tanh},
        seed=seed,
        device="cpu",
        verbose=0,
    )


def evaluate_sb3(model, env, n_episodes: int) -> dict[str, float]:
    """Our trainer's evaluation protocol: seeds EVAL_SEED_OFFSET + i, deterministic actor, success at step T."""
    success, distance = [], []
    for i in range(n_episodes):
        obs, info = env.reset(seed=EVAL_SEED_OFFSET + i)
        for _ in range(HORIZON):
            action, _ = model.predict(obs, deterministic=True)
            obs, _, terminated, truncated, info = env.step(action)
        if not truncated:
            raise RuntimeError("an eval episode did not end at the horizon")
        success.append(bool(info["is_success"]))
        distance.append(float(info[GT_DISTANCE]))
    return {"eval_success_rate": float(np.mean(success)), "eval_final_distance": float(np.mean(distance))}


def run_sb3(seed: int, args: argparse.Namespace) -> dict:
    from stable_baselines3.common.callbacks import BaseCallback

    from lerobot_indicator.envs.goal_env_adapter import make_goal_env

    model = make_sb3(seed, args)
    eval_env = make_goal_env()
    curve: list[dict] = []
    clock = {"eval": 0.0, "collect": 0.0, "rollout_t0": 0.0, "start": 0.0}

    def do_eval() -> None:
        t0 = time.perf_counter()
        train_wall = t0 - clock["start"] - clock["eval"]
        result = evaluate_sb3(model, eval_env, args.eval_episodes)
        clock["eval"] += time.perf_counter() - t0
        curve.append(
            {
                "env_steps": int(model.num_timesteps),
                "updates": int(model._n_updates),
                "train_wall_s": train_wall,
                **result,
            }
        )

    class Timer(BaseCallback):
        """Rollout start = the previous cycle's gradient steps are done: evaluate there (as ours does)."""

        def _on_training_start(self) -> None:
            clock["start"] = time.perf_counter()

        def _on_rollout_start(self) -> None:
            n = self.model.num_timesteps
            if n > 0 and n % args.eval_every == 0 and (not curve or curve[-1]["env_steps"] != n):
                do_eval()
            clock["rollout_t0"] = time.perf_counter()

        def _on_rollout_end(self) -> None:
            clock["collect"] += time.perf_counter() - clock["rollout_t0"]

        def _on_step(self) -> bool:
            return True

    model.learn(total_timesteps=args.env_steps, callback=Timer())
    do_eval()  # after the last cycle's gradient steps
    return {"curve": curve, "collect_wall_s": clock["collect"], "updates": int(model._n_updates)}


# ----------------------------------------------------------------------------------------------------------
# our side
# ----------------------------------------------------------------------------------------------------------
def ours_config(method: str, seed: int, args: argparse.Namespace, output_dir: Path, steps: int):
    import draccus

    from lerobot_indicator.training.config import OnlineTrainConfig

    # As scripts/experiments.py (paper section 6): the Oracle is HER-style (no balancing, no filtering).
    if method == "ours_oracle":
        reward = ["--policy.reward=oracle", "--policy.balance=false", "--policy.filter=false"]
    else:
        reward = ["--policy.reward=indicator", "--policy.balance=true", "--policy.filter=true"]
    cli = [
        "--env.type=sawyer_reach",
        "--env.obs_type=state",
        "--policy.type=indicator_ddpg",
        "--policy.device=cpu",
        "--policy.push_to_hub=false",
        f"--policy.learning_rate={args.lr}",
        f"--policy.noise_eps={args.noise}",
        *reward,
        "--online.n_envs=1",
        "--online.use_async_envs=false",
        f"--online.episodes_per_cycle={args.episodes_per_cycle}",
        f"--online.updates_per_cycle={args.updates_per_cycle}",
        f"--online.batch_size={args.batch_size}",
        f"--online.eval_episodes={args.eval_episodes}",
        f"--steps={steps}",
        f"--policy.compile_model={str(args.compile).lower()}",
        f"--env_eval_freq={args.eval_every * args.updates_per_cycle // (args.episodes_per_cycle * HORIZON)}",
        "--save_checkpoint=false",
        f"--seed={seed}",
        f"--output_dir={output_dir}",
    ]
    cfg = draccus.parse(OnlineTrainConfig, args=cli)
    cfg.validate()
    return cfg, cli


def timed_trainer_class():
    from lerobot_indicator.training import online

    class TimedTrainer(online.OnlineTrainer):
        """Records an eval curve with the training wall-clock (evaluation time excluded)."""

        def __init__(self, cfg):
            super().__init__(cfg)
            self.curve: list[dict] = []
            self.clock = {"eval": 0.0, "collect": 0.0, "optimise": 0.0, "start": None}

        def collect(self, *a, **kw):
            if self.clock["start"] is None:
                self.clock["start"] = time.perf_counter()
            t0 = time.perf_counter()
            out = super().collect(*a, **kw)
            self.clock["collect"] += time.perf_counter() - t0
            return out

        def optimise(self, *a, **kw):
            t0 = time.perf_counter()
            out = super().optimise(*a, **kw)
            self.clock["optimise"] += time.perf_counter() - t0
            return out

        def evaluate(self):
            t0 = time.perf_counter()
            result = super().evaluate()
            train_wall = t0 - self.clock["start"] - self.clock["eval"]
            self.clock["eval"] += time.perf_counter() - t0
            self.curve.append(
                {
                    "env_steps": self.progress.env_steps,
                    "updates": self.progress.step,
                    "train_wall_s": train_wall,
                    **result,
                }
            )
            return result

    return TimedTrainer


def run_ours(method: str, seed: int, args: argparse.Namespace) -> dict:
    steps = args.env_steps * args.updates_per_cycle // (args.episodes_per_cycle * HORIZON)
    with tempfile.TemporaryDirectory() as tmp:
        cfg, cli = ours_config(method, seed, args, Path(tmp) / "run", steps)
        trainer = timed_trainer_class()(cfg)
        try:
            trainer.train()
        finally:
            trainer.close()
    return {
        "curve": trainer.curve,
        "collect_wall_s": trainer.clock["collect"],
        "optimise_wall_s": trainer.clock["optimise"],
        "updates": trainer.progress.step,
        "cli": "lerobot-indicator-train " + " ".join(c for c in cli if not c.startswith("--output_dir")),
    }


# ----------------------------------------------------------------------------------------------------------
# update throughput, one process, interleaved
# ----------------------------------------------------------------------------------------------------------
def time_update_arms(method: str, sb3, args: argparse.Namespace) -> dict[str, list[float]]:
    """Seconds per block of ``updates_per_block`` gradient steps for each arm (see ``bench_updates``): ours
    (eager), ours with ``--policy.compile_model=true`` when ``--compile`` is given, and SB3."""
    n = args.updates_per_block
    variants = {"ours": False, **({"ours_compiled": True} if args.compile else {})}
    arms, trainers = {}, []
    with tempfile.TemporaryDirectory() as tmp:
        for name, compiled in variants.items():
            cfg, _ = ours_config(method, 0, args, Path(tmp) / name, steps=max(n, args.updates_per_cycle))
            cfg.online.updates_per_cycle = n
            cfg.policy.compile_model = compiled
            trainer = timed_trainer_class()(cfg)
            g = torch.Generator().manual_seed(0)
            for cycle in range(args.fill_episodes // args.episodes_per_cycle):
                for r in trainer.collect(cycle, g, warmup=True):
                    for episode in r.episodes():
                        trainer.buffer.add_episode(*episode)
            rng = np.random.default_rng(0)
            arms[name] = lambda trainer=trainer, rng=rng, g=g: trainer.optimise(rng, g)
            trainers.append(trainer)

        def sb3_train() -> None:
            sb3.train(gradient_steps=n, batch_size=args.batch_size)

        arms["sb3"] = sb3_train
        names = list(arms)
        flops = {}
        for name in names:  # warm-up (and compilation); matmul FLOPs counted on the eager arms
            if name in ("ours", "sb3"):
                with FlopCounterMode(display=False) as counter:
                    arms[name]()
                flops[name] = counter.get_total_flops() / n
            else:
                arms[name]()
        times: dict[str, list[float]] = {name: [] for name in names}
        for block in range(args.update_blocks):
            k = block % len(names)
            for name in names[k:] + names[:k]:
                t0 = time.perf_counter()
                arms[name]()
                times[name].append(time.perf_counter() - t0)
        for trainer in trainers:
            trainer.close()
    return times, flops


def sgemm_gflops(size: int = 256, repeats: int = 400) -> float:
    """This core's float32 matmul throughput at the update's layer size: the roofline for both libraries."""
    a, b = torch.randn(size, size), torch.randn(size, size)
    for _ in range(20):
        a @ b
    t0 = time.perf_counter()
    for _ in range(repeats):
        a @ b
    return 2 * size**3 * repeats / (time.perf_counter() - t0) / 1e9


def bench_updates(args: argparse.Namespace) -> dict:
    """Gradient updates/s at batch 256 incl. replay sampling (what each library's train step does), both
    buffers filled with the same number of random-action episodes; blocks interleaved, the order of the arms
    rotating every block. Also each library's matmul FLOPs per update (``torch.utils.flop_counter``; the
    compiled arm does the same math as ``ours``) and the share of the core's measured sgemm throughput they
    reach: the headroom left once the matmuls dominate."""
    n = args.updates_per_block
    sb3 = make_sb3(0, args, learning_starts=10**9)
    sb3.learn(total_timesteps=args.fill_episodes * HORIZON)  # random actions, no training
    results = {}
    for method in ("ours_indicator", "ours_oracle"):
        times, flops = time_update_arms(method, sb3, args)
        r = {f"{name}_updates_per_s": n * len(t) / sum(t) for name, t in times.items()}
        flops["ours_compiled"] = flops["ours"]
        for name in times:
            r[f"{name}_matmul_gflop_per_update"] = flops[name] / 1e9
            r[f"{name}_matmul_gflops"] = flops[name] * r[f"{name}_updates_per_s"] / 1e9
        r |= {f"per_block_{name}": [n / x for x in t] for name, t in times.items()}
        for name in (x for x in times if x != "sb3"):
            ratios = [b / s for b, s in zip(times["sb3"], times[name], strict=True)]
            r[f"{name}_over_sb3"] = r[f"{name}_updates_per_s"] / r["sb3_updates_per_s"]
            r[f"{name}_over_sb3_median_of_blocks"] = float(np.median(ratios))
        results[method] = r
        print(
            f"updates/s {method}: "
            + ", ".join(f"{name} {r[f'{name}_updates_per_s']:.1f}" for name in times)
            + "".join(
                f", {name}/SB3 {r[f'{name}_over_sb3']:.2f} (median of blocks {r[f'{name}_over_sb3_median_of_blocks']:.2f})"
                for name in times
                if name != "sb3"
            )
            + "; matmul GFLOP/s "
            + ", ".join(f"{name} {r[f'{name}_matmul_gflops']:.1f}" for name in times),
            flush=True,
        )
    peak = sgemm_gflops()
    for r in results.values():
        for name in [k.removesuffix("_matmul_gflops") for k in r if k.endswith("_matmul_gflops")]:
            r[f"{name}_share_of_sgemm_peak"] = r[f"{name}_matmul_gflops"] / peak
    print(f"sgemm 256x256x256 on this core: {peak:.1f} GFLOP/s", flush=True)
    return {
        "sgemm_gflops_256": peak,
        "batch_size": args.batch_size,
        "filled_episodes": args.fill_episodes,
        "updates_per_block": n,
        "blocks": args.update_blocks,
        **results,
    }


# ----------------------------------------------------------------------------------------------------------
# summary
# ----------------------------------------------------------------------------------------------------------
def summarise_run(run: dict) -> dict:
    curve = run["curve"]
    hit = next((c for c in curve if c["eval_success_rate"] >= SUCCESS_TARGET), None)
    final = curve[-1]
    train_wall = final["train_wall_s"]
    return {
        "env_steps_to_90": hit["env_steps"] if hit else None,
        "train_wall_s_to_90": hit["train_wall_s"] if hit else None,
        "final_success_rate": final["eval_success_rate"],
        "final_distance_m": final["eval_final_distance"],
        "train_wall_s": train_wall,
        "env_steps_per_s_training": final["env_steps"] / train_wall,
        "env_steps_per_s_collecting": final["env_steps"] / run["collect_wall_s"],
    }


def aggregate(runs: list[dict]) -> dict:
    s = [r["summary"] for r in runs]

    def stat(key: str) -> dict:
        vals = [x[key] for x in s if x[key] is not None]
        return {
            "mean": float(np.mean(vals)) if vals else None,
            "median": float(np.median(vals)) if vals else None,
            "n_reached": len(vals),
        }

    keys = ("env_steps_to_90", "train_wall_s_to_90", "final_success_rate", "final_distance_m")
    keys += ("train_wall_s", "env_steps_per_s_training", "env_steps_per_s_collecting")
    return {k: stat(k) for k in keys}


def plot(record: dict, png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(16, 4.2))
    colors = {"sb3_ddpg_her": "tab:gray", "ours_oracle": "tab:blue", "ours_indicator": "tab:red"}
    labels = {
        "sb3_ddpg_her": "SB3 DDPG+HER (GT reward)",
        "ours_oracle": "ours, oracle (GT reward)",
        "ours_indicator": "ours, indicator+balance+filter",
    }
    for method in METHODS:
        runs = [r for r in record["runs"] if r["method"] == method]
        if not runs:
            continue
        for i, r in enumerate(runs):
            steps = [c["env_steps"] for c in r["curve"]]
            wall = [c["train_wall_s"] for c in r["curve"]]
            succ = [c["eval_success_rate"] for c in r["curve"]]
            label = labels[method] if i == 0 else None
            axes[0].plot(steps, succ, color=colors[method], alpha=0.35, lw=1)
            axes[1].plot(wall, succ, color=colors[method], alpha=0.8, lw=1.2, label=label)
        n = min(len(r["curve"]) for r in runs)
        steps = [c["env_steps"] for c in runs[0]["curve"][:n]]
        mean = np.mean([[c["eval_success_rate"] for c in r["curve"][:n]] for r in runs], axis=0)
        axes[0].plot(steps, mean, color=colors[method], lw=2.2, label=f"{labels[method]} (mean)")
    for ax, xlabel in zip(axes[:2], ("env steps", "training wall-clock (s, eval excluded)"), strict=True):
        ax.axhline(SUCCESS_TARGET, color="k", ls=":", lw=0.8)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("eval success rate")
        ax.set_ylim(-0.02, 1.02)
        ax.legend(fontsize=7)
    upd = record["update_throughput"]
    names = ["SB3 DDPG+HER", "ours oracle", "ours indicator"]
    vals = [
        upd["ours_indicator"]["sb3_updates_per_s"],
        upd["ours_oracle"]["ours_updates_per_s"],
        upd["ours_indicator"]["ours_updates_per_s"],
    ]
    axes[2].bar(names, vals, color=[colors[m] for m in METHODS])
    axes[2].set_ylabel("gradient updates/s")
    axes[2].set_title(f"batch {upd['batch_size']}, CPU, incl. replay sampling", fontsize=9)
    for i, v in enumerate(vals):
        axes[2].text(i, v, f"{v:.1f}", ha="center", va="bottom")
    fig.suptitle(
        f"Sawyer reach (state): SB3 {record['versions']['stable_baselines3']} vs lerobot-indicator, "
        f"seeds {record['seeds']}, {record['env_steps_budget']} env steps, "
        f"torch threads {record['torch_threads']}"
    )
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def run_single(args: argparse.Namespace) -> None:
    torch.set_num_threads(args.threads)
    t0 = time.perf_counter()
    run = run_sb3(args.seed, args) if args.run == "sb3_ddpg_her" else run_ours(args.run, args.seed, args)
    run["process_wall_s"] = time.perf_counter() - t0
    Path(args.run_out).write_text(json.dumps(run))


RUN_OPTIONS = (
    "env_steps",
    "eval_every",
    "eval_episodes",
    "episodes_per_cycle",
    "updates_per_cycle",
    "batch_size",
    "lr",
    "noise",
    "threads",
)


def run_options(args: argparse.Namespace) -> list[str]:
    """The options a training-run subprocess needs, from the parent's parsed arguments."""
    return [f"--{k.replace('_', '-')}={getattr(args, k)}" for k in RUN_OPTIONS] + (
        ["--compile"] if args.compile else []
    )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    p.add_argument("--env-steps", type=int, default=5000, help="env-step budget per run")
    p.add_argument("--eval-every", type=int, default=250, help="env steps between evaluations")
    p.add_argument("--eval-episodes", type=int, default=20)
    p.add_argument("--episodes-per-cycle", type=int, default=2)
    p.add_argument("--updates-per-cycle", type=int, default=40)
    p.add_argument("--batch-size", type=int, default=256)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--noise", type=float, default=0.2, help="Gaussian action noise std (both)")
    p.add_argument("--threads", type=int, default=1, help="torch threads in every process")
    p.add_argument(
        "--compile",
        action="store_true",
        help="ours with --policy.compile_model=true: an extra update-throughput arm, and the training runs",
    )
    p.add_argument("--fill-episodes", type=int, default=40, help="update benchmark: episodes in the buffers")
    p.add_argument("--updates-per-block", type=int, default=50)
    p.add_argument("--update-blocks", type=int, default=6)
    p.add_argument("--skip-training", action="store_true", help="only the update-throughput benchmark")
    p.add_argument("--out-dir", type=Path, default=Path("docs/results"))
    p.add_argument("--run", choices=METHODS, help=argparse.SUPPRESS)
    p.add_argument("--seed", type=int, help=argparse.SUPPRESS)
    p.add_argument("--run-out", help=argparse.SUPPRESS)
    args = p.parse_args()
    cycle_steps = args.episodes_per_cycle * HORIZON
    if args.eval_every % cycle_steps or args.env_steps % cycle_steps:
        p.error(f"--eval-every and --env-steps must be multiples of one cycle ({cycle_steps} env steps)")
    if args.run:
        run_single(args)
        return

    import stable_baselines3

    command = "python " + " ".join(sys.argv)
    load_start = os.getloadavg()
    t_start = time.perf_counter()
    torch.set_num_threads(args.threads)
    update_throughput = bench_updates(args)
    runs = []
    if not args.skip_training:
        with tempfile.TemporaryDirectory() as tmp:
            for seed in args.seeds:
                for method in args.methods:
                    out = Path(tmp) / f"{method}_{seed}.json"
                    cmd = [sys.executable, __file__, *run_options(args), "--run", method, "--seed", str(seed)]
                    subprocess.run([*cmd, "--run-out", str(out)], check=True)
                    run = json.loads(out.read_text())
                    run |= {"method": method, "seed": seed, "summary": summarise_run(run)}
                    runs.append(run)
                    print(f"{method} seed {seed}: {json.dumps(run['summary'])}", flush=True)
    record = {
        "command": command,
        "machine": {"cpus": os.cpu_count(), "cpu": platform.processor() or platform.machine()},
        "load_average_1_5_15_min": {"start": load_start, "end": os.getloadavg()},
        "bench_wall_s": time.perf_counter() - t_start,
        "torch_threads": args.threads,
        "versions": {
            "stable_baselines3": stable_baselines3.__version__,
            "torch": torch.__version__,
            "numpy": np.__version__,
            "python": platform.python_version(),
        },
        "seeds": args.seeds,
        "env_steps_budget": args.env_steps,
        "settings": {k: getattr(args, k) for k in RUN_OPTIONS}
        | {
            "gamma": 1 - 1 / HORIZON,
            "target_smoothing": 0.98,
            "hidden": [256, 256, 256],
            "activation": "tanh",
        },
        "protocol_differences": PROTOCOL_DIFFERENCES,
        "update_throughput": update_throughput,
        "summary": {m: aggregate([r for r in runs if r["method"] == m]) for m in args.methods}
        if runs
        else {},
        "runs": runs,
    }
    if runs:
        sb3 = record["summary"].get("sb3_ddpg_her", {}).get("env_steps_to_90", {}).get("mean")
        ind = record["summary"].get("ours_indicator", {}).get("env_steps_to_90", {}).get("mean")
        record["ratio_env_steps_to_90_indicator_over_sb3"] = ind / sb3 if sb3 and ind else None
    args.out_dir.mkdir(parents=True, exist_ok=True)
    # --skip-training records only the update benchmark: its own file, so it never replaces a full run.
    name = "vs_sb3.json" if runs else "vs_sb3_updates.json"
    (args.out_dir / name).write_text(json.dumps(record, indent=2) + "\n")
    if runs:
        plot(record, args.out_dir / "vs_sb3.png")
    print(json.dumps(record["summary"], indent=1))


if __name__ == "__main__":
    main()
