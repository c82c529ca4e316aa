"""``lerobot-indicator-train --policy.push_to_hub=true`` against the local Hub server (``local_hub``): the pushed
repo holds what ``lerobot-train``'s push holds, loads back bit for bit, and a failed push keeps the trained policy
on disk and ends the run with one line."""

import json
import os
import re
import subprocess

import draccus
import pytest
import torch
import yaml
from huggingface_hub import DatasetCard, ModelCard
from lerobot.processor import PolicyProcessorPipeline
from test_online_training import BIN, ENVS, TINY, _env

from lerobot_indicator.data.recorder import RecordConfig, record
from lerobot_indicator.envs import SawyerReachEnvConfig
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy
from lerobot_indicator.training import online
from lerobot_indicator.training.config import OnlineTrainConfig

HORIZON = 5  # ENVS["sawyer_reach"]'s episode length
ARGS = [
    *[a for a in TINY if not a.startswith("--policy.push_to_hub")],
    *ENVS["sawyer_reach"],
    "--steps=5",
    # Process-wide settings stay as they are in this pytest process.
    "--cpu_threads=null",
    "--keep_freed_memory=false",
    "--video_decoder_threads=null",
]


@pytest.fixture(autouse=True)
def _egl(monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))


def _train_in_process(tmp_path, repo_id: str, *args: str) -> OnlineTrainConfig:
    cfg = draccus.parse(
        OnlineTrainConfig,
        args=[*ARGS, f"--output_dir={tmp_path / 'run'}", "--policy.push_to_hub=true", f"--policy.repo_id={repo_id}",
              *args],
    )  # fmt: skip
    online.train(cfg)
    return cfg


def _assert_pushed_run(local_hub, repo_id: str, out, batch_size: int) -> ModelCard:
    """The repo holds the policy, its processors, the online run's config and a model card, equal to the local
    checkpoint of the last step; returns the card."""
    files = local_hub.files(repo_id, repo_type="model")
    assert {"config.json", "model.safetensors", "train_config.json", "README.md"} <= set(files), sorted(files)
    assert {"policy_preprocessor.json", "policy_postprocessor.json"} <= set(files), sorted(files)
    local = out / "checkpoints" / "last" / "pretrained_model"
    assert files["model.safetensors"] == (local / "model.safetensors").read_bytes()
    assert json.loads(files["train_config.json"])["online"]["updates_per_cycle"] == 5  # the online config
    pushed = IndicatorDDPGPolicy.from_pretrained(repo_id)
    saved = IndicatorDDPGPolicy.from_pretrained(local)
    for name, tensor in saved.state_dict().items():
        assert torch.equal(tensor, pushed.state_dict()[name]), name
    for name in ("policy_preprocessor", "policy_postprocessor"):
        pipeline = PolicyProcessorPipeline.from_pretrained(repo_id, config_filename=f"{name}.json")
        assert json.loads(files[f"{name}.json"]) == json.loads((local / f"{name}.json").read_text())
        assert len(pipeline.steps) == len(json.loads(files[f"{name}.json"])["steps"])
        for path in [p for p in files if p.startswith(f"{name}_") and p.endswith(".safetensors")]:
            assert files[path] == (local / path).read_bytes(), path
    card = ModelCard(files["README.md"].decode())
    assert card.data.library_name == "lerobot" and "indicator_ddpg" in card.data.tags
    assert f"| Batch size | {batch_size} |" in card.text and "| Training steps | 5 |" in card.text
    return card


def test_online_run_pushes_policy_processors_and_card(tmp_path, local_hub):
    """Online only, with its rollouts recorded and pushed too: the policy's card names that dataset, whose own
    card names the training command."""
    repo_id, rollouts = "indicator-tests/online_policy", "indicator-tests/online_rollouts"
    _train_in_process(
        tmp_path, repo_id, f"--record.repo_id={rollouts}", f"--record.root={tmp_path / 'rollouts'}",
        "--record.push_to_hub=true",
    )  # fmt: skip
    card = _assert_pushed_run(local_hub, repo_id, tmp_path / "run", batch_size=16)
    assert card.data.datasets == rollouts  # trained from its own rollouts only
    assert ("POST", "/api/validate-yaml") in local_hub.requests
    dataset_card = DatasetCard(local_hub.files(rollouts)["README.md"].decode())
    assert "lerobot-indicator-train --policy.type=indicator_ddpg --env.type=sawyer_reach" in dataset_card.text
    assert (
        "**simulated** with MuJoCo" in dataset_card.text and "arxiv.org/abs/1905.07866" in dataset_card.text
    )
    (block,) = re.findall(r"```yaml\n(.*?)```", dataset_card.text, flags=re.S)
    assert yaml.safe_load(block)["episode_length"] == HORIZON


def test_run_seeded_from_a_dataset_pushes_with_that_dataset_on_its_card(tmp_path, local_hub):
    dataset_id = "indicator-tests/reach_state"
    record(
        RecordConfig(
            env=SawyerReachEnvConfig(obs_type="state", episode_length=HORIZON),
            repo_id=dataset_id,
            root=tmp_path / "ds",
            policy="noisy_scripted",
            num_episodes=2,
            image_writer_threads=0,
        )
    )
    repo_id = "indicator-tests/offline_policy"
    _train_in_process(
        tmp_path, repo_id, f"--dataset.repo_id={dataset_id}", f"--dataset.root={tmp_path / 'ds'}",
        "--online.episodes_per_cycle=0", "--online.batch_size=null",
    )  # fmt: skip
    card = _assert_pushed_run(local_hub, repo_id, tmp_path / "run", batch_size=256)  # the paper's, for states
    assert card.data.datasets == dataset_id
    assert "**Episodes:** 2" in card.text and "`sawyer`" in card.text  # the dataset's metadata on the card


@pytest.mark.parametrize("save_checkpoint", [True, False])
def test_failed_push_keeps_the_policy_and_ends_with_one_line(tmp_path, save_checkpoint):
    """The Hub is unreachable: exit code 1, one error line naming the repo and the policy directory, no
    traceback, and that directory holds the trained policy (saved for the push when checkpoints are off)."""
    out = tmp_path / "run"
    env = {k: v for k, v in _env().items() if k != "HF_HUB_OFFLINE"}
    env |= {"HF_ENDPOINT": "http://127.0.0.1:9", "HF_TOKEN": "hf_local_test_token"}  # nothing listens there
    cmd = [str(BIN / "lerobot-indicator-train"), *ARGS, f"--output_dir={out}", "--policy.push_to_hub=true",
           "--policy.repo_id=indicator-tests/unreachable", f"--save_checkpoint={str(save_checkpoint).lower()}"]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 1, proc.stderr[-4000:]
    assert "Traceback" not in proc.stderr, proc.stderr[-4000:]
    errors = [line for line in proc.stderr.splitlines() if line.startswith(("ERROR", "error:"))]
    assert len(errors) == 1, proc.stderr[-4000:]
    kept = out / "checkpoints" / "000005" / "pretrained_model"
    assert "indicator-tests/unreachable" in errors[0] and f"kept at {kept}" in errors[0]
    policy = IndicatorDDPGPolicy.from_pretrained(kept)
    assert policy.config.type == "indicator_ddpg"
    assert (kept / "policy_preprocessor.json").exists() and (kept / "train_config.json").exists()
