"""Pushes through LeRobot's own Hub code to the local Hub server (``local_hub`` fixture), and back."""

import json

import pytest
import torch
from huggingface_hub import DatasetCard, HfApi
from lerobot.configs import FeatureType, PolicyFeature
from lerobot.configs.default import DatasetConfig
from lerobot.configs.train import TrainPipelineConfig
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.policies.act.configuration_act import ACTConfig
from lerobot.policies.act.modeling_act import ACTPolicy
from test_record import T, env_cfg

from lerobot_indicator.data.recorder import RecordConfig, record


def test_recorded_dataset_push_round_trip(tmp_path, local_hub, monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", "egl")
    repo_id = "indicator-tests/reach_rgbd"
    cfg = RecordConfig(
        env=env_cfg(obs_type="rgbd"),
        repo_id=repo_id,
        root=tmp_path / "ds",
        policy="noisy_scripted",
        num_episodes=2,
        push_to_hub=True,
        tags=["tiny"],
    )
    local = record(cfg)

    files = local_hub.files(repo_id)
    local_files = {
        p.relative_to(local.root).as_posix(): p.read_bytes() for p in local.root.rglob("*") if p.is_file()
    }
    assert {"meta/info.json", "meta/stats.json", "meta/tasks.parquet", "README.md"} <= set(files)
    for path, content in local_files.items():  # everything but the temporary images/ dir arrived intact
        assert path.startswith("images/") or files[path] == content, path
    assert any(p.startswith("data/") and p.endswith(".parquet") for p in files)
    assert not any(p.startswith(("images/", ".recording/")) for p in files)

    card = DatasetCard(files["README.md"].decode())
    assert card.data.license == "apache-2.0"
    assert {"LeRobot", "lerobot-indicator", "indicator-rewards", "sawyer_reach", "tiny"} <= set(
        card.data.tags
    )
    assert "**sawyer_reach**" in card.text and "policy: `noisy_scripted`" in card.text
    assert "obs_type: rgbd" in card.text  # the env config that recorded it
    assert json.loads(files["meta/info.json"])["total_episodes"] == 2
    # LeRobot tags the codebase version; the tag points at the commit that holds the card.
    repo = local_hub.repo(repo_id)
    assert repo.tags["v3.0"] == repo.branches["main"]
    # The card's YAML went through validate-yaml (RepoCard.validate + create_commit's check).
    assert ("POST", "/api/validate-yaml") in local_hub.requests

    downloaded = LeRobotDataset(repo_id, root=tmp_path / "download", video_backend="pyav")
    assert (downloaded.num_episodes, len(downloaded)) == (2, 2 * (T + 1))  # T + 1 frames: o_0..o_T
    for i in range(len(local)):
        a, b = local[i], downloaded[i]
        for key, value in a.items():
            if isinstance(value, torch.Tensor):
                assert torch.equal(value, b[key]), key
            else:
                assert value == b[key], key


def test_card_validation_still_rejects_bad_yaml(local_hub):
    """Validation is routed to the local hub, not switched off: an invalid card is refused."""
    HfApi().create_repo("indicator-tests/bad_card", repo_type="dataset")
    bad = DatasetCard("---\ntags:\n  nested: 1\n---\n\nbody\n")
    with pytest.raises(ValueError, match="'tags' must be a list of strings"):
        bad.push_to_hub("indicator-tests/bad_card", repo_type="dataset")
    assert "README.md" not in local_hub.files("indicator-tests/bad_card")


def test_policy_push_model_to_hub_round_trip(local_hub):
    """``PreTrainedPolicy.push_model_to_hub`` (what ``--policy.push_to_hub=true`` calls) then ``from_pretrained``."""
    config = ACTConfig(
        input_features={
            "observation.state": PolicyFeature(FeatureType.STATE, (3,)),
            "observation.environment_state": PolicyFeature(FeatureType.ENV, (3,)),
        },
        output_features={"action": PolicyFeature(FeatureType.ACTION, (3,))},
        dim_model=16,
        n_heads=2,
        dim_feedforward=16,
        n_encoder_layers=1,
        n_decoder_layers=1,
        chunk_size=2,
        n_action_steps=1,
        use_vae=False,
        repo_id="indicator-tests/tiny_policy",
        device="cpu",
    )
    policy = ACTPolicy(config)
    policy.push_model_to_hub(
        TrainPipelineConfig(dataset=DatasetConfig(repo_id="indicator-tests/reach"), policy=config)
    )

    files = local_hub.files("indicator-tests/tiny_policy", repo_type="model")
    assert {"config.json", "model.safetensors", "train_config.json", "README.md"} <= set(files)
    loaded = ACTPolicy.from_pretrained("indicator-tests/tiny_policy")
    for name, tensor in policy.state_dict().items():
        assert torch.equal(tensor, loaded.state_dict()[name]), name


def test_branch_push_and_unchanged_files_are_skipped(tmp_path, local_hub):
    """``push_to_hub(branch=...)`` lands on that branch only; re-pushing unchanged files adds no commit."""
    features = {"observation.state": {"dtype": "float32", "shape": (2,), "names": None}}
    ds = LeRobotDataset.create("indicator-tests/branchy", fps=10, features=features, root=tmp_path / "ds")
    for t in range(3):
        ds.add_frame({"observation.state": torch.tensor([t, -t], dtype=torch.float32), "task": "noop"})
    ds.save_episode()
    ds.finalize()

    ds.push_to_hub(branch="dev", tag_version=False)
    assert "meta/info.json" in local_hub.files("indicator-tests/branchy", revision="dev")
    assert "meta/info.json" not in local_hub.files("indicator-tests/branchy", revision="main")
    refs = HfApi().list_repo_refs("indicator-tests/branchy", repo_type="dataset")
    assert {b.name for b in refs.branches} == {"main", "dev"}

    repo = local_hub.repo("indicator-tests/branchy")
    commits_before = len(repo.commits)
    info = HfApi().upload_folder(
        repo_id="indicator-tests/branchy", folder_path=ds.root, repo_type="dataset", revision="dev"
    )
    assert len(repo.commits) == commits_before  # preupload returned the same blob ids: nothing to commit
    assert info.oid == repo.branches["dev"]


def test_local_hub_refuses_commit_paths_outside_the_repository(tmp_path, local_hub):
    """A commit path with ``..`` segments is refused with a 400, as by the real Hub (``huggingface_hub`` checks
    its own paths client-side, so the request is sent raw), and nothing is written beside the repo folder."""
    import base64
    import os
    import urllib.error
    import urllib.request

    repo_id = HfApi().create_repo("escape", repo_type="dataset").repo_id
    lines = [
        {"key": "header", "value": {"summary": "escape"}},
        {"key": "file", "value": {"path": "sub/../../outside.txt", "encoding": "base64",
                                  "content": base64.b64encode(b"x").decode()}},
    ]  # fmt: skip
    request = urllib.request.Request(
        f"{local_hub.url}/api/datasets/{repo_id}/commit/main",
        data="\n".join(json.dumps(line) for line in lines).encode(),
        headers={"Content-Type": "application/x-ndjson", "Authorization": f"Bearer {os.environ['HF_TOKEN']}"},
        method="POST",
    )
    with pytest.raises(urllib.error.HTTPError) as error:
        urllib.request.urlopen(request)
    assert error.value.code == 400 and b"must stay inside the repository" in error.value.read()
    assert not list((tmp_path / "local_hub").rglob("outside.txt"))
