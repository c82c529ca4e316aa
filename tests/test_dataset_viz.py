"""LeRobot's own visualiser opens a dataset recorded by our recorder (RGB-D, depth maps, goal images)."""

import os
import subprocess
import sys
from pathlib import Path

from lerobot_indicator.data.recorder import RecordConfig, record
from lerobot_indicator.envs.configs import SawyerReachEnvConfig

BIN = Path(sys.executable).parent


def test_lerobot_dataset_viz_saves_a_recording_of_our_dataset(tmp_path):
    root, out = tmp_path / "ds", tmp_path / "viz"
    env = SawyerReachEnvConfig(obs_type="rgbd", episode_length=3)
    record(RecordConfig(env=env, repo_id="local/viz", root=root, policy="random", num_episodes=1))
    cmd = [
        str(BIN / "lerobot-dataset-viz"),
        "--repo-id=local/viz",
        f"--root={root}",
        "--episode-index=0",
        "--save=1",
        f"--output-dir={out}",
        "--num-workers=0",
    ]
    proc = subprocess.run(
        cmd, capture_output=True, text=True, timeout=300, env={**os.environ, "HF_HUB_OFFLINE": "1"}
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    rrd = out / "local_viz_episode_0.rrd"
    assert rrd.stat().st_size > 10_000  # the frames, not just a header
