"""Samples/s of the offline paths on one recorded RGB-D dataset, stored as PNG/TIFF frames and as lossless video.

Records ``--episodes`` RGB-D reach episodes twice with the recorder (``--use_videos=false`` / ``true``, same
seed; or takes them from ``--png_root`` / ``--video_root``), then, in one run on the same machine load:

1. ``LeRobotDataset.__getitem__`` with the policy's delta indices (samples/s, PNG/TIFF decodes per sample),
   and on the video copy without delta indices (one frame per key: the reader's per-sample floor);
2. the per-key video decode of one sample: LeRobot's pyav call against the same call with a single-threaded
   decoder (milliseconds per call);
3. frame equality of the video copy, and of a copy with LeRobot's default (lossy) video encoders, against
   the PNG/TIFF frames (false positives / negatives of the indicator's bit-for-bit comparison);
4. ``lerobot-train`` on each, reading its own logged ``data_s`` / ``updt_s`` (steps after the first two);
5. ``lerobot-indicator-train --dataset.* --online.episodes_per_cycle=0`` (in-memory buffer): updates/s of a
   cycle and the share of a cycle spent sampling the buffer.

    python -m benchmarks.speed.run_offline_throughput --out docs/results/offline_throughput.json
"""

import argparse
import json
import os
import tempfile
from pathlib import Path

import torch

from benchmarks.records import command_line, git_commit, machine_record
from benchmarks.speed.offline_throughput import (
    BIN,
    PARTS,
    REPO,
    lerobot_train,
    loading_floor,
    measure_decoder,
    measure_equality,
    measure_getitem,
    offline_path,
    run,
    train_run_spec,
)
from lerobot_indicator.process import set_video_decoder_threads


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--batch_size", type=int, default=128)
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--getitem_samples", type=int, default=30)
    parser.add_argument("--parts", nargs="+", default=PARTS, choices=PARTS, help="measured in this order")
    parser.add_argument(
        "--runs",
        nargs="+",
        default=["png:0", "video:0", "video:2"],
        help="lerobot-train runs, storage:num_workers[:fork|spawn[:decoder_threads|auto]]",
    )
    parser.add_argument("--out", type=Path, required=True)
    # Datasets already recorded with the same settings (--use_videos=false / true); default: record both.
    parser.add_argument("--png_root", type=Path, default=None)
    parser.add_argument("--video_root", type=Path, default=None)
    args = parser.parse_args()
    torch.set_num_threads(1)
    # The reader parts decode as lerobot-train's fork workers do under process.environment()'s default.
    decoder_threads = 1
    set_video_decoder_threads(decoder_threads)
    env_args = ["--env.type=sawyer_reach", "--env.obs_type=rgbd", f"--env.camera.height={args.size}",
                f"--env.camera.width={args.size}"]  # fmt: skip
    record = {
        "command": command_line(),
        "commit": git_commit(),
        "machine": machine_record(),
        "video_decoder_threads_getitem": decoder_threads,
        "complete": False,  # each part is written as soon as it is measured
        "load_average_1_5_15_min_before": os.getloadavg(),
    }

    def save() -> None:
        args.out.write_text(json.dumps(record, indent=2) + "\n")

    with tempfile.TemporaryDirectory() as tmp:
        given = {"png": args.png_root, "video": args.video_root}
        roots = {name: given[name] or Path(tmp) / name for name in given}
        for name, root in roots.items():
            if given[name] is not None:
                continue
            run([str(BIN / "lerobot-indicator-record"), *env_args, "--policy=noisy_scripted",
                 f"--num_episodes={args.episodes}", f"--repo_id={REPO}", f"--root={root}",
                 f"--use_videos={str(name == 'video').lower()}"])  # fmt: skip
        record["dataset_mb"] = {
            name: sum(f.stat().st_size for f in root.rglob("*") if f.is_file()) / 2**20
            for name, root in roots.items()
        }
        for part in args.parts:  # in the order given
            if part == "getitem":
                record["delta_timestamps_s"], record["getitem"] = measure_getitem(roots, args.getitem_samples)
            elif part == "decoder":
                record["decoder_ms_per_call"] = measure_decoder(roots["video"], args.getitem_samples)
            elif part == "equality":
                record["frame_equality_vs_png"] = measure_equality(roots, Path(tmp) / "lossy")
            elif part == "offline":
                record["online_trainer_offline"] = offline_path(
                    env_args, roots["video"], Path(tmp) / "online", args.batch_size, args.steps * 5
                )
            else:
                record["lerobot_train"] = {}
                for spec in args.runs:
                    storage, workers, extra, env, name = train_run_spec(spec)
                    record["lerobot_train"][name] = lerobot_train(
                        roots[storage],
                        Path(tmp) / f"lt_{name}",
                        args.batch_size,
                        args.steps,
                        workers,
                        extra,
                        env,
                    )
                    save()
            save()
    if "getitem" in record and "lerobot_train" in record:
        record["loading_floor"] = loading_floor(record["getitem"], record["lerobot_train"], args.batch_size)
    record["complete"] = True
    record["load_average_1_5_15_min_after"] = os.getloadavg()
    print(json.dumps(record, indent=1))
    save()


if __name__ == "__main__":
    main()
