#!/usr/bin/env python
"""Measure recording throughput (frames/s) per task and observation type -> docs/results/record_throughput.json.

    MUJOCO_GL=egl python scripts/record_throughput.py --episodes=20 [--tasks sawyer_reach rope_push]

With ``--compare_root=<dir>`` (another version of this package, e.g. ``git archive <commit> | tar -x -C <dir>``)
both versions are measured in ``--rounds`` interleaved rounds and the JSON gets frames/s ratios
(this tree / the other) per setting. See ``lerobot_indicator/bench/record_throughput.py``. The datasets go
to temporary directories.
"""

import argparse
import json
import os
import platform
import sys
from pathlib import Path

from lerobot_indicator.bench.record_throughput import SETTINGS, THIS_TREE, compare, measure

OUT = Path(__file__).resolve().parents[1] / "docs" / "results" / "record_throughput.json"


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--tasks", nargs="+", default=["sawyer_reach"])
    parser.add_argument("--compare_root", type=Path, default=None)
    parser.add_argument("--compare_label", default="other", help="name of the --compare_root version")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    result = {
        "command": f"MUJOCO_GL={os.environ.get('MUJOCO_GL', '')} python {' '.join(sys.argv)}",
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPU cores (shared), no GPU rendering",
    }
    if args.compare_root is None:
        runs = []
        for task in args.tasks:
            for obs_type, use_videos in SETTINGS:
                runs.append(measure(task, obs_type, args.episodes, use_videos))
                print(json.dumps(runs[-1]))
        result["runs"] = runs
    else:
        trees = {"current": THIS_TREE, args.compare_label: args.compare_root.resolve()}
        result |= compare(trees, args.tasks, args.episodes, args.rounds)
        for r in result["ratios"]:
            print(json.dumps({k: r[k] for k in ("task", "obs_type", "use_videos", "ratio_median")}))
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
