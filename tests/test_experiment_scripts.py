"""The experiment helpers: the no-movement reference distance and the comparison plot that draws it."""

import json
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

import lerobot_indicator  # noqa: F401  (registers the gym ids)
from lerobot_indicator.training.online import EVAL_SEED_OFFSET

ROOT = Path(__file__).resolve().parents[1]


def test_start_distance_is_the_eval_goals_distance_at_reset(tmp_path):
    out = tmp_path / "start_distance_reach_state.json"
    cmd = [
        sys.executable,
        "scripts/start_distance.py",
        "--env.type=sawyer_reach",
        "--episodes=2",
        f"--out={out}",
    ]
    subprocess.run(cmd, cwd=ROOT, check=True, env={**os.environ, "MUJOCO_GL": "egl"}, capture_output=True)
    record = json.loads(out.read_text())
    env = gym.make("lerobot_indicator/SawyerReach-v0", obs_type="state")
    try:
        expected = [env.reset(seed=EVAL_SEED_OFFSET + i)[1]["gt_distance"] for i in range(2)]
    finally:
        env.close()
    np.testing.assert_allclose(record["start_distances"], expected, rtol=1e-6)
    assert record["start_distance_mean"] == np.mean(record["start_distances"])
    assert record["command"].startswith("python ")

    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import experiments
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    reference = experiments.start_distances(tmp_path, ["reach_state", "rope_state"])
    assert reference == {"reach_state": record["start_distance_mean"]}
