"""`make demo` / `make demo-rgbd`: train indicator_ddpg online on Sawyer reach (state, or RGB-D images only),
then evaluate it with lerobot-eval.

Everything runs through the installed console scripts, so the printed commands are exactly what a user
would type. Prints the success rate and where the checkpoint, eval videos and learning curve are.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from lerobot_indicator.training.plots import read_metrics

BIN = Path(sys.executable).parent

COMMON = [
    "--policy.type=indicator_ddpg",
    "--policy.device=cpu",
    "--policy.push_to_hub=false",
    "--online.n_envs=2",
]


@dataclass
class DemoPreset:
    """``make demo`` / ``make demo-rgbd``: a budget that trains a working policy on a 2-core CPU."""

    env_args: list[str]
    train_args: list[str]
    description: str


DEMOS: dict[str, DemoPreset] = {
    "state": DemoPreset(
        ["--env.type=sawyer_reach", "--env.obs_type=state"],
        [
            "--steps=2400",
            "--online.episodes_per_cycle=4",
            "--online.updates_per_cycle=40",
            "--online.eval_episodes=20",
            "--env_eval_freq=400",
            "--save_freq=2400",
            "--seed=1",
        ],
        "indicator_ddpg on state-based Sawyer reach",
    ),
    # From pixels only: the policy compares and sees the 64x64 RGB-D camera (its default keys), never the state.
    "rgbd": DemoPreset(
        ["--env.type=sawyer_reach", "--env.obs_type=rgbd", "--env.camera.height=64", "--env.camera.width=64"],
        [
            # The policy's defaults with images (--policy.preset=auto: 3-step targets, the inverse-dynamics
            # loss, the return-scaled critic output) learn reach from pixels (docs/results/experiments_rgbd/);
            # 10,000 env steps: this seed's evaluations reach 0.80 only at 8000 and 0.95-1.00 from 9000 on
            # (docs/results/demo_rgbd.json), so the budget keeps a margin over the demo's 80% bar.
            # Both cores for the updates: the demo has the machine to itself (1 thread is the default because
            # concurrent runs on 2 cores are slower with 2 threads each; docs/results/policy_updates.json).
            "--cpu_threads=2",
            "--steps=10000",
            "--online.episodes_per_cycle=4",
            "--online.updates_per_cycle=100",
            "--online.eval_episodes=20",
            "--env_eval_freq=1000",
            "--save_freq=10000",
            "--seed=1",
        ],
        "indicator_ddpg on Sawyer reach from 64x64 RGB-D images",
    ),
}


def run(cmd: list[str]) -> None:
    print("\n$ " + shlex.join(str(c) for c in cmd), flush=True)
    subprocess.run(cmd, check=True, env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")})


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    stamp = dt.datetime.now().strftime("%Y-%m-%d_%H-%M-%S")
    parser.add_argument("--preset", choices=sorted(DEMOS), default="state")
    parser.add_argument("--output_dir", type=Path, default=None, help="default: outputs/demo[_rgbd]/<time>")
    parser.add_argument("--eval_episodes", type=int, default=50)
    parser.add_argument("--min_success", type=float, default=80.0, help="exit non-zero below this pc_success")
    args = parser.parse_args()
    demo = DEMOS[args.preset]
    suffix = "" if args.preset == "state" else f"_{args.preset}"
    out: Path = args.output_dir or Path(f"outputs/demo{suffix}") / stamp
    train_dir, eval_dir = out / "train", out / "eval"

    t0 = time.perf_counter()
    run(
        [
            BIN / "lerobot-indicator-train",
            *demo.env_args,
            *COMMON,
            *demo.train_args,
            f"--output_dir={train_dir}",
        ]
    )
    train_s = time.perf_counter() - t0
    checkpoint = (train_dir / "checkpoints" / "last" / "pretrained_model").resolve()

    t1 = time.perf_counter()
    run(
        [
            BIN / "lerobot-eval",
            f"--policy.path={checkpoint}",
            *demo.env_args,
            # lerobot-eval's avg_sum_reward becomes minus the mean final distance to the goal.
            "--env.eval_reward=final_distance",
            f"--eval.n_episodes={args.eval_episodes}",
            "--eval.batch_size=10",
            "--eval.use_async_envs=false",
            "--policy.device=cpu",
            f"--output_dir={eval_dir}",
        ]
    )
    eval_s = time.perf_counter() - t1
    info = json.loads((eval_dir / "eval_info.json").read_text())["overall"]
    summary = {
        "pc_success": info["pc_success"],
        "n_episodes": info.get("n_episodes", args.eval_episodes),
        "mean_final_distance_m": -info["avg_sum_reward"],
        "train_wall_s": round(train_s, 1),
        "eval_wall_s": round(eval_s, 1),
        "checkpoint": str(checkpoint),
        "eval_videos": str(eval_dir / "videos"),
        "learning_curve": str((train_dir / "learning_curve.png").resolve()),
        "metrics": str((train_dir / "metrics.jsonl").resolve()),
    }
    print(f"\n==== demo: {demo.description} ====")
    print(f"success rate (lerobot-eval, {summary['n_episodes']} episodes): {summary['pc_success']:.1f}%")
    print(f"mean final distance to the goal (lerobot-eval): {summary['mean_final_distance_m']:.3f} m")
    metrics = read_metrics(train_dir / "metrics.jsonl")
    last = metrics[-1]
    summary["trainer_eval"] = {k: last[k] for k in ("env_steps", "eval_success_rate", "eval_final_distance")}
    print(
        f"trainer's own eval (final step, {last['env_steps']} env steps): success "
        f"{last['eval_success_rate']:.2f}, mean final distance {last['eval_final_distance']:.3f} m"
    )
    print(f"training {train_s:.0f} s, evaluation {eval_s:.0f} s")
    for key in ("checkpoint", "eval_videos", "learning_curve", "metrics"):
        print(f"{key:>15}: {summary[key]}")
    summary["command"] = shlex.join([sys.executable, *sys.argv])
    summary["preset"] = args.preset
    (out / "demo_summary.json").write_text(json.dumps(summary, indent=2))
    if summary["pc_success"] < args.min_success:
        print(f"FAILED: success {summary['pc_success']:.1f}% < {args.min_success}%", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
