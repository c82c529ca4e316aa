"""Time per env step and per update of the Gym task presets not run here (docs/results/gym_tasks/README.md).

For each task preset of ``benchmarks/experiments/presets.py`` (``TASKS``): random-action env steps/s of our env
(resets included: each renders the goal images), and gradient updates/s of ``lerobot-indicator-train`` with the
Indicator+Balance+Filter arm over ``--cycles`` cycles of the preset (the first cycle, which builds the buffers,
left out); then the hours one (task, method, seed) run of the preset's budget takes at those rates, evaluation
included. Writes ``docs/results/gym_tasks/speed.json``.

    MUJOCO_GL=egl OMP_NUM_THREADS=1 python benchmarks/speed/run_gym_task_cost.py \
        --tasks fetch_reach_state fetch_push_state fetch_reach_rgbd reacher_rgb
"""

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import draccus
import gymnasium as gym
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository root (benchmarks/)
from benchmarks.experiments.presets import METHODS, TASKS  # noqa: E402
from benchmarks.records import command_line, git_commit, machine_record  # noqa: E402

ARM = "indicator_balance_filter"
GYM_IDS = {
    "reacher": "lerobot_indicator/Reacher-v0",
    "fetch_reach": "lerobot_indicator/FetchReach-v0",
    "fetch_push": "lerobot_indicator/FetchPush-v0",
}


def env_config(task: str):
    from lerobot_indicator.training.config import OnlineTrainConfig

    args = [*TASKS[task].env_args, "--policy.type=indicator_ddpg", "--policy.push_to_hub=false"]
    cfg = draccus.parse(OnlineTrainConfig, args=[*args, "--output_dir=/tmp/unused"])
    return cfg.env


def env_steps_per_s(task: str, n: int) -> dict:
    import lerobot_indicator  # noqa: F401  (registers the ids)

    cfg = env_config(task)
    env = gym.make(GYM_IDS[cfg.type], obs_type=cfg.obs_type)  # the presets keep the default 100x100 camera
    obs, _ = env.reset(seed=0)
    env.action_space.seed(0)
    t0, resets = time.perf_counter(), 0
    for _ in range(n):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
            resets += 1
    seconds = time.perf_counter() - t0
    env.close()
    return {
        "env_steps_per_s": n / seconds,
        "steps": n,
        "resets": resets,
        "obs_type": cfg.obs_type,
        "image_shape": list(obs["pixels"]["front"].shape) if "pixels" in obs else None,
    }


def updates_per_s(task: str, cycles: int) -> dict:
    preset = TASKS[task]
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [
            str(Path(sys.executable).parent / "lerobot-indicator-train"),
            *preset.env_args,
            "--policy.type=indicator_ddpg",
            "--policy.push_to_hub=false",
            "--policy.device=cpu",
            *METHODS[ARM],
            f"--steps={cycles * preset.updates_per_cycle}",
            "--online.n_envs=1",
            "--online.use_async_envs=false",
            f"--online.episodes_per_cycle={preset.episodes_per_cycle}",
            f"--online.updates_per_cycle={preset.updates_per_cycle}",
            "--online.eval_episodes=1",
            f"--env_eval_freq={10**9}",
            "--save_checkpoint=false",
            "--cpu_threads=1",
            f"--output_dir={tmp}/run",
        ]
        subprocess.run(cmd, check=True, capture_output=True)
        rows = [json.loads(line) for line in (Path(tmp) / "run/metrics.jsonl").read_text().splitlines()]
    rows = [r for r in rows if "update_s" in r][1:]
    update_s = float(np.sum([r["update_s"] + r.get("data_s", 0.0) for r in rows]))
    walls = [r["wall_time_s"] for r in rows]
    return {
        "updates_per_s": preset.updates_per_cycle * len(rows) / update_s,
        "cycles_timed": len(rows),
        "cycle_wall_s": float(np.mean(np.diff(walls))) if len(walls) > 1 else None,
        "command": " ".join(cmd[:1] + [c for c in cmd[1:] if not c.startswith("--output_dir")]),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--tasks",
        nargs="+",
        default=["fetch_reach_state", "fetch_push_state", "fetch_reach_rgbd", "reacher_rgb"],
    )
    p.add_argument("--env-steps", type=int, default=500)
    p.add_argument("--cycles", type=int, default=3)
    p.add_argument(
        "--out", type=Path, default=Path(__file__).resolve().parents[2] / "docs/results/gym_tasks/speed.json"
    )
    args = p.parse_args()
    record = {
        "command": command_line(),
        "commit": git_commit(),
        "machine": machine_record(),
        "arm": ARM,
        "tasks": {},
    }
    for task in args.tasks:
        preset = TASKS[task]
        env = env_steps_per_s(task, args.env_steps)
        upd = updates_per_s(task, args.cycles)
        horizon = env_config(task).episode_length
        env_steps = preset.steps * preset.episodes_per_cycle * horizon // preset.updates_per_cycle
        eval_steps = preset.steps // preset.env_eval_freq * preset.eval_episodes * horizon
        hours = (
            preset.steps / upd["updates_per_s"] + (env_steps + eval_steps) / env["env_steps_per_s"]
        ) / 3600
        record["tasks"][task] = {
            **env,
            **upd,
            "preset": {"updates": preset.steps, "env_steps": env_steps, "eval_env_steps": eval_steps},
            "estimated_hours_per_run": hours,
            "estimated_hours_3_arms_3_seeds": 9 * hours,
        }
        print(task, json.dumps(record["tasks"][task]), flush=True)
        args.out.write_text(json.dumps(record, indent=2) + "\n")


if __name__ == "__main__":
    main()
