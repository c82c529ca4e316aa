"""What a ``lerobot-train`` sample of a recorded dataset costs, and what video storage does to the indicator.

- :func:`loading_rates`: samples/s of ``LeRobotDataset.__getitem__`` with the policy's delta indices, and
  the image decodes per sample (PNG/TIFF frames: ``datasets`` decodes every image column of every row a
  key's delta query touches; video frames are decoded per video key instead).
- :func:`equality_errors`: the indicator compares frames bit for bit. Over every pair of frames of an
  episode (a relabelled goal o_{t'} against o_{t+1}, and each frame against the episode's goal) it counts
  the pairs a stored copy of the dataset calls equal where the lossless source does not (false positives)
  and the reverse (false negatives).
- :func:`decode_call_costs`: what one video key of one sample costs in LeRobot's pyav decoder (a fresh
  container and decoder per call, FFmpeg's default thread count) against the same call with a
  single-threaded decoder, for the policy's delta window and for o_t alone.
- :func:`bench_dataset`: samples/s of a synthetic 100 px PNG dataset (:func:`make_rgbd_dataset`) for growing
  delta windows (``benchmarks/speed/run_policy_updates.py --dataset-cost``).
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path

import av
import torch
from datasets.features import image as hf_image
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.datasets.video_utils import decode_video_frames_pyav

from lerobot_indicator.keys import goal_key
from lerobot_indicator.process import ffmpeg_cores, set_video_decoder_threads


@contextmanager
def count_image_decodes():
    """Counts ``datasets``' PNG/TIFF decodes in this process while the context is open."""
    counter: Counter = Counter()
    original = hf_image.Image.decode_example

    def counting(self, value, token_per_repo_id=None):
        counter["decodes"] += 1
        return original(self, value, token_per_repo_id)

    hf_image.Image.decode_example = counting
    try:
        yield counter
    finally:
        hf_image.Image.decode_example = original


def loading_rates(datasets: dict[str, LeRobotDataset], samples: int, rounds: int = 3) -> dict[str, dict]:
    """Samples/s of each dataset's ``__getitem__``, timed in interleaved rounds (same load on every arm)."""
    elapsed = dict.fromkeys(datasets, 0.0)
    decodes = {}
    for name, ds in datasets.items():
        with count_image_decodes() as counter:
            ds[0]
        decodes[name] = counter["decodes"]
    for r in range(rounds):
        for name, ds in datasets.items():
            t0 = time.perf_counter()
            for i in range(samples):
                ds[(r * samples + i) * 7 % len(ds)]
            elapsed[name] += time.perf_counter() - t0
    return {
        name: {
            "samples_per_s": rounds * samples / elapsed[name],
            "png_tiff_decodes_per_sample": decodes[name],
        }
        for name in datasets
    }


def _frame_ids(frames: list[dict[str, torch.Tensor]], keys: list[str]) -> torch.Tensor:
    """One id per frame: equal ids iff the frames are bit-for-bit equal on every key."""
    flat = torch.cat([torch.stack([f[k] for f in frames]).float().flatten(1) for k in keys], dim=1)
    return torch.unique(flat, dim=0, return_inverse=True)[1]


def equality_errors(reference: LeRobotDataset, stored: LeRobotDataset, keys: list[str]) -> dict[str, int]:
    """False positives / negatives of frame equality in ``stored`` against ``reference`` (the same frames).

    Both datasets must return images alike (float in [0, 1] for RGB, millimetres for depth).
    """
    out: Counter = Counter()
    goals = [goal_key(k) for k in keys]
    episodes = reference.meta.episodes
    for ep in range(reference.meta.total_episodes):
        start, end = episodes["dataset_from_index"][ep], episodes["dataset_to_index"][ep]
        ref = [reference[i] for i in range(start, end)]
        new = [stored[i] for i in range(start, end)]
        for k in keys + goals:
            out[f"frames_differing.{k}"] += sum(
                not torch.equal(x[k], y[k]) for x, y in zip(ref, new, strict=True)
            )
        # Ids of the episode's frames and, last, of its recorded goal (stored under the goal keys).
        ids = []
        for frames in (ref, new):
            goal = {k: frames[0][g] for k, g in zip(keys, goals, strict=True)}
            ids.append(_frame_ids([*frames, goal], keys))
        eq_ref, eq_new = (i[:, None] == i[None] for i in ids)
        n = end - start
        pairs = ~torch.eye(n, dtype=torch.bool)  # o_{t+1} against another frame o_{t'} of the episode
        for name, ref_eq, new_eq in (
            ("frame_pairs", eq_ref[:n, :n][pairs], eq_new[:n, :n][pairs]),
            ("frame_vs_goal", eq_ref[n, :n], eq_new[n, :n]),
        ):
            out[f"{name}_compared"] += ref_eq.numel()
            out[f"{name}_equal_in_reference"] += int(ref_eq.sum())
            out[f"{name}_false_positives"] += int((new_eq & ~ref_eq).sum())
            out[f"{name}_false_negatives"] += int((ref_eq & ~new_eq).sum())
    return dict(out)


