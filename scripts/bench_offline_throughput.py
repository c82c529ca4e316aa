"""Samples/s of the two offline paths on one recorded RGB-D dataset: ``lerobot-train`` and
``lerobot-indicator-train --dataset.* --online.episodes_per_cycle=0`` (in-memory buffer).

Records ``--episodes`` RGB-D reach episodes with the recorder, then runs both trainers for a few steps at
``--batch_size`` and reads their own timings: lerobot-train's logged ``data_s`` / ``updt_s`` (the last
logged step's values; LeRobot logs the max over the log window), the online trainer's wall time per cycle.

    python scripts/bench_offline_throughput.py --out docs/results/offline_throughput.json
"""

import argparse
import json
import os
import re
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BIN = Path(sys.executable).parent
ENV = {**os.environ, "HF_HUB_OFFLINE": "1", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}


def run(cmd: list[str]) -> str:
    proc = subprocess.run(cmd, capture_output=True, text=True, env=ENV)
    if proc.returncode != 0:
        raise RuntimeError(f"{shlex.join(cmd)} failed:\n{proc.stderr[-3000:]}")
    return proc.stdout + proc.stderr


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--batch_size", type=int, default=128)
    parser.add_argument("--steps", type=int, default=6)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    env_args = ["--env.type=sawyer_reach", "--env.obs_type=rgbd", f"--env.camera.height={args.size}",
                f"--env.camera.width={args.size}"]  # fmt: skip
    record = {"command": shlex.join(["python", *sys.argv]), "load_average_1_5_15_min_before": os.getloadavg()}
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "ds"
        run([str(BIN / "lerobot-indicator-record"), *env_args, "--policy=noisy_scripted",
             f"--num_episodes={args.episodes}", "--repo_id=bench/rgbd", f"--root={root}"])  # fmt: skip
        common = ["--policy.type=indicator_ddpg", "--policy.push_to_hub=false", "--policy.device=cpu"]
        log = run([str(BIN / "lerobot-train"), *common, "--dataset.repo_id=bench/rgbd", f"--dataset.root={root}",
                   f"--batch_size={args.batch_size}", f"--steps={args.steps}", "--log_freq=1", "--num_workers=0",
                   "--save_checkpoint=false", "--wandb.enable=false", f"--output_dir={Path(tmp) / 'lt'}"])  # fmt: skip
        data_s = [float(x) for x in re.findall(r"data_s:([0-9.]+)", log)][1:]  # the first step warms up
        updt_s = [float(x) for x in re.findall(r"updt_s:([0-9.]+)", log)][1:]
        step_s = (sum(data_s) + sum(updt_s)) / len(data_s)
        record["lerobot_train"] = {
            "data_s_per_step": sum(data_s) / len(data_s),
            "update_s_per_step": sum(updt_s) / len(updt_s),
            "samples_per_s": args.batch_size / step_s,
            "loading_share_of_step": sum(data_s) / (sum(data_s) + sum(updt_s)),
        }
        out = Path(tmp) / "online"
        t0 = time.perf_counter()
        run([str(BIN / "lerobot-indicator-train"), *env_args, *common, "--dataset.repo_id=bench/rgbd",
             f"--dataset.root={root}", "--online.episodes_per_cycle=0", f"--online.batch_size={args.batch_size}",
             f"--online.updates_per_cycle={args.steps * 5}", f"--steps={args.steps * 10}", "--env_eval_freq=0",
             "--online.eval_episodes=1", "--save_checkpoint=false", f"--output_dir={out}"])  # fmt: skip
        total_s = time.perf_counter() - t0
        rows = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
        # The dataset is decoded into the buffer before the first cycle; a cycle is sampling + updates.
        cycle_s = rows[1]["wall_time_s"] - rows[0]["wall_time_s"]
        record["online_trainer_offline"] = {
            "process_wall_s": total_s,
            "first_cycle_s": rows[0]["wall_time_s"],
            "updates_per_s": args.steps * 5 / cycle_s,
            "samples_per_s": args.steps * 5 * args.batch_size / cycle_s,
        }
    record["online_over_lerobot_train_samples_per_s"] = (
        record["online_trainer_offline"]["samples_per_s"] / record["lerobot_train"]["samples_per_s"]
    )
    print(json.dumps(record, indent=1))
    args.out.write_text(json.dumps(record, indent=2) + "\n")


if __name__ == "__main__":
    main()
