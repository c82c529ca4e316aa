"""Per-run throughput of online rope runs from their metrics.jsonl: where a cycle's wall time goes.

    python -m benchmarks.speed.cycle_times OUT.json NAME=RUN_DIR_GLOB [NAME=RUN_DIR_GLOB ...]

A cycle collects episodes and runs updates (here 24 env steps and 40 updates); `update_s` and `data_s` are the trainer's own
timers (updates; sampling and relabeling the batches), the rest of a cycle's wall time is the rollouts, the
evaluations every 10 cycles and the replay files. Medians over the cycles after the first 5 (start-up), so a
resume's gap or a cycle with an evaluation does not move them.
"""

import glob
import json
import sys
from itertools import pairwise
from pathlib import Path
from statistics import median

from benchmarks.experiments.runner import read_rows
from benchmarks.records import command_line

WARMUP_CYCLES = 5


def run_stats(metrics: Path) -> dict:
    cycles = [r for r in read_rows(metrics) if "update_s" in r]
    steady = cycles[WARMUP_CYCLES:]
    wall = median(b["wall_time_s"] - a["wall_time_s"] for a, b in pairwise(steady))
    update = median(r["update_s"] for r in steady[1:])
    data = median(r["data_s"] for r in steady[1:])
    updates_per_cycle = median(b["step"] - a["step"] for a, b in pairwise(steady))
    last = cycles[-1]
    return {
        "run": str(metrics.parent),
        "cycles": len(cycles),
        "updates": last["step"],
        "env_steps": last["env_steps"],
        "wall_time_s": round(last["wall_time_s"], 1),
        "median_per_cycle_s": {
            "wall": wall,
            "update": update,
            "data": data,
            "rollouts_eval_io": wall - update - data,
        },
        "updates_per_s": updates_per_cycle / wall,
    }


def main() -> None:
    out, groups = Path(sys.argv[1]), dict(arg.split("=", 1) for arg in sys.argv[2:])
    result = {"command": command_line()}
    for name, pattern in groups.items():
        runs = [run_stats(Path(p) / "metrics.jsonl") for p in sorted(glob.glob(pattern))]
        result[name] = {
            "runs": runs,
            "aggregate_updates_per_s": sum(r["updates_per_s"] for r in runs),
            "mean_of_median_per_cycle_s": {
                k: sum(r["median_per_cycle_s"][k] for r in runs) / len(runs)
                for k in runs[0]["median_per_cycle_s"]
            },
        }
        print(
            name,
            len(runs),
            "runs;",
            json.dumps(result[name]["mean_of_median_per_cycle_s"]),
            f"aggregate {result[name]['aggregate_updates_per_s']:.1f} updates/s",
        )
    out.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