def copy_as_video(source: LeRobotDataset, repo_id: str, root, **encoders) -> LeRobotDataset:
    """``source``'s episodes re-written with its camera keys as video (LeRobot's default encoders unless
    ``encoders`` gives ``rgb_encoder`` / ``depth_encoder``): the same frames under another storage."""
    features = {
        k: ({**ft, "dtype": "video"} if ft["dtype"] == "image" else ft)
        for k, ft in source.meta.features.items()
        if k not in ("timestamp", "frame_index", "episode_index", "index", "task_index")
    }
    copy = LeRobotDataset.create(
        repo_id,
        fps=source.fps,
        features=features,
        root=root,
        use_videos=True,
        video_backend="pyav",
        **encoders,
    )
    episodes = source.meta.episodes
    for ep in range(source.meta.total_episodes):
        for i in range(episodes["dataset_from_index"][ep], episodes["dataset_to_index"][ep]):
            item = source[i]
            frame = {"task": item["task"]}
            for key in features:
                value = item[key]
                if key in source.meta.depth_keys:
                    frame[key] = value.permute(1, 2, 0).numpy().astype("uint16")
                elif key in source.meta.camera_keys:
                    frame[key] = (value * 255).round().to(torch.uint8).permute(1, 2, 0).numpy()
                else:
                    frame[key] = value.reshape(features[key]["shape"]).numpy()
            copy.add_frame(frame)
        copy.save_episode()
    copy.finalize()
    return LeRobotDataset(repo_id, root=root, video_backend="pyav")


def decode_single_threaded(path: Path, timestamps: list[float], is_depth: bool) -> list[tuple[float, object]]:
    """LeRobot's pyav decode loop (seek to the keyframe before the first timestamp, decode forward past the
    last) with the decoder on one thread: every decoded frame as (timestamp, array)."""
    decoded = []
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        stream.codec_context.thread_count = 1
        container.seek(round(min(timestamps) / stream.time_base) - 1, backward=True, stream=stream)
        for frame in container.decode(stream):
            ts = float(frame.pts * stream.time_base)
            decoded.append((ts, frame.to_ndarray(format="gray12le" if is_depth else "rgb24")))
            if ts >= max(timestamps):
                break
    return decoded


