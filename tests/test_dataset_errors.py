"""Bad dataset content ends in one line naming the file, key, episode, frame or shape, not a traceback.

Each case reproduces a failure seen on a damaged tiny dataset: random bytes in an mp4, a corrupt PNG cell,
a missing ``meta/info.json`` (offline), a goal whose shape differs from its observation's, and an
``info.json`` shape that differs from the stored values.
"""

import json
import os
import random
import shutil
import struct
import subprocess
import sys
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from huggingface_hub import constants as hf_constants
from lerobot.configs.default import DatasetConfig

from lerobot_indicator.data.errors import DatasetError
from lerobot_indicator.data.integrity import HASHES, INFO, check_dataset
from lerobot_indicator.data.recorder import RecordConfig, record
from lerobot_indicator.envs import SawyerReachEnvConfig
from lerobot_indicator.training.dataset_seed import dataset_episodes, load_dataset

BIN = Path(sys.executable).parent
REPO_ID = "test/errors"
T = 3
CAMERA, GOAL_CAMERA = "observation.images.front", "observation.images.goal_front"


@pytest.fixture(autouse=True)
def _offline(monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setattr(hf_constants, "HF_HUB_OFFLINE", True)


def _record(root: Path, use_videos: bool) -> Path:
    env = SawyerReachEnvConfig(obs_type="rgbd", episode_length=T, camera={"width": 32, "height": 32})
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(hf_constants, "HF_HUB_OFFLINE", True)
        record(RecordConfig(env=env, repo_id=REPO_ID, root=root, num_episodes=2, use_videos=use_videos,
                            image_writer_threads=0))  # fmt: skip
    return root


@pytest.fixture(scope="module")
def video_dataset(tmp_path_factory) -> Path:
    return _record(tmp_path_factory.mktemp("errors") / "video", use_videos=True)


@pytest.fixture(scope="module")
def png_dataset(tmp_path_factory) -> Path:
    return _record(tmp_path_factory.mktemp("errors") / "png", use_videos=False)


def copy_of(root: Path, tmp_path: Path, keep_hashes: bool = True) -> Path:
    copy = tmp_path / root.name
    shutil.copytree(root, copy)
    if not keep_hashes:
        (copy / HASHES).unlink()
    return copy


def load(root: Path):
    return load_dataset(DatasetConfig(repo_id=REPO_ID, root=str(root), video_backend="pyav"))


def read_all(root: Path) -> None:
    """What the online trainer does with ``--dataset.*``: load, then read every episode's frames."""
    for _ in dataset_episodes(load(root), [CAMERA, GOAL_CAMERA, "observation.state"], T):
        pass


def one_line_error(call) -> str:
    with pytest.raises(DatasetError) as err:
        call()
    message = str(err.value)
    assert "\n" not in message
    return message


def mdat_span(data: bytes) -> tuple[int, int]:
    offset = 0
    while offset < len(data):
        size, kind = struct.unpack(">I4s", data[offset : offset + 8])
        if kind == b"mdat":
            return offset + 8, offset + size
        offset += size
    raise AssertionError("no mdat box")


def set_shape(root: Path, shapes: dict[str, list[int]]) -> None:
    info = json.loads((root / INFO).read_text())
    for key, shape in shapes.items():
        info["features"][key]["shape"] = shape
    (root / INFO).write_text(json.dumps(info, indent=4))


@pytest.mark.parametrize("keep_hashes", [True, False], ids=["hashed", "unhashed"])
def test_an_mp4_of_random_bytes_is_one_line_naming_file_key_and_episode(video_dataset, tmp_path, keep_hashes):
    root = copy_of(video_dataset, tmp_path, keep_hashes)
    video = root / f"videos/{GOAL_CAMERA}/chunk-000/file-001.mp4"
    video.write_bytes(random.Random(0).randbytes(video.stat().st_size))
    message = one_line_error(lambda: read_all(root))
    assert str(video) in message and f"keys {GOAL_CAMERA}; episodes 1" in message
    expected = "does not match its recorded" if keep_hashes else "cannot be opened as a video"
    assert expected in message


def test_random_bytes_in_the_coded_frames_name_key_episode_frame_and_file(video_dataset, tmp_path):
    root = copy_of(video_dataset, tmp_path, keep_hashes=False)
    video = root / f"videos/{CAMERA}/chunk-000/file-000.mp4"
    data = bytearray(video.read_bytes())
    start, end = mdat_span(data)
    data[start:end] = random.Random(1).randbytes(end - start)
    video.write_bytes(bytes(data))
    message = one_line_error(lambda: read_all(root))
    assert message.startswith(f"cannot read {CAMERA} of episode 0, frame 0 from {video} (")


def corrupt_png_cell(data_file: Path, key: str, row: int) -> None:
    table = pq.read_table(data_file)
    cells = table.column(key).to_pylist()
    png = bytearray(cells[row]["bytes"])
    middle = len(png) // 2
    png[middle : middle + 64] = bytes(b ^ 0xFF for b in png[middle : middle + 64])
    cells[row] = {**cells[row], "bytes": bytes(png)}
    field = table.schema.field(key)
    table = table.set_column(table.schema.get_field_index(key), field, pa.array(cells, type=field.type))
    pq.write_table(table, data_file)


def test_a_corrupt_png_cell_names_key_episode_frame_and_file(png_dataset, tmp_path):
    root = copy_of(png_dataset, tmp_path, keep_hashes=False)
    data_file = root / "data/chunk-000/file-001.parquet"
    corrupt_png_cell(data_file, GOAL_CAMERA, row=2)
    message = one_line_error(lambda: read_all(root))
    assert message.startswith(f"cannot read {GOAL_CAMERA} of episode 1, frame 2 from {data_file} (")


def test_a_corrupt_png_cell_in_a_hashed_dataset_fails_before_any_read(png_dataset, tmp_path):
    root = copy_of(png_dataset, tmp_path)
    data_file = root / "data/chunk-000/file-001.parquet"
    corrupt_png_cell(data_file, GOAL_CAMERA, row=2)
    message = one_line_error(lambda: load(root))
    assert str(data_file) in message and GOAL_CAMERA in message and "episodes 1)" in message


def test_a_missing_info_json_is_named_before_the_hub_is_tried(video_dataset, tmp_path):
    root = copy_of(video_dataset, tmp_path)
    (root / INFO).unlink()
    message = one_line_error(lambda: load(root))
    assert message == (
        f"no dataset at {root}: meta/info.json is missing (offline: HF_HUB_OFFLINE is set, nothing is downloaded)"
    )


def test_a_goal_shaped_unlike_its_observation_is_named(video_dataset, tmp_path):
    root = copy_of(video_dataset, tmp_path)
    set_shape(root, {"observation.goal_state": [2]})
    message = one_line_error(lambda: load(root))
    assert message == (
        f"{root / INFO}: goal observation.goal_state has shape (2,) but its observation observation.state has "
        "shape (3,); a goal must have its observation's shape"
    )


def test_an_info_json_shape_unlike_the_stored_values_is_named(video_dataset, tmp_path):
    root = copy_of(video_dataset, tmp_path)
    set_shape(root, {"observation.state": [2], "observation.goal_state": [2]})
    message = one_line_error(lambda: load(root))
    data_file = root / "data/chunk-000/file-000.parquet"
    assert (
        message == f"{data_file} (episodes 0): observation.state is stored with shape (3,), {INFO} says (2,)"
    )


@pytest.mark.parametrize("cli", ["lerobot-train", "lerobot-indicator-train"])
def test_the_trainers_print_one_line_for_bad_data(video_dataset, tmp_path, cli):
    root = copy_of(video_dataset, tmp_path)
    set_shape(root, {"observation.goal_state": [2]})
    cmd = [str(BIN / cli), "--policy.type=indicator_ddpg", "--policy.push_to_hub=false", "--policy.device=cpu",
           f"--dataset.repo_id={REPO_ID}", f"--dataset.root={root}", f"--output_dir={tmp_path / 'run'}"]  # fmt: skip
    if cli == "lerobot-indicator-train":
        cmd += ["--env.type=sawyer_reach", "--env.obs_type=rgbd", f"--env.episode_length={T}",
                "--env.camera.width=32", "--env.camera.height=32", "--online.n_envs=1",
                "--online.use_async_envs=false", "--steps=1"]  # fmt: skip
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "CUDA_VISIBLE_DEVICES": ""}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 1, out[-3000:]
    errors = [line for line in out.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "goal observation.goal_state has shape (2,)" in errors[0], out[-3000:]
    assert "Traceback" not in out


def test_check_dataset_accepts_an_intact_dataset(video_dataset):
    assert check_dataset(video_dataset) == len(json.loads((video_dataset / HASHES).read_text())["files"])
