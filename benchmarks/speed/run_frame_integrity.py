#!/usr/bin/env python
"""Cost of the content hashes (lerobot_indicator/data/integrity.py) -> docs/results/frame_integrity.json.

    MUJOCO_GL=egl python -m benchmarks.speed.run_frame_integrity --episodes=20 --size=64 --rounds=2 \
        --train_steps=20 --train_batch_size=64 --train_rounds=3

Recording: ``record()`` of ``--episodes`` RGB-D reach episodes (PNG/TIFF frames and lossless video), with the
hashes and with ``updated_hashes`` replaced by a stub (no file read, no hash), in interleaved rounds; besides
frames/s, the seconds spent inside ``updated_hashes`` during the hashed recordings (the exact cost, which a
shared machine's load does not blur). Loading: on each hashed dataset, the once-per-run check both trainers
run (``check_dataset``: hashes, shapes, video headers) with and without the hash file, the hash
verification alone (``verify_hashes``), against the
``LeRobotDataset`` construction and ``__getitem__`` samples/s (``benchmarks.speed.dataset_loading``).
``lerobot-train``: on the hashed video dataset, the README's RGB-D command (pyav, 3 forked workers, one decoder
and one torch thread) for ``--train_steps`` steps of ``--train_batch_size``, with the check and with the plugin's
check left out (the same process otherwise), in interleaved rounds: samples/s over each process's wall time
(start-up included, where the check runs) and the seconds ``make_train_eval_datasets`` took in each.
"""

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from lerobot.datasets.lerobot_dataset import LeRobotDataset

from benchmarks.records import command_line, git_commit, machine_record
from benchmarks.speed.dataset_loading import loading_rates
from lerobot_indicator.data import checkpoint
from lerobot_indicator.data.integrity import HASHES, check_dataset, verify_hashes
from lerobot_indicator.data.recorder import RecordConfig, record
from lerobot_indicator.envs import SawyerReachEnvConfig

OUT = Path(__file__).resolve().parents[2] / "docs" / "results" / "frame_integrity.json"
REPO = "bench/integrity"


def record_timed(root: Path, episodes: int, size: int, use_videos: bool, hashing: bool) -> dict:
    """One recording; with ``hashing``, also the seconds spent in ``updated_hashes``."""
    real, spent = checkpoint.updated_hashes, [0.0]

    def timed(*args, **kwargs) -> str:
        t0 = time.perf_counter()
        try:
            return real(*args, **kwargs)
        finally:
            spent[0] += time.perf_counter() - t0

    checkpoint.updated_hashes = timed if hashing else (lambda *args, **kwargs: '{"algorithm": "none"}')
    try:
        env = SawyerReachEnvConfig(obs_type="rgbd", camera={"width": size, "height": size})
        cfg = RecordConfig(env=env, repo_id=REPO, root=root, num_episodes=episodes, use_videos=use_videos)
        t0 = time.perf_counter()
        frames = record(cfg).meta.total_frames
        seconds = time.perf_counter() - t0
    finally:
        checkpoint.updated_hashes = real
    return {"seconds": seconds, "frames_per_s": frames / seconds, "hash_seconds": spent[0], "frames": frames}


# lerobot-train as its console script runs it, the plugin imported first; argv[1] "check" keeps the plugin's dataset
# check, "no_check" marks make_train_eval_datasets as checked so the plugin leaves it alone. Prints how long
# make_train_eval_datasets (check included) took.
TRAIN_CHILD = """
import functools, sys, time
from lerobot.scripts import lerobot_train as script
if sys.argv.pop(1) == "no_check":
    script.make_train_eval_datasets.checks_integrity = True
import lerobot_policy_indicator_ddpg
make = script.make_train_eval_datasets
@functools.wraps(make)
def timed(cfg):
    t0 = time.perf_counter()
    try:
        return make(cfg)
    finally:
        print(f"DATASETS_S={time.perf_counter() - t0}", flush=True)
script.make_train_eval_datasets = timed
sys.argv[0] = "lerobot-train"
script.main()
"""
# The README's RGB-D lerobot-train environment.
TRAIN_ENV = {
    "OMP_NUM_THREADS": "1",
    "MALLOC_MMAP_MAX_": "0",
    "MALLOC_TRIM_THRESHOLD_": "2147483647",
    "LEROBOT_INDICATOR_VIDEO_DECODER_THREADS": "1",
    "HF_HUB_OFFLINE": "1",
    "CUDA_VISIBLE_DEVICES": "",
}


def lerobot_train_timed(root: Path, out: Path, check: bool, steps: int, batch_size: int) -> dict:
    """One ``lerobot-train`` process on the dataset at ``root``: wall seconds, samples/s over them, and the
    seconds of ``make_train_eval_datasets``."""
    args = [f"--dataset.repo_id={REPO}", f"--dataset.root={root}", "--dataset.video_backend=pyav",
            "--num_workers=3", "--dataloader_multiprocessing_context=fork", f"--batch_size={batch_size}",
            f"--steps={steps}", "--policy.type=indicator_ddpg", "--policy.push_to_hub=false",
            "--policy.device=cpu", "--save_checkpoint=false", "--wandb.enable=false", f"--log_freq={steps}",
            f"--output_dir={out}"]  # fmt: skip
    cmd = [sys.executable, "-c", TRAIN_CHILD, "check" if check else "no_check", *args]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, **TRAIN_ENV})
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"lerobot-train failed: {proc.stderr[-3000:]}")
    datasets_s = float(next(x for x in proc.stdout.splitlines() if x.startswith("DATASETS_S=")).split("=")[1])
    return {"seconds": seconds, "samples_per_s": steps * batch_size / seconds, "make_datasets_s": datasets_s}


