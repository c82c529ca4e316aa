"""Gradient updates/s of ``indicator_ddpg`` beside LeRobot 0.6.1's SAC, FLOPs per update and the CPU's peak.

RGB-D arms at 64 and 100 px, batch 128, timed in one interleaved run (``benchmarks.speed.updates``): the
paper's encoder, the default ("drq") encoder, each also with float32 convs, "drq" with 3-step targets and the
inverse-dynamics loss (the setting that learns RGB-D reach), that one also compiled (``compile_model``), "drq"
with each conv and its ReLU as plain ops rather than one fused oneDNN primitive, and
LeRobot's SAC (``gaussian_actor`` + ``SACAlgorithm``) on the same image size and batch, with its convs trained
(as ours) and frozen (its config default); plus the state-based update (batch 256). For each arm the matmul/conv FLOPs
of one update and their share of the measured peak. ``--dataset-cost`` also times what fetching future frames
costs in lerobot-train. Writes a JSON record (default ``docs/results/policy_updates.json``).

    python -m benchmarks.speed.run_policy_updates [--device cpu] [--seconds 9] [--threads 1] [--dataset-cost]
"""

import argparse
import json
import os
from pathlib import Path

import torch

from benchmarks.records import command_line, cpu_model, git_commit
from benchmarks.speed.dataset_loading import bench_dataset
from benchmarks.speed.peers import (
    COMPILED,
    ENCODERS,
    make_arms,
    matmul_conv_flops,
    measure_peaks,
)
from benchmarks.speed.updates import interleaved_rates
from lerobot_indicator.policy.networks_indicator_ddpg import native_bf16
from lerobot_indicator.process import keep_freed_memory


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--seconds", type=float, default=9.0, help="per arm, split over 3 interleaved rounds")
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 100])
    parser.add_argument("--batch-size", type=int, default=128)
    parser.add_argument("--dataset-cost", action="store_true")
    parser.add_argument("--threads", type=int, default=None, help="torch.set_num_threads (default: torch's)")
    parser.add_argument(
        "--return-freed-memory",
        action="store_true",
        help="leave glibc's allocator at its defaults (no lerobot_indicator.process.keep_freed_memory)",
    )
    parser.add_argument("--out", type=Path, default=Path("docs/results/policy_updates.json"))
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    if not args.return_freed_memory:  # as lerobot-indicator-train's default --keep_freed_memory=true
        keep_freed_memory()
    arms = make_arms(args.device, args.sizes, args.batch_size)
    flops = {name: matmul_conv_flops(step) for name, step in arms.items() if COMPILED not in name}
    flops.update({name: flops[name.replace(COMPILED, "")] for name in arms if COMPILED in name})
    results = interleaved_rates(arms, args.seconds)
    peaks = measure_peaks(device=args.device)
    peak = max(peaks.values())
    for name, r in results.items():
        r["gflop_per_update"] = flops[name] / 1e9
        r["gflop_per_s"] = flops[name] / 1e9 * r["updates_per_s"]
        r["share_of_best_measured_peak"] = r["gflop_per_s"] / peak
    ratios = {}
    for size in args.sizes:
        rate = {name: results[f"{name}_{size}px"]["updates_per_s"] for name in (*ENCODERS, "lerobot_sac")}
        ratios[f"{size}px"] = {
            "drq_over_paper": rate["drq"] / rate["paper"],
            "drq_over_paper_fp32": rate["drq"] / rate["paper_fp32"],
            "drq_n3_inverse_dynamics_over_paper": rate["drq_n3_inverse_dynamics"] / rate["paper"],
            "drq_n3_inverse_dynamics_over_drq": rate["drq_n3_inverse_dynamics"] / rate["drq"],
            "drq_n3_inverse_dynamics_compiled_over_eager": rate["drq_n3_inverse_dynamics_compiled"]
            / rate["drq_n3_inverse_dynamics"],
            "drq_over_lerobot_sac": rate["drq"] / rate["lerobot_sac"],
            "drq_light_over_paper": rate["drq_light"] / rate["paper"],
            "drq_bf16_over_fp32": rate["drq"] / rate["drq_fp32"],
        }
    device_name = torch.cuda.get_device_name() if args.device.startswith("cuda") else cpu_model()
    record = {
        "command": command_line(),
        "commit": git_commit(),
        "keep_freed_memory": not args.return_freed_memory,
        "device": args.device,
        "device_name": device_name,
        "native_bf16": native_bf16(torch.device(args.device).type),
        "cpu_count": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "load_average_1_5_15_min_after": os.getloadavg(),
        "torch": torch.__version__,
        "batch_size": args.batch_size,
        "peaks_gflop_per_s": peaks,
        "ratios": ratios,
        "results": results,
    }
    for name, r in results.items():
        print(
            f"{name}: {r['updates_per_s']:.2f} updates/s, {r['gflop_per_update']:.1f} GFLOP/update, "
            f"{100 * r['share_of_best_measured_peak']:.0f}% of peak"
        )
    print(json.dumps(ratios, indent=1))
    if args.dataset_cost:
        record["dataset_getitem_rgbd_100x100"] = bench_dataset(args.seconds)
        for deltas, r in record["dataset_getitem_rgbd_100x100"].items():
            print(f"dataset deltas {deltas}: {r['samples_per_s']:.1f} samples/s")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    existing = json.loads(args.out.read_text()) if args.out.exists() else {}
    suffix = "_freed_memory_returned" if args.return_freed_memory else ""
    existing[f"{device_name}_threads{torch.get_num_threads()}{suffix}"] = record
    args.out.write_text(json.dumps(existing, indent=2) + "\n")


if __name__ == "__main__":
    main()
