"""Forward + backward of the policy's 3x256 tanh MLP: ``torch.tanh`` against the CPU tanh formulas.

Interleaved rounds in one process (``lerobot_indicator.bench.tanh``); writes steps/s per arm, the per-round
speed-up of each formula over ``torch.tanh`` in the same executor, their max errors and the machine.

    python scripts/bench_tanh.py [--batch-sizes 128 256] [--calls 20] [--rounds 40] [--out docs/results/tanh.json]
"""

import argparse
import shlex
import sys
from pathlib import Path

import torch

from lerobot_indicator.bench.records import machine_record, write_json
from lerobot_indicator.bench.tanh import bench_tanh, max_errors


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--batch-sizes", type=int, nargs="+", default=[128, 256])
    p.add_argument("--calls", type=int, default=20, help="forward + backward calls per arm and round")
    p.add_argument("--rounds", type=int, default=40)
    p.add_argument("--no-compile", action="store_true", help="skip the torch.compile arms")
    p.add_argument("--out", type=Path, default=Path("docs/results/tanh.json"))
    args = p.parse_args()
    torch.set_num_threads(1)
    result = bench_tanh(args.batch_sizes, args.calls, args.rounds, compiled=not args.no_compile)
    record = {
        "command": shlex.join(["python", *sys.argv]),
        "machine": machine_record(),
        "batch_sizes": args.batch_sizes,
        "rounds": args.rounds,
        "calls_per_round": args.calls,
        "max_abs_error": max_errors(),
        **result,
    }
    write_json(args.out, record)
    for name, s in record["speedup"].items():
        cpu, wall = s["cpu"], s["wall"]
        print(
            f"{name}: CPU time {cpu['median']:.3f} ({cpu['min']:.3f}-{cpu['max']:.3f}), wall {wall['median']:.3f}"
        )


if __name__ == "__main__":
    main()
