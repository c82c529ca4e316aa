"""LeRobot's own env path (make_env -> preprocess_observation -> env processors) on sawyer_reach.

This is what ``lerobot-eval`` and ``lerobot-train``'s periodic eval do with ``--env.type=sawyer_reach``.
"""

import os

import numpy as np
import pytest
import torch

os.environ.setdefault("MUJOCO_GL", "egl")
pytest.importorskip("robosuite")

from lerobot.envs.factory import make_env, make_env_config, make_env_pre_post_processors  # noqa: E402
from lerobot.envs.utils import close_envs, env_to_policy_features, preprocess_observation  # noqa: E402

import lerobot_indicator  # noqa: E402, F401  (registers the env type, as plugin discovery does)
from lerobot_indicator.keys import goal_key  # noqa: E402

H, W = 36, 44
RGBD_KEYS = {
    "observation.state": ((3,), torch.float32),
    "observation.goal_state": ((3,), torch.float32),
    "observation.images.front": ((3, H, W), torch.float32),
    "observation.images.goal_front": ((3, H, W), torch.float32),
    "observation.images.front_depth": ((1, H, W), torch.float32),
    "observation.images.goal_front_depth": ((1, H, W), torch.float32),
}


def eval_batch(cfg, n_envs=2):
    """One observation batch exactly as lerobot-eval's rollout builds it."""
    envs = make_env(cfg, n_envs=n_envs)
    vec = envs[cfg.type][0]
    try:
        obs, _ = vec.reset(seed=list(range(n_envs)))
        batch = preprocess_observation(obs)
        batch["task"] = list(vec.call("task_description"))
        env_pre, _ = make_env_pre_post_processors(cfg, policy_cfg=None)
        batch = env_pre(batch)
        _, reward, terminated, truncated, info = vec.step(np.zeros((n_envs, 3), dtype=np.float32))
        frames = vec.call("render")
        max_steps = vec.call("_max_episode_steps")[0]
        return obs, batch, info, frames, max_steps
    finally:
        close_envs(envs)


def test_rgbd_eval_batch_has_documented_keys_dtypes_and_depth_units():
    cfg = make_env_config("sawyer_reach", obs_type="rgbd", camera={"width": W, "height": H})
    obs, batch, info, frames, max_steps = eval_batch(cfg)
    for key, (shape, dtype) in RGBD_KEYS.items():
        assert key in batch, key
        assert tuple(batch[key].shape) == (2, *shape), (key, batch[key].shape)
        assert batch[key].dtype == dtype, key
    # RGB in [0, 1]; depth in millimetres, exactly the env's uint16 values
    assert batch["observation.images.front"].min() >= 0.0 and batch["observation.images.front"].max() <= 1.0
    expected_depth = torch.from_numpy(obs["front_depth"].astype(np.float32)).permute(0, 3, 1, 2)
    assert torch.equal(batch["observation.images.front_depth"], expected_depth)
    assert batch["observation.images.front_depth"].max() > 500  # mm, not m
    # the goal of every compared key is in the batch under the goal-key rule
    for key in ("observation.state", "observation.images.front", "observation.images.front_depth"):
        assert goal_key(key) in batch
    # the env features LeRobot gives the policy are the same keys and shapes
    policy_features = env_to_policy_features(cfg)
    for key, (shape, _) in RGBD_KEYS.items():
        assert tuple(policy_features[key].shape) == shape, key
    assert set(info) >= {"gt_achieved_goal", "gt_desired_goal", "gt_distance", "is_success"}
    assert info["is_success"].dtype == bool and info["gt_distance"].shape == (2,)
    assert max_steps == cfg.episode_length == 25
    assert frames[0].shape == (H, W, 3) and frames[0].dtype == np.uint8


def test_state_eval_batch():
    cfg = make_env_config("sawyer_reach")
    assert cfg.obs_type == "state"
    _, batch, *_ = eval_batch(cfg, n_envs=1)
    obs_keys = {k for k in batch if k.startswith("observation.")}
    assert obs_keys == {"observation.state", "observation.goal_state"}
    assert batch["observation.state"].shape == (1, 3) and batch["observation.state"].dtype == torch.float32


def test_env_processor_feature_contract_matches_batch():
    """transform_features of the env processor maps the env's depth feature to the image key."""
    from lerobot.configs import PipelineFeatureType

    cfg = make_env_config("sawyer_reach", obs_type="rgbd", camera={"width": W, "height": H})
    env_pre, _ = cfg.get_env_processors()
    raw = {PipelineFeatureType.OBSERVATION: {f"observation.{k}": cfg.features[k] for k in cfg.depth_keys}}
    out = env_pre.transform_features(raw)[PipelineFeatureType.OBSERVATION]
    assert set(out) == {"observation.images.front_depth", "observation.images.goal_front_depth"}
    assert all(tuple(ft.shape) == (1, H, W) for ft in out.values())


@pytest.mark.slow
@pytest.mark.parametrize("config", ["sawyer_reach_state_sim", "sawyer_reach_sim"])
def test_lerobot_eval_cli_runs_on_env_config_file(config, tmp_path):
    """``lerobot-eval --config_path=env_configs/<file>.yaml`` with an (untrained) indicator_ddpg checkpoint."""
    import subprocess
    import sys
    from pathlib import Path

    from lerobot.policies.factory import make_policy, make_pre_post_processors

    from lerobot_indicator.envs.configs import load_env_config
    from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig

    config_path = Path(__file__).resolve().parents[1] / "env_configs" / f"{config}.yaml"
    env_cfg = load_env_config(config_path)
    keys = ["observation.state"]
    if env_cfg.obs_type == "rgbd":
        keys = ["observation.images.front", "observation.images.front_depth"]
    policy_cfg = IndicatorDDPGConfig(
        observation_keys=keys, horizon=env_cfg.episode_length, device="cpu", push_to_hub=False
    )
    ckpt = tmp_path / "ckpt"
    make_policy(policy_cfg, env_cfg=env_cfg).save_pretrained(ckpt)
    for processor in make_pre_post_processors(policy_cfg, dataset_stats=None):
        processor.save_pretrained(ckpt)
    cli = Path(sys.executable).with_name("lerobot-eval")
    out = subprocess.run(
        [
            str(cli),
            f"--config_path={config_path}",
            f"--policy.path={ckpt}",
            "--policy.device=cpu",
            "--eval.n_episodes=2",
            "--eval.batch_size=2",
            f"--output_dir={tmp_path / 'eval'}",
        ],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "MUJOCO_GL": "egl"},
    )
    assert out.returncode == 0, out.stderr[-3000:]
    assert "pc_success" in out.stdout + out.stderr
    assert list((tmp_path / "eval" / "videos").rglob("*.mp4"))
