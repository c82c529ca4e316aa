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
