"""``lerobot-rollout`` runs a trained policy toward a goal image with no hardware: the simulated Sawyer reach robot
(``--robot.type=indicator_sim_reach``, lerobot_indicator/envs/sim_robot.py) and ``--policy.goal_path``."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

BIN = Path(sys.executable).parent
REPO_ID, SIZE, T = "local/sim_reach_rgb", 32, 6


def env() -> dict[str, str]:
    return {**os.environ, "HF_HUB_OFFLINE": "1", "CUDA_VISIBLE_DEVICES": "", "MUJOCO_GL": "egl"}


def run(cmd: list[str], check: bool = True) -> subprocess.CompletedProcess:
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env())
    if check:
        assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-6000:]
    return proc


@pytest.fixture(scope="module")
def policy_and_goal(tmp_path_factory) -> tuple[Path, Path]:
    """An RGB reach policy (2 lerobot-train steps on a tiny recording) and a goal saved from a recorded frame."""
    tmp = tmp_path_factory.mktemp("rollout")
    data, out, goal = tmp / "data", tmp / "train", tmp / "goal"
    run([str(BIN / "lerobot-indicator-record"), "--env.type=sawyer_reach", "--env.obs_type=rgb",
         f"--env.episode_length={T}", f"--env.camera.height={SIZE}", f"--env.camera.width={SIZE}",
         "--env.camera.use_depth=false", f"--repo_id={REPO_ID}", f"--root={data}", "--num_episodes=2",
         "--policy=noisy_scripted", "--push_to_hub=false"])  # fmt: skip
    run([str(BIN / "lerobot-train"), "--policy.type=indicator_ddpg", f"--dataset.repo_id={REPO_ID}",
         f"--dataset.root={data}", "--policy.push_to_hub=false", "--policy.device=cpu", "--policy.future_offsets=[2,3]",
         "--policy.hidden_dims=[16,16,16]", "--batch_size=4", "--num_workers=0", "--steps=2", "--save_freq=2",
         "--wandb.enable=false", f"--output_dir={out}"])  # fmt: skip
    run([sys.executable, "-m", "lerobot_indicator.policy.goal_observations", f"--dataset.repo_id={REPO_ID}",
         f"--dataset.root={data}", "--episode=1", "--frame=-1", f"--output_dir={goal}"])  # fmt: skip
    return out / "checkpoints" / "last" / "pretrained_model", goal


def rollout(policy: Path, trace: Path, goal: Path | None) -> subprocess.CompletedProcess:
    goal_flag = [f"--policy.goal_path={goal}"] if goal else []
    return run([str(BIN / "lerobot-rollout"), "--strategy.type=base", f"--policy.path={policy}", *goal_flag,
                "--robot.type=indicator_sim_reach", f"--robot.camera_size={SIZE}", f"--robot.trace_path={trace}",
                "--duration=1", "--fps=10", "--play_sounds=false", "--return_to_initial_position=false",
                "--task=reach", "--device=cpu"], check=False)  # fmt: skip


def test_lerobot_rollout_drives_the_sim_robot_with_the_saved_goal(policy_and_goal, tmp_path):
    policy, goal = policy_and_goal
    proc = rollout(policy, tmp_path / "trace.jsonl", goal)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-6000:]
    ticks = [json.loads(line) for line in (tmp_path / "trace.jsonl").read_text().splitlines()]
    assert len(ticks) >= 3  # 1 s at 10 fps, minus start-up
    actions = np.array([t["action"] for t in ticks])
    assert actions.shape[1] == 3 and np.isfinite(actions).all() and np.abs(actions).max() <= 1.0
    assert all(np.isfinite(t["gt_distance"]) for t in ticks)


def test_lerobot_rollout_without_a_goal_names_the_goal_key_and_the_flag(policy_and_goal, tmp_path):
    policy, _ = policy_and_goal
    proc = rollout(policy, tmp_path / "trace.jsonl", None)
    out = proc.stdout + proc.stderr
    assert proc.returncode != 0
    assert "observation.images.goal_front" in out and "--policy.goal_path" in out
    assert not (tmp_path / "trace.jsonl").exists()  # no action reached the robot
