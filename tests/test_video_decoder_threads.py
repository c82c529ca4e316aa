"""``video_decoder_threads``: how many threads FFmpeg gives each video decoder opened afterwards (LeRobot's pyav
reader included), set by lerobot-indicator-train's flag or, under LeRobot's CLIs, by an environment variable
read when the plugin is imported; forked loader workers inherit it, and the decoded frames stay bit-identical."""

import multiprocessing
import os
import subprocess
import sys

import av
import numpy as np
import pytest
import torch
from lerobot.datasets.video_utils import decode_video_frames_pyav

from benchmarks.speed.updates import STATE_FEATURES, make_policy
from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig
from lerobot_indicator.process import VIDEO_DECODER_THREADS_ENV, ffmpeg_cores, set_video_decoder_threads
from lerobot_indicator.training.config import OnlineTrainConfig

FPS = 20


@pytest.fixture(autouse=True)
def restore_ffmpeg_default():
    yield
    set_video_decoder_threads(None)


@pytest.fixture(scope="module")
def video(tmp_path_factory) -> tuple[str, np.ndarray]:
    """12 random 64x64 RGB frames in HEVC, lossless planar RGB: the recorder's RGB storage (data/storage.py)."""
    frames = np.random.default_rng(0).integers(0, 256, (12, 64, 64, 3), dtype=np.uint8)
    path = str(tmp_path_factory.mktemp("video") / "rgb.mp4")
    with av.open(path, "w") as out:
        stream = out.add_stream(
            "hevc", rate=FPS, options={"x265-params": "lossless=1:log-level=none", "g": "2"}
        )
        stream.width, stream.height, stream.pix_fmt = 64, 64, "gbrp"
        for frame in frames:
            out.mux(stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24").reformat(format="gbrp")))
        out.mux(stream.encode())
    return path, frames


def decoder_threads(path: str) -> int:
    """Threads FFmpeg gave a decoder opened now, as LeRobot's pyav reader opens one (no thread settings)."""
    with av.open(path) as container:
        stream = container.streams.video[0]
        next(container.decode(stream))
        return stream.codec_context.thread_count


def test_setting_decides_the_threads_of_decoders_opened_afterwards(video):
    path, _ = video
    assert set_video_decoder_threads(1)
    assert ffmpeg_cores() == 1
    assert decoder_threads(path) == 1
    set_video_decoder_threads(None)
    assert ffmpeg_cores() == len(os.sched_getaffinity(0))
    if ffmpeg_cores() > 1:  # FFmpeg's own choice: one thread per core + 1
        assert decoder_threads(path) == ffmpeg_cores() + 1
    set_video_decoder_threads(3)
    assert decoder_threads(path) == 4


def test_frames_are_identical_with_one_thread_and_ffmpegs_choice(video):
    path, frames = video
    timestamps = [k / FPS for k in (0, 1, 3, 7, 11)]
    decoded = {}
    for threads in (None, 1):
        set_video_decoder_threads(threads)
        decoded[threads] = decode_video_frames_pyav(path, timestamps, 1 / (2 * FPS), return_uint8=True)
    assert torch.equal(decoded[None], decoded[1])
    expected = torch.from_numpy(frames[[0, 1, 3, 7, 11]]).permute(0, 3, 1, 2)
    assert torch.equal(decoded[1], expected)  # lossless: the recorded frames, bit for bit


def _child_cores(queue) -> None:
    queue.put(ffmpeg_cores())


def test_forked_workers_inherit_the_setting_and_a_policy_leaves_it_alone():
    set_video_decoder_threads(1)
    make_policy(STATE_FEATURES)
    assert ffmpeg_cores() == 1
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    worker = ctx.Process(target=_child_cores, args=(queue,))
    worker.start()
    assert queue.get(timeout=60) == 1
    worker.join(timeout=60)
    set_video_decoder_threads(None)
    make_policy(STATE_FEATURES)
    assert ffmpeg_cores() == len(os.sched_getaffinity(0))


CORES_AFTER_PLUGIN_IMPORT = """
import lerobot_indicator
from lerobot_indicator.process import ffmpeg_cores
print(ffmpeg_cores())
"""


def cores_after_plugin_import(value: str | None) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != VIDEO_DECODER_THREADS_ENV}
    if value is not None:
        env[VIDEO_DECODER_THREADS_ENV] = value
    return subprocess.run(
        [sys.executable, "-c", CORES_AFTER_PLUGIN_IMPORT], capture_output=True, text=True, env=env
    )


def test_environment_variable_sets_the_threads_when_the_plugin_is_imported():
    """What lerobot-train users set (docs/policy.md, "Process settings"); unset, FFmpeg keeps its choice."""
    assert cores_after_plugin_import("1").stdout.split()[-1] == "1"
    assert cores_after_plugin_import(None).stdout.split()[-1] == str(len(os.sched_getaffinity(0)))
    bad = cores_after_plugin_import("0")
    assert (
        bad.returncode != 0
        and f"{VIDEO_DECODER_THREADS_ENV} must be a thread count >= 1, got '0'" in bad.stderr
    )


def test_a_bad_thread_count_names_the_flag():
    cfg = OnlineTrainConfig(env=None, policy=IndicatorDDPGConfig(device="cpu"), video_decoder_threads=0)
    with pytest.raises(ValueError, match=r"--video_decoder_threads must be null .* or >= 1, got 0"):
        cfg.validate()
    with pytest.raises(ValueError, match="video_decoder_threads must be None or >= 0, got -1"):
        set_video_decoder_threads(-1)
