"""The own-data loop's recordings (benchmarks/experiments/own_data_loop.py): LeRobot's own API, no goal column,
and a scripted teleoperator that drives the arm to places."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("gymnasium_robotics")


def test_the_scripted_teleoperator_drives_the_fingertip_to_its_point(monkeypatch):
    import gymnasium as gym

    from benchmarks.experiments import own_data_loop
    from lerobot_indicator.envs import REACHER_ID

    monkeypatch.setenv("MUJOCO_GL", "egl")
    env = gym.make(REACHER_ID, obs_type="state")
    rng = np.random.default_rng(0)
    ends, starts = [], []
    for seed in range(6):
        obs, _ = env.reset(seed=seed)
        act, points = own_data_loop.teleop_actions(env, rng, own_data_loop.HORIZON)
        last = points[-1]  # where the episode should end
        starts.append(np.linalg.norm(obs["agent_pos"] - last))
        for _ in range(own_data_loop.HORIZON):
            action = act()
            assert action.shape == (2,) and np.all(np.abs(action) <= 1.0)
            obs, *_ = env.step(action)
        ends.append(np.linalg.norm(obs["agent_pos"] - last))
    env.close()
    # Driven, not random: every episode ends near its last point (noise of 0.3 keeps it within a few cm).
    assert max(ends) < 0.03 and np.mean(ends) < 0.1 * np.mean(starts)


def test_recordings_hold_no_goal_reward_or_ground_truth_column(tmp_path, monkeypatch):
    from lerobot.datasets import LeRobotDataset

    from benchmarks.experiments import own_data_loop

    monkeypatch.setenv("MUJOCO_GL", "egl")
    for exploration in own_data_loop.EXPLORATION:
        root = tmp_path / exploration
        out = own_data_loop.record(root, n_episodes=2, seed=0, exploration=exploration)
        ds = LeRobotDataset(own_data_loop.repo_id(exploration), root=root)
        assert out["frames"] == len(ds) == 2 * (own_data_loop.HORIZON + 1)
        keys = set(ds.meta.features)
        assert {own_data_loop.STATE, own_data_loop.ENV_STATE, "action"} <= keys
        assert not any("goal" in k or "reward" in k or k.startswith("observation.gt_") for k in keys)
