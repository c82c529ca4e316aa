"""Bad input to the CLIs ends in one line that names the field or key, not a generic parser error."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

BIN = Path(sys.executable).parent


@pytest.mark.parametrize(
    "cli",
    [
        ["lerobot-indicator-train", "--env.type=sawyer_reach"],
        ["lerobot-train", "--dataset.repo_id=user/none", "--policy.push_to_hub=false"],
    ],
)
def test_a_goal_key_as_observation_key_is_named(cli):
    cmd = [str(BIN / cli[0]), *cli[1:], "--policy.type=indicator_ddpg"]
    cmd.append("--policy.observation_keys=[observation.goal_state]")
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "MUJOCO_GL": "egl"}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode != 0
    assert "observation_keys: 'observation.goal_state' is a goal key" in proc.stdout + proc.stderr


def test_lerobot_train_prints_one_line_for_the_torchcodec_fallback_and_no_traceback():
    cmd = [str(BIN / "lerobot-train"), "--dataset.repo_id=user/none", "--policy.type=indicator_ddpg"]
    cmd.append("--policy.observation_keys=[observation.goal_state]")
    proc = subprocess.run(
        cmd, capture_output=True, text=True, timeout=300, env={**os.environ, "HF_HUB_OFFLINE": "1"}
    )
    out = proc.stdout + proc.stderr
    assert "libtorchcodec loading traceback" not in out and "Traceback" not in out, out[-3000:]


def test_an_rgbd_env_left_open_exits_without_renderer_tracebacks():
    code = (
        "import gymnasium as gym, lerobot_indicator\n"
        "env = gym.make('lerobot_indicator/SawyerReach-v0', obs_type='rgbd')\n"
        "env.reset(seed=0)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "MUJOCO_GL": "egl"})  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "Exception ignored" not in proc.stderr and "__del__" not in proc.stderr, proc.stderr[-2000:]
