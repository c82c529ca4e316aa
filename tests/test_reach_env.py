"""Sawyer reach env: spaces, solvability, bit-exact goal observations, determinism."""

import os
from contextlib import closing

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
pytest.importorskip("robosuite")
pytest.importorskip("mujoco")

import gymnasium as gym  # noqa: E402

from lerobot_indicator.envs import SAWYER_REACH_ID  # noqa: E402
from lerobot_indicator.envs.sawyer_reach import SawyerReachEnv  # noqa: E402

SMALL_CAMERA = {"width": 48, "height": 40}


def scripted_action(obs):
    """Proportional controller: full speed towards the goal, saturating at the step size."""
    return np.clip((obs["goal_state"] - obs["agent_pos"]) / 0.05, -1.0, 1.0)


@pytest.fixture(scope="module")
def state_env():
    with closing(SawyerReachEnv(obs_type="state")) as env:
        yield env


@pytest.fixture(scope="module")
def rgbd_env():
    with closing(SawyerReachEnv(obs_type="rgbd", camera=SMALL_CAMERA)) as env:
        yield env


def test_registered_gym_id_builds_with_time_limit():
    env = gym.make(SAWYER_REACH_ID, disable_env_checker=True)
    try:
        assert env.spec.max_episode_steps == 25
        obs, info = env.reset(seed=0)
        assert set(obs) == {"agent_pos", "goal_state"}
        assert env.unwrapped.metadata["render_fps"] == 20
    finally:
        env.close()


def test_rgbd_spaces_shapes_and_dtypes(rgbd_env):
    obs, info = rgbd_env.reset(seed=0)
    assert rgbd_env.observation_space.contains(obs)
    assert obs["agent_pos"].dtype == np.float32 and obs["agent_pos"].shape == (3,)
    assert obs["goal_state"].dtype == np.float32 and obs["goal_state"].shape == (3,)
    for key in ("front", "goal_front"):
        assert obs["pixels"][key].shape == (40, 48, 3) and obs["pixels"][key].dtype == np.uint8
    for key in ("front_depth", "goal_front_depth"):
        assert obs[key].shape == (40, 48, 1) and obs[key].dtype == np.uint16
        # the table and robot are 0.7-2.5 m from the camera: millimetres, not metres
        assert 500 < np.median(obs[key]) < 3000
    assert rgbd_env.action_space.shape == (3,)
    assert set(info) == {"gt_achieved_goal", "gt_desired_goal", "gt_distance", "is_success"}
    frame = rgbd_env.render()
    assert frame.shape == (40, 48, 3) and frame.dtype == np.uint8
    obs2, reward, terminated, truncated, info2 = rgbd_env.step(rgbd_env.action_space.sample())
    assert rgbd_env.observation_space.contains(obs2)
    assert reward in (-1.0, 1.0) and not terminated and not truncated


def test_action_moves_at_most_step_size_and_stays_in_bounds(state_env):
    obs, _ = state_env.reset(seed=3, options={"start_pos": [0.28, 0.0, 1.0]})
    for _ in range(4):
        prev = obs["agent_pos"]
        obs, *_ = state_env.step(np.array([1.0, 0.0, 0.0]))
        assert obs["agent_pos"][0] <= 0.3 + 0.01  # clipped to the bounds (weld error < 1 cm)
        assert np.all(np.abs(obs["agent_pos"] - prev) <= 0.05 + 0.01)


def test_scripted_controller_reaches_95_percent_of_50_seeded_goals(state_env):
    successes, distances = [], []
    for seed in range(50):
        obs, _ = state_env.reset(seed=seed)
        for _ in range(25):
            obs, _, _, _, info = state_env.step(scripted_action(obs))
        successes.append(info["is_success"])
        distances.append(info["gt_distance"])
    assert np.mean(successes) >= 0.95, f"success {np.mean(successes):.2f}, distances {np.round(distances, 3)}"


def test_goal_is_reachable_and_matches_the_sampled_point(state_env):
    for seed in range(5):
        _, info = state_env.reset(seed=seed)
        assert np.linalg.norm(info["gt_desired_goal"] - state_env._goal_target) < 0.01


