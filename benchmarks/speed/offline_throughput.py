"""The offline loading paths of ``benchmarks/speed/run_offline_throughput.py``: ``lerobot-train`` on a recorded dataset,
``LeRobotDataset.__getitem__`` with the policy's delta indices and without, the per-key decode, frame equality
of the stored copies, and ``lerobot-indicator-train`` from the in-memory buffer."""

import os
import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

from lerobot.datasets.factory import resolve_delta_timestamps
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from benchmarks.speed.dataset_loading import (
    copy_as_video,
    decode_call_costs,
    equality_errors,
    loading_rates,
)
from lerobot_indicator import process
from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig
from lerobot_indicator.training.plots import read_metrics

BIN = Path(sys.executable).parent
ENV = {**os.environ, "HF_HUB_OFFLINE": "1", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
REPO = "bench/rgbd"
COMPARED = ["observation.images.front", "observation.images.front_depth"]
PARTS = ["getitem", "decoder", "equality", "lerobot_train", "offline"]
ONE_FRAME = "video_one_frame_per_key"


def run(cmd: list[str], env: dict[str, str] | None = None) -> str:
    proc = subprocess.run(cmd, capture_output=True, text=True, env={**ENV, **(env or {})})
    if proc.returncode != 0:
        raise RuntimeError(f"{shlex.join(cmd)} failed:\n{proc.stderr[-3000:]}")
    return proc.stdout + proc.stderr


def lerobot_train(
    root: Path,
    out: Path,
    batch_size: int,
    steps: int,
    num_workers: int,
    extra: list[str] | None = None,
    env: dict[str, str] | None = None,
) -> dict:
    """``lerobot-train`` with the process settings of ``env`` (default ``process.environment()``: those
    lerobot-indicator-train applies by default, docs/policy.md "Process settings")."""
    env = process.environment() if env is None else env
    cmd = [str(BIN / "lerobot-train"), "--policy.type=indicator_ddpg", "--policy.push_to_hub=false",
           "--policy.device=cpu", f"--dataset.repo_id={REPO}", f"--dataset.root={root}",
           "--dataset.video_backend=pyav", f"--batch_size={batch_size}", f"--steps={steps}", "--log_freq=1",
           f"--num_workers={num_workers}", "--save_checkpoint=false", "--wandb.enable=false",
           f"--output_dir={out}", *(extra or [])]  # fmt: skip
    log = run(cmd, env)
    # The first two steps hold the loader's start (workers, accelerate's one-batch look-ahead).
    data_s = [float(x) for x in re.findall(r"data_s:([0-9.]+)", log)][2:]
    updt_s = [float(x) for x in re.findall(r"updt_s:([0-9.]+)", log)][2:]
    step_s = (sum(data_s) + sum(updt_s)) / len(data_s)
    return {
        "command": " ".join([*(f"{k}={v}" for k, v in env.items()), shlex.join(["lerobot-train", *cmd[1:]])]),
        "steps_averaged": len(data_s),
        "data_s_per_step": sum(data_s) / len(data_s),
        "update_s_per_step": sum(updt_s) / len(updt_s),
        "samples_per_s": batch_size / step_s,
        "loading_share_of_step": sum(data_s) / (sum(data_s) + sum(updt_s)),
    }


def train_run_spec(spec: str) -> tuple[str, int, list[str], dict[str, str], str]:
    """``storage:workers[:start_method[:decoder_threads]]`` -> storage, workers, extra ``lerobot-train`` flags,
    its process settings (``process.environment``), record name. ``start_method``: ``fork`` / ``spawn``
    (``--dataloader_multiprocessing_context``; default LeRobot's); ``decoder_threads``: the
    ``LEROBOT_INDICATOR_VIDEO_DECODER_THREADS`` it runs with (``auto`` = unset: FFmpeg's choice; default 1)."""
    parts = spec.split(":")
    if not 2 <= len(parts) <= 4 or parts[0] not in ("png", "video") or not parts[1].isdigit():
        raise ValueError(f"run {spec!r}: expected png|video:<workers>[:fork|spawn[:<threads>|auto]]")
    storage, workers, *rest = parts
    extra, name, threads = [], f"{storage}_workers{workers}", 1
    if rest:
        extra.append(f"--dataloader_multiprocessing_context={rest[0]}")
        name += f"_{rest[0]}"
    if len(rest) == 2:
        if rest[1] != "auto" and not rest[1].isdigit():
            raise ValueError(f"run {spec!r}: expected png|video:<workers>[:fork|spawn[:<threads>|auto]]")
        threads = None if rest[1] == "auto" else int(rest[1])
        name += f"_decoder_threads_{rest[1]}"
    return storage, int(workers), extra, process.environment(video_decoder_threads=threads), name


def measure_getitem(roots: dict[str, Path], samples: int) -> tuple[dict, dict]:
    """``__getitem__`` as lerobot-train builds the dataset (policy delta indices, uint8 video frames), and the
    video copy without delta indices (one frame per key): the per-sample floor of LeRobot's reader."""
    cfg = IndicatorDDPGConfig(device="cpu")
    datasets, delta = {}, None
    for name, root in roots.items():
        meta = LeRobotDataset(REPO, root=root, video_backend="pyav").meta
        delta = resolve_delta_timestamps(cfg, meta)
        datasets[name] = LeRobotDataset(
            REPO, root=root, video_backend="pyav", return_uint8=True, delta_timestamps=delta
        )
    datasets[ONE_FRAME] = LeRobotDataset(REPO, root=roots["video"], video_backend="pyav", return_uint8=True)
    rates = loading_rates(datasets, samples)
    rates["video_over_png_samples_per_s"] = rates["video"]["samples_per_s"] / rates["png"]["samples_per_s"]
    return delta, rates


def loading_floor(getitem: dict, train_runs: dict, batch_size: int) -> dict:
    """What "loading below the update" asks of LeRobot's reader. With every core loading (the update needs one
    too), a step's loading stays below its update only if the reader's per-sample floor divided by the cores
    is below the update's time per sample: ``floor_over_update_with_every_core`` < 1."""
    floor_ms = 1000 / getitem[ONE_FRAME]["samples_per_s"]
    update_ms = 1000 * min(r["update_s_per_step"] for r in train_runs.values()) / batch_size
    cores = os.cpu_count() or 1
    return {
        "reader_floor_ms_per_sample": floor_ms,
        "update_ms_per_sample": update_ms,
        "cores": cores,
        "floor_over_update_with_every_core": floor_ms / cores / update_ms,
    }


def measure_decoder(root: Path, calls: int) -> dict:
    """Per-key cost of one sample's video decode (episode 0's files) with the policy's delta window."""
    meta = LeRobotDataset(REPO, root=root, video_backend="pyav").meta
    videos = {key: root / meta.get_video_file_path(0, key) for key in meta.video_keys}
    frames = meta.episodes["length"][0]
    cfg = IndicatorDDPGConfig(device="cpu")
    return decode_call_costs(videos, cfg.observation_delta_indices, meta.fps, frames, calls)


def measure_equality(roots: dict[str, Path], lossy_root: Path) -> dict:
    """Indicator equality on the stored frames: lossless video and LeRobot's default encoders vs PNG/TIFF."""
    reference = LeRobotDataset(REPO, root=roots["png"], video_backend="pyav")
    lossy = copy_as_video(reference, REPO, lossy_root)
    video = LeRobotDataset(REPO, root=roots["video"], video_backend="pyav")
    return {
        "compared_keys": COMPARED,
        "video_lossless": equality_errors(reference, video, COMPARED),
        "video_lerobot_default_encoders": equality_errors(reference, lossy, COMPARED),
    }


def offline_path(env_args: list[str], root: Path, out: Path, batch_size: int, updates: int) -> dict:
    """``lerobot-indicator-train --dataset.* --online.episodes_per_cycle=0``: its second cycle's timings."""
    t0 = time.perf_counter()
    run([str(BIN / "lerobot-indicator-train"), *env_args, "--policy.type=indicator_ddpg",
         "--policy.push_to_hub=false", "--policy.device=cpu", f"--dataset.repo_id={REPO}",
         f"--dataset.root={root}", "--dataset.video_backend=pyav", "--online.episodes_per_cycle=0",
         f"--online.batch_size={batch_size}", f"--online.updates_per_cycle={updates}",
         f"--steps={updates * 2}", "--env_eval_freq=0", "--online.eval_episodes=1", "--save_checkpoint=false",
         f"--output_dir={out}"])  # fmt: skip
    rows = read_metrics(out / "metrics.jsonl")
    cycle_s = rows[1]["wall_time_s"] - rows[0]["wall_time_s"]
    return {
        "process_wall_s": time.perf_counter() - t0,
        "first_cycle_s": rows[0]["wall_time_s"],
        "updates_per_s": updates / cycle_s,
        "samples_per_s": updates * batch_size / cycle_s,
        "data_s_per_cycle": rows[1]["data_s"],
        "update_s_per_cycle": rows[1]["update_s"],
        "loading_share_of_update_time": rows[1]["data_s"] / (rows[1]["data_s"] + rows[1]["update_s"]),
    }
