"""The frame-equality count behind the video-storage measurements (benchmarks/speed/dataset_loading.py)."""

from types import SimpleNamespace

import torch

from benchmarks.speed.dataset_loading import equality_errors

KEY, GOAL = "observation.images.front", "observation.images.goal_front"


class FakeDataset:
    """One episode of frames (value per pixel) with a constant goal frame, as LeRobotDataset indexes them."""

    def __init__(self, values: list[float], goal: float):
        self.items = [{KEY: torch.full((1, 2, 2), v), GOAL: torch.full((1, 2, 2), goal)} for v in values]
        episodes = {"dataset_from_index": [0], "dataset_to_index": [len(values)]}
        self.meta = SimpleNamespace(episodes=episodes, total_episodes=1)

    def __getitem__(self, i: int) -> dict:
        return self.items[i]


def test_counts_false_positives_and_negatives_of_frame_equality():
    # Frames 0 and 2 equal the goal in the reference. The stored copy decodes frame 1 like the others (four
    # ordered false-positive pairs) and changes the goal (frames 0 and 2 no longer match it: two false negatives).
    reference = FakeDataset([1.0, 2.0, 1.0], goal=1.0)
    stored = FakeDataset([1.0, 1.0, 1.0], goal=1.5)
    errors = equality_errors(reference, stored, [KEY])
    assert errors["frame_pairs_compared"] == 6
    assert errors["frame_pairs_equal_in_reference"] == 2  # (0, 2) and (2, 0)
    assert errors["frame_pairs_false_positives"] == 4  # (0, 1), (1, 0), (1, 2), (2, 1)
    assert errors["frame_pairs_false_negatives"] == 0
    assert errors["frame_vs_goal_equal_in_reference"] == 2
    assert errors["frame_vs_goal_false_negatives"] == 2
    assert errors["frame_vs_goal_false_positives"] == 0
    assert errors[f"frames_differing.{KEY}"] == 1 and errors[f"frames_differing.{GOAL}"] == 3
    assert not any(v for k, v in equality_errors(reference, reference, [KEY]).items() if "false" in k)


def test_single_threaded_decode_arm_decodes_the_frames_lerobot_returns(tmp_path):
    # The decoder benchmark's comparison arm must decode the same frames as LeRobot's pyav call, only on one
    # thread: a lossless 10-frame video with a distinct value per frame, queried at the policy's offsets.
    import av
    import numpy as np
    from lerobot.datasets.video_utils import decode_video_frames_pyav

    from benchmarks.speed.dataset_loading import decode_single_threaded

    path, fps = tmp_path / "v.mp4", 20
    with av.open(str(path), "w") as out:
        stream = out.add_stream(
            "hevc", rate=fps, options={"x265-params": "lossless=1:log-level=none", "g": "2"}
        )
        stream.width = stream.height = 16
        stream.pix_fmt = "gbrp"
        for i in range(10):
            frame = av.VideoFrame.from_ndarray(np.full((16, 16, 3), 20 * i, dtype=np.uint8), format="rgb24")
            out.mux(stream.encode(frame))
        out.mux(stream.encode())
    timestamps = [(2 + k) / fps for k in (0, 1, 2, 4)]
    expected = decode_video_frames_pyav(path, timestamps, 0.5 / fps, return_uint8=True)
    decoded = dict(decode_single_threaded(path, timestamps, is_depth=False))
    assert max(decoded) >= max(timestamps) - 1e-6
    got = np.stack([decoded[min(decoded, key=lambda t, q=q: abs(t - q))] for q in timestamps])
    assert np.array_equal(got.transpose(0, 3, 1, 2), expected.numpy())
    assert [int(x[0, 0, 0]) for x in got] == [40, 60, 80, 120]


def test_loading_floor_compares_the_reader_floor_spread_over_every_core_with_the_update(monkeypatch):
    from benchmarks.speed import offline_throughput

    monkeypatch.setattr(offline_throughput.os, "cpu_count", lambda: 2)
    getitem = {offline_throughput.ONE_FRAME: {"samples_per_s": 50.0}}  # 20 ms per sample
    runs = {
        "a": {"update_s_per_step": 0.256},
        "b": {"update_s_per_step": 0.128},
    }  # the faster: 1 ms per sample
    floor = offline_throughput.loading_floor(getitem, runs, batch_size=128)
    assert floor["reader_floor_ms_per_sample"] == 20.0
    assert floor["update_ms_per_sample"] == 1.0
    assert floor["floor_over_update_with_every_core"] == 10.0  # 20 ms / 2 cores against 1 ms


def test_train_run_spec_turns_start_method_and_decoder_threads_into_lerobot_train_flags_and_environment():
    import pytest

    from benchmarks.speed.offline_throughput import train_run_spec
    from lerobot_indicator.process import environment

    assert train_run_spec("video:3") == ("video", 3, [], environment(), "video_workers3")
    assert train_run_spec("video:3:fork") == (
        "video", 3, ["--dataloader_multiprocessing_context=fork"], environment(), "video_workers3_fork"
    )  # fmt: skip
    storage, workers, extra, env, name = train_run_spec("png:0:spawn:auto")
    assert (storage, workers, extra) == ("png", 0, ["--dataloader_multiprocessing_context=spawn"])
    assert (
        env == environment(video_decoder_threads=None)
        and "LEROBOT_INDICATOR_VIDEO_DECODER_THREADS" not in env
    )
    assert name == "png_workers0_spawn_decoder_threads_auto"
    assert train_run_spec("video:3:fork:2")[3]["LEROBOT_INDICATOR_VIDEO_DECODER_THREADS"] == "2"
    for bad in ("video", "mp4:3", "video:x", "video:3:fork:1:2", "video:3:fork:x"):
        with pytest.raises(ValueError, match="expected png\\|video:<workers>"):
            train_run_spec(bad)
