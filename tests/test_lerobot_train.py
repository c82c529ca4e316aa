"""``lerobot-train --policy.type=indicator_ddpg`` end to end on CPU on a tiny synthetic reach-like dataset."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

BIN = Path(sys.executable).parent
REPO_ID = "local/tiny_reach"
EPISODES, T = 3, 6


def make_tiny_reach_dataset(root: Path) -> Path:
    """A few episodes of the real sawyer_reach task, recorded by our own recorder (docs/dataset_format.md):
    what a user trains on, T + 1 frames per episode, ground truth included."""
    from lerobot_indicator.data.recorder import RecordConfig, record
    from lerobot_indicator.envs.configs import SawyerReachEnvConfig

    cfg = RecordConfig(
        env=SawyerReachEnvConfig(episode_length=T),
        repo_id=REPO_ID,
        root=root,
        policy="noisy_scripted",
        num_episodes=EPISODES,
        image_writer_threads=0,
    )
    record(cfg)
    return root


@pytest.fixture(scope="module")
def tiny_reach(tmp_path_factory) -> Path:
    return make_tiny_reach_dataset(tmp_path_factory.mktemp("data") / "tiny_reach")


def lerobot_train(args: list[str]) -> subprocess.CompletedProcess:
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "CUDA_VISIBLE_DEVICES": ""}
    proc = subprocess.run(
        [str(BIN / "lerobot-train"), *args], capture_output=True, text=True, timeout=300, env=env
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-6000:]
    return proc


@pytest.fixture(scope="module")
def trained_run(tiny_reach: Path, tmp_path_factory) -> Path:
    """Two lerobot-train steps with a checkpoint at step 2; returns the output dir."""
    out = tmp_path_factory.mktemp("train") / "run"
    common = [
        "--policy.type=indicator_ddpg",
        f"--dataset.repo_id={REPO_ID}",
        f"--dataset.root={tiny_reach}",
        "--policy.push_to_hub=false",
        "--policy.device=cpu",
        "--policy.horizon=6",
        "--policy.future_offsets=[2,3]",
        "--policy.hidden_dims=[16,16,16]",
        "--batch_size=8",
        "--num_workers=0",
        "--log_freq=1",
        "--save_freq=2",
        "--wandb.enable=false",
        f"--output_dir={out}",
    ]
    proc = lerobot_train([*common, "--steps=2"])
    log = proc.stdout + proc.stderr
    assert "critic_loss" in log and "frac_filtered" in log and "reward_accuracy" in log, log[-3000:]
    return out


def test_train_checkpoint_resume_and_load(trained_run: Path):
    out = trained_run
    ckpt = out / "checkpoints" / "000002" / "pretrained_model"
    assert (ckpt / "model.safetensors").is_file()
    cfg = json.loads((ckpt / "config.json").read_text())
    assert cfg["type"] == "indicator_ddpg"
    # Ground-truth keys are dropped from the inputs; only the compared key and its goal remain.
    assert sorted(cfg["input_features"]) == ["observation.goal_state", "observation.state"]

    # Resumed with a forked loader worker, the start method the README's RGB-D command uses.
    resume = [f"--config_path={ckpt / 'train_config.json'}", "--resume=true", "--steps=4", "--num_workers=1",
              "--dataloader_multiprocessing_context=fork"]  # fmt: skip
    proc = lerobot_train(resume)
    assert "Resuming data order" in proc.stdout + proc.stderr
    assert (out / "checkpoints" / "000004" / "pretrained_model" / "model.safetensors").is_file()
    state = json.loads((out / "checkpoints" / "000004" / "training_state" / "training_step.json").read_text())
    assert state["step"] == 4

    from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

    policy = IndicatorDDPGPolicy.from_pretrained(out / "checkpoints" / "last" / "pretrained_model")
    assert policy.config.horizon == 6
    batch = {"observation.state": torch.zeros(2, 3), "observation.goal_state": torch.ones(2, 3)}
    action = policy.select_action(batch)
    assert action.shape == (2, 3) and action.abs().max() <= 1


def test_lerobot_eval_loads_checkpoint_on_sawyer_reach(trained_run: Path, tmp_path: Path):
    """The trained checkpoint runs in lerobot-eval on the state-based reach env (same keys and shapes)."""
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "CUDA_VISIBLE_DEVICES": "", "MUJOCO_GL": "egl"}
    args = [
        str(BIN / "lerobot-eval"),
        f"--policy.path={trained_run / 'checkpoints' / 'last' / 'pretrained_model'}",
        "--policy.device=cpu",
        "--env.type=sawyer_reach",
        "--eval.n_episodes=1",
        "--eval.batch_size=1",
        f"--output_dir={tmp_path / 'eval'}",
    ]
    proc = subprocess.run(args, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-6000:]
    info = json.loads((tmp_path / "eval" / "eval_info.json").read_text())
    assert info["overall"]["n_episodes"] == 1 and 0 <= info["overall"]["pc_success"] <= 100


def test_push_checkpoint_to_local_hub(trained_run: Path, local_hub):
    """What lerobot-train does with --policy.push_to_hub=true at the end of training, against the local Hub."""
    from lerobot.configs.train import TrainPipelineConfig

    from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

    ckpt = trained_run / "checkpoints" / "000002" / "pretrained_model"
    cfg = TrainPipelineConfig.from_pretrained(ckpt)
    policy = IndicatorDDPGPolicy.from_pretrained(ckpt)
    policy.config.repo_id = "local-user/indicator_ddpg_tiny"
    policy.push_model_to_hub(cfg)
    files = local_hub.files("local-user/indicator_ddpg_tiny", "model")
    assert {"model.safetensors", "config.json", "train_config.json", "README.md"} <= set(files)
    pulled = IndicatorDDPGPolicy.from_pretrained("local-user/indicator_ddpg_tiny")
    batch = {"observation.state": torch.rand(4, 3), "observation.goal_state": torch.rand(4, 3)}
    torch.testing.assert_close(pulled.select_action(batch), policy.select_action(batch))


def test_push_processors_after_policy_to_local_hub(trained_run: Path, local_hub):
    """lerobot-train pushes the policy, then the pre/post processors, to the same repo."""
    from lerobot.policies import make_pre_post_processors

    from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

    ckpt = trained_run / "checkpoints" / "000002" / "pretrained_model"
    policy = IndicatorDDPGPolicy.from_pretrained(ckpt)
    preprocessor, postprocessor = make_pre_post_processors(policy.config, pretrained_path=str(ckpt))
    preprocessor.push_to_hub("local-user/indicator_ddpg_tiny")
    postprocessor.push_to_hub("local-user/indicator_ddpg_tiny")
    files = local_hub.files("local-user/indicator_ddpg_tiny", "model")
    assert any(name.startswith("policy_preprocessor") for name in files)


def test_rgbd_dataset_batch_trains_through_lerobot_factories(tmp_path: Path):
    """The lerobot-train data path on RGB-D: delta indices, depth units and stats, uint8 -> float images."""
    from lerobot.datasets import LeRobotDataset
    from lerobot.datasets.factory import resolve_delta_timestamps
    from lerobot.policies import make_policy, make_pre_post_processors

    from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig

    size, rgb = 16, {"dtype": "image", "shape": (16, 16, 3), "names": ["height", "width", "channels"]}
    depth = {**rgb, "shape": (size, size, 1), "info": {"is_depth_map": True}}
    vec = {"dtype": "float32", "shape": (3,), "names": ["x", "y", "z"]}
    keys = ["observation.images.front", "observation.images.front_depth"]
    features = {
        keys[0]: rgb,
        keys[1]: depth,
        "observation.images.goal_front": rgb,
        "observation.images.goal_front_depth": depth,
        "action": vec,
    }
    ds = LeRobotDataset.create(
        "local/tiny_rgbd", fps=10, features=features, root=tmp_path / "d", use_videos=False
    )
    rng = np.random.default_rng(0)
    for _ in range(2):
        goal_rgb, goal_depth = rng.integers(0, 256, (size, size, 3), dtype=np.uint8), np.ones((size, size, 1))
        for _ in range(5):
            ds.add_frame(
                {
                    keys[0]: rng.integers(0, 256, (size, size, 3), dtype=np.uint8),
                    keys[1]: rng.uniform(0.5, 1.5, (size, size, 1)).astype(np.float32),
                    "observation.images.goal_front": goal_rgb,
                    "observation.images.goal_front_depth": goal_depth.astype(np.float32),
                    "action": rng.uniform(-1, 1, 3).astype(np.float32),
                    "task": "reach",
                }
            )
        ds.save_episode()
    ds.finalize()

    cfg = IndicatorDDPGConfig(
        device="cpu",
        observation_keys=keys,
        horizon=4,
        future_offsets=[2, 3],
        image_encoder="paper",
        episode_end_goal=False,  # the data has goal columns: no episode-end frame to fetch
    )
    cfg.hidden_dims, cfg.conv_channels = [16, 16, 16], [4, 4, 4, 4]
    meta = LeRobotDataset("local/tiny_rgbd", root=tmp_path / "d").meta
    dataset = LeRobotDataset(
        "local/tiny_rgbd", root=tmp_path / "d", delta_timestamps=resolve_delta_timestamps(cfg, meta)
    )
    policy = make_policy(cfg, ds_meta=dataset.meta)
    preprocessor, _ = make_pre_post_processors(cfg, dataset_stats=dataset.meta.stats)
    batch = next(iter(torch.utils.data.DataLoader(dataset, batch_size=8, shuffle=False)))
    for key in dataset.meta.camera_keys:  # what lerobot-train does before the preprocessor
        if batch[key].dtype == torch.uint8:
            batch[key] = batch[key].float() / 255
    batch = preprocessor(batch)
    assert batch[keys[0]].shape == (8, 4, 3, size, size) and batch[keys[1]].shape == (8, 4, 1, size, size)
    # Depth arrives in the dataset's unit (mm) and is normalised inside the network with matching stats.
    assert batch[keys[1]].max() > 100
    depth_mean = policy.actor.encoder.normalize(keys[1], batch[keys[1]][:, 0]).mean().abs()
    assert depth_mean < 3
    loss, stats = policy.forward(batch, generator=torch.Generator().manual_seed(0))
    loss.backward()
    assert loss.isfinite() and 0 < stats["frac_positive"] < 1


def test_offline_only_online_trainer_trains_from_the_dataset_without_rollouts(tiny_reach: Path, tmp_path):
    """``lerobot-indicator-train --dataset.* --online.episodes_per_cycle=0``: updates from the in-memory buffer
    of the dataset's episodes, no env steps collected (the env only evaluates)."""
    out = tmp_path / "run"
    cmd = [
        str(BIN / "lerobot-indicator-train"),
        "--env.type=sawyer_reach",
        "--env.obs_type=state",
        f"--env.episode_length={T}",
        "--policy.type=indicator_ddpg",
        "--policy.push_to_hub=false",
        "--policy.device=cpu",
        "--policy.hidden_dims=[16,16,16]",
        f"--dataset.repo_id={REPO_ID}",
        f"--dataset.root={tiny_reach}",
        "--online.episodes_per_cycle=0",
        "--online.n_envs=1",
        "--online.use_async_envs=false",
        "--online.updates_per_cycle=5",
        "--online.batch_size=8",
        "--online.eval_episodes=1",
        "--env_eval_freq=10",
        "--steps=10",
        f"--output_dir={out}",
    ]
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "MUJOCO_GL": "egl"}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr[-4000:]
    rows = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    assert [r["step"] for r in rows] == [5, 10]
    assert all(r["env_steps"] == 0 and r["episodes"] == EPISODES for r in rows)
    assert np.isfinite(rows[-1]["critic_loss"]) and "eval_success_rate" in rows[-1]
