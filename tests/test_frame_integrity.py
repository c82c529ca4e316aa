"""Content hashes of a recorded dataset: written at every commit, verified before training reads a frame.

Lossless HEVC has no checksum: bytes flipped inside a video's ``mdat`` decode without error into other
frames, and the indicator reward compares frames bit for bit. Each test records a tiny RGB-D dataset once
(module fixture) and works on a copy.
"""

import hashlib
import json
import os
import shutil
import struct
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from huggingface_hub import constants as hf_constants
from lerobot.configs.default import DatasetConfig
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from lerobot_indicator.data.errors import DatasetError
from lerobot_indicator.data.integrity import HASHES, check_dataset, verify_hashes
from lerobot_indicator.data.recorder import RecordConfig, record
from lerobot_indicator.envs import SawyerReachEnvConfig
from lerobot_indicator.training.dataset_seed import load_dataset

BIN = Path(sys.executable).parent
REPO_ID = "test/integrity"
T = 3
GOAL_CAMERA = "observation.images.goal_front"


@pytest.fixture(autouse=True)
def _offline(monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setattr(hf_constants, "HF_HUB_OFFLINE", True)


def record_rgbd(root: Path, num_episodes: int = 2, resume: bool = False) -> None:
    env = SawyerReachEnvConfig(obs_type="rgbd", episode_length=T, camera={"width": 32, "height": 32})
    cfg = RecordConfig(
        env=env, repo_id=REPO_ID, root=root, num_episodes=num_episodes, use_videos=True, resume=resume,
        image_writer_threads=0,
    )  # fmt: skip
    record(cfg)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("integrity") / "ds"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(hf_constants, "HF_HUB_OFFLINE", True)
        record_rgbd(root)
    return root


@pytest.fixture
def dataset_copy(recorded: Path, tmp_path: Path) -> Path:
    root = tmp_path / "ds"
    shutil.copytree(recorded, root)
    return root


def video_of(root: Path, key: str, episode: int) -> Path:
    return root / f"videos/{key}/chunk-000/file-{episode:03d}.mp4"


def flip_mdat_bytes(path: Path, count: int = 64) -> None:
    """Invert ``count`` bytes in the middle of the mp4's ``mdat`` box (the coded frames, not the headers)."""
    data = bytearray(path.read_bytes())
    offset = 0
    while offset < len(data):
        size, kind = struct.unpack(">I4s", data[offset : offset + 8])
        if kind == b"mdat":
            middle = offset + 8 + (size - 8) // 2
            data[middle : middle + count] = bytes(b ^ 0xFF for b in data[middle : middle + count])
            path.write_bytes(bytes(data))
            return
        offset += size
    raise AssertionError(f"no mdat box in {path}")


def test_every_committed_file_is_hashed_with_its_episodes_and_keys(recorded: Path):
    hashes = json.loads((recorded / HASHES).read_text())
    on_disk = {
        p.relative_to(recorded).as_posix()
        for d in ("data", "videos", "meta/episodes")
        for p in (recorded / d).rglob("*")
        if p.is_file()
    }
    assert set(hashes["files"]) == on_disk
    for rel, entry in hashes["files"].items():
        digest = hashlib.blake2b((recorded / rel).read_bytes(), digest_size=32).hexdigest()
        assert entry["hash"] == digest and entry["size"] == (recorded / rel).stat().st_size, rel
    meta = LeRobotDataset(REPO_ID, root=recorded, video_backend="pyav").meta
    for episode in range(2):
        for key in meta.video_keys:
            entry = hashes["files"][meta.get_video_file_path(episode, key).as_posix()]
            assert entry["episodes"] == [episode] and entry["keys"] == [key]
        entry = hashes["files"][meta.get_data_file_path(episode).as_posix()]
        assert entry["episodes"] == [episode]
        assert "observation.state" in entry["keys"] and "action" in entry["keys"]
        assert not set(entry["keys"]) & set(meta.video_keys)


def test_flipped_mdat_bytes_decode_silently_but_verification_names_the_file(dataset_copy: Path):
    before = LeRobotDataset(REPO_ID, root=dataset_copy, video_backend="pyav")
    frames_before = [before[i][GOAL_CAMERA] for i in range(len(before))]
    video = video_of(dataset_copy, GOAL_CAMERA, 1)
    flip_mdat_bytes(video)
    after = LeRobotDataset(REPO_ID, root=dataset_copy, video_backend="pyav")
    changed = [i for i in range(len(after)) if not torch.equal(after[i][GOAL_CAMERA], frames_before[i])]
    assert changed, "the flipped bytes changed no decoded frame: the test corrupts nothing"
    with pytest.raises(DatasetError) as err:
        check_dataset(dataset_copy)
    message = str(err.value)
    assert "\n" not in message
    assert str(video) in message and f"keys {GOAL_CAMERA}; episodes 1" in message
    assert "does not match its recorded" in message


def test_verification_covers_only_the_loaded_episodes(dataset_copy: Path):
    flip_mdat_bytes(video_of(dataset_copy, GOAL_CAMERA, 1))
    with pytest.raises(DatasetError):
        verify_hashes(dataset_copy)
    hashes = json.loads((dataset_copy / HASHES).read_text())["files"]
    # Episode 0's data and videos, and every episode-metadata file (LeRobot reads them all).
    wanted = [rel for rel, e in hashes.items() if e["episodes"] == [0] or rel.startswith("meta/episodes/")]
    assert verify_hashes(dataset_copy, episodes=[0]) == len(wanted) == 7


def test_online_trainer_refuses_a_corrupted_dataset_before_reading_frames(dataset_copy: Path):
    flip_mdat_bytes(video_of(dataset_copy, "observation.images.front", 0))
    with pytest.raises(DatasetError, match=r"observation\.images\.front; episodes 0\) does not match"):
        load_dataset(DatasetConfig(repo_id=REPO_ID, root=str(dataset_copy), video_backend="pyav"))


def test_a_dataset_without_hashes_is_accepted_with_one_info_line(dataset_copy: Path, caplog):
    (dataset_copy / HASHES).unlink()
    flip_mdat_bytes(video_of(dataset_copy, GOAL_CAMERA, 1))  # undetectable without hashes
    with caplog.at_level("INFO"):
        assert check_dataset(dataset_copy) is None
    lines = [r.getMessage() for r in caplog.records if "not verified" in r.getMessage()]
    assert len(lines) == 1 and str(dataset_copy) in lines[0]


def test_resume_adds_the_new_episode_and_keeps_the_old_hashes(dataset_copy: Path):
    before = json.loads((dataset_copy / HASHES).read_text())["files"]
    record_rgbd(dataset_copy, num_episodes=1, resume=True)
    after = json.loads((dataset_copy / HASHES).read_text())["files"]
    assert {k: after[k] for k in before} == before
    new = {rel: e for rel, e in after.items() if rel not in before}
    assert new and all(e["episodes"] == [2] for e in new.values())
    assert verify_hashes(dataset_copy) == len(after)


def test_verify_cli_prints_one_line_and_exits_non_zero(dataset_copy: Path):
    env = {**os.environ, "HF_HUB_OFFLINE": "1"}
    cmd = [str(BIN / "lerobot-indicator-verify"), f"--repo_id={REPO_ID}", f"--root={dataset_copy}"]
    ok = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env)
    assert ok.returncode == 0 and "files match their recorded" in ok.stdout, ok.stderr[-2000:]
    video = video_of(dataset_copy, "observation.images.front_depth", 1)
    flip_mdat_bytes(video)
    bad = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env)
    assert bad.returncode == 1
    errors = [line for line in bad.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and str(video) in errors[0], bad.stderr[-2000:]
    assert "Traceback" not in bad.stderr


def test_lerobot_train_refuses_a_corrupted_dataset_in_one_line(dataset_copy: Path, tmp_path: Path):
    video = video_of(dataset_copy, GOAL_CAMERA, 0)
    flip_mdat_bytes(video)
    cmd = [
        str(BIN / "lerobot-train"), "--policy.type=indicator_ddpg", f"--dataset.repo_id={REPO_ID}",
        f"--dataset.root={dataset_copy}", "--policy.push_to_hub=false", "--policy.device=cpu", "--steps=1",
        "--num_workers=0", "--wandb.enable=false", f"--output_dir={tmp_path / 'run'}",
    ]  # fmt: skip
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "CUDA_VISIBLE_DEVICES": ""}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 1, out[-3000:]
    errors = [line for line in out.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and str(video) in errors[0] and "episodes 0" in errors[0], out[-3000:]
    assert "Traceback" not in out