def test_goal_observation_equals_observation_at_goal_state(rgbd_env):
    goal = [0.1, -0.2, 1.0]
    obs, info = rgbd_env.reset(seed=0, options={"goal_pos": goal, "start_pos": goal})
    assert np.array_equal(obs["pixels"]["front"], obs["pixels"]["goal_front"])
    assert np.array_equal(obs["front_depth"], obs["goal_front_depth"])
    assert np.array_equal(obs["agent_pos"], obs["goal_state"])
    assert info["is_success"]
    # ... and not when the arm is elsewhere: the comparison can fail
    obs, _ = rgbd_env.reset(seed=0, options={"goal_pos": goal, "start_pos": [-0.2, 0.2, 1.2]})
    assert not np.array_equal(obs["pixels"]["front"], obs["pixels"]["goal_front"])


def test_same_state_renders_bit_identical_across_restore_and_reset(rgbd_env):
    obs, _ = rgbd_env.reset(seed=5)
    for _ in range(3):
        obs, *_ = rgbd_env.step(np.array([0.5, -0.3, 0.2]))
    state = rgbd_env.save_state()
    again = rgbd_env._camera_obs()
    assert np.array_equal(again["front"], obs["pixels"]["front"])  # same state twice
    rgbd_env.reset(seed=6)  # a different episode (goal rendered, state overwritten) ...
    rgbd_env.restore_state(state)  # ... then back
    restored = rgbd_env._camera_obs()
    assert np.array_equal(restored["front"], obs["pixels"]["front"])
    assert np.array_equal(restored["front_depth"], obs["front_depth"])
    # rendering the goal restores the exact simulator state
    rgbd_env._render_goal_observation()
    assert np.array_equal(rgbd_env.save_state(), state)


def test_seeded_reset_and_rollout_are_deterministic(rgbd_env):
    def rollout(seed):
        obs, _ = rgbd_env.reset(seed=seed)
        frames = [obs["pixels"]["front"], obs["pixels"]["goal_front"], obs["front_depth"]]
        rng = np.random.default_rng(seed)
        for _ in range(3):
            obs, *_ = rgbd_env.step(rng.uniform(-1, 1, 3))
            frames += [obs["pixels"]["front"], obs["front_depth"], obs["agent_pos"]]
        return frames

    first, second, other = rollout(11), rollout(11), rollout(12)
    assert all(np.array_equal(a, b) for a, b in zip(first, second, strict=True))
    assert not np.array_equal(first[1], other[1])


def test_bad_arguments_fail_clearly():
    with pytest.raises(ValueError, match="obs_type"):
        SawyerReachEnv(obs_type="depth")
    with pytest.raises(ValueError, match="epsilon"):
        SawyerReachEnv(epsilon=0)
    with pytest.raises(ValueError, match="use_depth"):
        SawyerReachEnv(obs_type="rgbd", camera={"use_depth": False})


def test_reset_option_outside_bounds_is_rejected(state_env):
    with pytest.raises(ValueError, match="goal_pos"):
        state_env.reset(seed=0, options={"goal_pos": [2.0, 0.0, 1.0]})


def test_missing_robosuite_error_names_the_fix(monkeypatch):
    import builtins

    from lerobot_indicator.envs._robosuite import ROBOSUITE_FIX, require_robosuite

    real_import = builtins.__import__

    def fake_import(name, *args, **kwargs):
        if name == "robosuite":
            raise ImportError("No module named 'robosuite'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake_import)
    with pytest.raises(ImportError) as err:
        require_robosuite()
    assert "pip install --no-deps robosuite==1.5.2" in str(err.value) and ROBOSUITE_FIX in str(err.value)


@pytest.mark.parametrize("eval_reward", ["success", "final_distance"])
def test_eval_reward_modes(eval_reward):
    """The env reward is for evaluation only; "final_distance" makes lerobot-eval's avg_sum_reward equal
    minus the mean final distance (0 on every step but the last)."""
    env = gym.make(SAWYER_REACH_ID, max_episode_steps=4, episode_length=4, eval_reward=eval_reward)
    obs, _ = env.reset(seed=3)
    rewards, infos = [], []
    for _ in range(4):
        obs, reward, _, truncated, info = env.step(scripted_action(obs))
        rewards.append(reward)
        infos.append(info)
    assert truncated
    if eval_reward == "success":
        assert rewards == [1.0 if i["is_success"] else -1.0 for i in infos]
    else:
        assert rewards[:3] == [0.0, 0.0, 0.0]
        assert rewards[3] == -float(infos[3]["gt_distance"]) < 0
    env.close()
    with pytest.raises(ValueError, match="eval_reward"):
        SawyerReachEnv(eval_reward="dense")