def median_seconds(call, rounds: int = 3) -> float:
    times = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        call()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--samples", type=int, default=50)  # __getitem__ calls per timing round
    parser.add_argument("--train_steps", type=int, default=20)  # lerobot-train steps per process
    parser.add_argument("--train_batch_size", type=int, default=64)
    parser.add_argument("--train_rounds", type=int, default=3)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    result = {
        "command": f"MUJOCO_GL={os.environ.get('MUJOCO_GL', '')} {command_line()}",
        "commit": git_commit(),
        "machine": machine_record(),
        "load_average_1_5_15_min_before": os.getloadavg(),
        "recording": {},
        "loading": {},
    }
    with tempfile.TemporaryDirectory() as tmp:
        kept = {}
        for storage, use_videos in (("png", False), ("video", True)):
            runs = {"hashed": [], "unhashed": []}
            for r in range(args.rounds):
                for arm in ("hashed", "unhashed") if r % 2 == 0 else ("unhashed", "hashed"):
                    root = Path(tmp) / f"{storage}_{arm}_{r}"
                    runs[arm].append(
                        record_timed(root, args.episodes, args.size, use_videos, arm == "hashed")
                    )
                    if arm == "hashed" and storage not in kept:
                        kept[storage] = root
                    else:
                        shutil.rmtree(root)
                    print(storage, arm, json.dumps(runs[arm][-1]), flush=True)
            hashed_fps = [run["frames_per_s"] for run in runs["hashed"]]
            ratios = [h / u["frames_per_s"] for h, u in zip(hashed_fps, runs["unhashed"], strict=True)]
            result["recording"][storage] = {
                "runs": runs,
                "hashed_over_unhashed_frames_per_s_per_round": ratios,
                "hash_share_of_recording_time": statistics.median(
                    run["hash_seconds"] / run["seconds"] for run in runs["hashed"]
                ),
                "hash_ms_per_episode": 1000
                * statistics.median(run["hash_seconds"] for run in runs["hashed"])
                / args.episodes,
            }
        for storage, root in kept.items():
            unhashed = Path(tmp) / f"{storage}_no_hash_file"
            shutil.copytree(root, unhashed)
            (unhashed / HASHES).unlink()
            size_mb = sum(p.stat().st_size for p in root.rglob("*") if p.is_file()) / 2**20
            construct_s = median_seconds(
                lambda root=root: LeRobotDataset(REPO, root=root, video_backend="pyav")
            )
            check_hashed_s = median_seconds(lambda root=root: check_dataset(root))
            check_unhashed_s = median_seconds(lambda root=unhashed: check_dataset(root))
            verify_s = median_seconds(lambda root=root: verify_hashes(root))
            dataset = LeRobotDataset(REPO, root=root, video_backend="pyav")
            samples_per_s = loading_rates({storage: dataset}, args.samples)[storage]["samples_per_s"]
            result["loading"][storage] = {
                "dataset_mb": size_mb,
                "lerobot_dataset_construction_s": construct_s,
                "check_with_hashes_s": check_hashed_s,
                "check_without_hash_file_s": check_unhashed_s,
                "hash_verification_s": verify_s,
                "hash_verification_mb_per_s": size_mb / verify_s,
                "getitem_samples_per_s": samples_per_s,
                "check_with_hashes_in_getitem_samples": check_hashed_s * samples_per_s,
            }
            print(storage, json.dumps(result["loading"][storage]), flush=True)
        runs = {"check": [], "no_check": []}
        for r in range(args.train_rounds):
            for arm in ("check", "no_check") if r % 2 == 0 else ("no_check", "check"):
                out = Path(tmp) / f"train_{arm}_{r}"
                run = lerobot_train_timed(
                    kept["video"], out, arm == "check", args.train_steps, args.train_batch_size
                )
                runs[arm].append(run)
                shutil.rmtree(out, ignore_errors=True)
                print("lerobot-train", arm, json.dumps(run), flush=True)
        ratios = [
            c["samples_per_s"] / n["samples_per_s"]
            for c, n in zip(runs["check"], runs["no_check"], strict=True)
        ]
        check_s = statistics.median(run["make_datasets_s"] for run in runs["check"]) - statistics.median(
            run["make_datasets_s"] for run in runs["no_check"]
        )
        result["lerobot_train"] = {
            "dataset": "video",
            "steps": args.train_steps,
            "batch_size": args.train_batch_size,
            "runs": runs,
            "checked_over_unchecked_samples_per_s_per_round": ratios,
            "checked_over_unchecked_samples_per_s": statistics.median(ratios),
            "check_s": check_s,
            "check_share_of_run": check_s / statistics.median(run["seconds"] for run in runs["check"]),
        }
    result["load_average_1_5_15_min_after"] = os.getloadavg()
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