def decode_call_costs(
    videos: dict[str, Path], offsets: list[int], fps: int, frames: int, calls: int, rounds: int = 3
) -> dict[str, dict[str, float]]:
    """Milliseconds per call, per video key: ``decode_video_frames_pyav`` (what ``lerobot-train`` runs per
    key per sample) with FFmpeg's thread choice and with one decoder thread (``video_decoder_threads=1``), and
    the single-threaded loop, for ``offsets`` (the policy's delta indices) and for ``[0]``, at start frames
    spread over the first ``frames - max(offsets)`` frames of one episode's file. Interleaved rounds, so load
    on the machine hits every arm alike. Leaves FFmpeg's thread choice as it found it."""
    starts = [i % max(1, frames - max(offsets)) for i in range(calls)]
    before = ffmpeg_cores()

    def lerobot_pyav(threads: int | None) -> Callable[[Path, list[float], bool], object]:
        def call(path: Path, ts: list[float], depth: bool) -> object:
            set_video_decoder_threads(threads)
            return decode_video_frames_pyav(path, ts, 1 / (2 * fps), return_uint8=True, is_depth=depth)

        return call

    arms = {
        "lerobot_pyav": lerobot_pyav(None),
        "lerobot_pyav_one_decoder_thread": lerobot_pyav(1),
        "single_threaded_decoder": decode_single_threaded,
    }
    spent: dict[str, Counter] = {key: Counter() for key in videos}
    for _ in range(rounds):
        for key, path in videos.items():
            depth = "depth" in key
            for window_name, window in (("delta_window", offsets), ("o_t_only", [0])):
                for arm, fn in arms.items():
                    t0 = time.perf_counter()
                    for start in starts:
                        fn(path, [(start + k) / fps for k in window], depth)
                    spent[key][f"{arm}.{window_name}_ms"] += time.perf_counter() - t0
    set_video_decoder_threads(before)  # the same core count: FFmpeg's choice as before
    out = {}
    for key, totals in spent.items():
        out[key] = {name: 1000 * total / (rounds * calls) for name, total in totals.items()}
        out[key]["lerobot_over_single_threaded.delta_window"] = (
            totals["lerobot_pyav.delta_window_ms"] / totals["single_threaded_decoder.delta_window_ms"]
        )
        out[key]["lerobot_over_one_decoder_thread.delta_window"] = (
            totals["lerobot_pyav.delta_window_ms"] / totals["lerobot_pyav_one_decoder_thread.delta_window_ms"]
        )
    return out


def make_rgbd_dataset(root: Path, episodes: int = 4, horizon: int = 25) -> Path:
    """Random 100x100 RGB-D frames with the conventions' keys (docs/conventions.md), stored as PNG images."""
    import numpy as np

    rgb = {"dtype": "image", "shape": (100, 100, 3), "names": ["height", "width", "channels"]}
    depth = {
        "dtype": "image",
        "shape": (100, 100, 1),
        "names": ["height", "width", "channels"],
        "info": {"is_depth_map": True},
    }
    vec = {"dtype": "float32", "shape": (3,), "names": ["x", "y", "z"]}
    features = {
        "observation.images.front": rgb,
        "observation.images.front_depth": depth,
        "observation.images.goal_front": rgb,
        "observation.images.goal_front_depth": depth,
        "observation.state": vec,
        "action": vec,
    }
    ds = LeRobotDataset.create("bench/rgbd", fps=10, features=features, root=root, use_videos=False)
    rng = np.random.default_rng(0)
    for _ in range(episodes):
        goal_rgb = rng.integers(0, 256, (100, 100, 3), dtype=np.uint8)
        goal_depth = rng.uniform(0.3, 2.0, (100, 100, 1)).astype(np.float32)
        for _ in range(horizon):
            ds.add_frame(
                {
                    "observation.images.front": rng.integers(0, 256, (100, 100, 3), dtype=np.uint8),
                    "observation.images.front_depth": rng.uniform(0.3, 2.0, (100, 100, 1)).astype(np.float32),
                    "observation.images.goal_front": goal_rgb,
                    "observation.images.goal_front_depth": goal_depth,
                    "observation.state": rng.normal(size=3).astype(np.float32),
                    "action": rng.uniform(-1, 1, 3).astype(np.float32),
                    "task": "reach",
                }
            )
        ds.save_episode()
    ds.finalize()
    return root


def bench_dataset(seconds: float) -> dict:
    """Samples/s of LeRobotDataset.__getitem__ for growing observation_delta_indices (4 image keys)."""
    import tempfile

    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        root = make_rgbd_dataset(Path(tmp) / "rgbd")
        for deltas in ([0], [0, 1, 2], [0, 1, 2, 4, 8, 16]):
            keys = ["observation.images.front", "observation.images.front_depth"]
            keys += [
                "observation.images.goal_front",
                "observation.images.goal_front_depth",
                "observation.state",
            ]
            delta_timestamps = {k: [d / 10 for d in deltas] for k in keys}
            ds = LeRobotDataset("bench/rgbd", root=root, delta_timestamps=delta_timestamps)
            n, start = 0, time.perf_counter()
            while time.perf_counter() - start < seconds:
                ds[n % len(ds)]
                n += 1
            elapsed = time.perf_counter() - start
            out[str(deltas)] = {"samples_per_s": n / elapsed, "frames_per_sample_per_image_key": len(deltas)}
    return out
