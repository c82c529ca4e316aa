#!/usr/bin/env python
"""Measure recording throughput (frames/s) per task and observation type -> docs/results/record_throughput.json.

    MUJOCO_GL=egl python -m benchmarks.speed.run_record_throughput --episodes=20 [--tasks sawyer_reach rope_push]

With ``--compare_root=<dir>`` (another version of this package, e.g. ``git archive <commit> | tar -x -C <dir>``)
both versions are measured in ``--rounds`` interleaved rounds and the JSON gets frames/s ratios
(this tree / the other) per setting. See ``benchmarks/speed/record_throughput.py``. The datasets go
to temporary directories.
"""

import argparse
import json
import os
import platform
from pathlib import Path

from benchmarks.records import command_line
from benchmarks.speed.record_throughput import NAMED_SETTINGS, THIS_TREE, compare, measure

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
    parser.add_argument(
        "--settings",
        nargs="+",
        choices=list(NAMED_SETTINGS),
        default=list(NAMED_SETTINGS),
        help="what to record",
    )
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    settings = tuple(NAMED_SETTINGS[name] for name in args.settings)
    result = {
        "command": f"MUJOCO_GL={os.environ.get('MUJOCO_GL', '')} {command_line()}",
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPU cores (shared), no GPU rendering",
    }
    if args.compare_root is None:
        runs = []
        for task in args.tasks:
            for obs_type, use_videos in settings:
                runs.append(measure(task, obs_type, args.episodes, use_videos))
                print(json.dumps(runs[-1]))
        result["runs"] = runs
    else:
        trees = {"current": THIS_TREE, args.compare_label: args.compare_root.resolve()}

        def save(partial: dict) -> None:  # after every measurement: an interrupted run keeps what it measured
            args.out.write_text(json.dumps(result | partial | {"complete": False}, indent=2) + "\n")

        result |= compare(trees, args.tasks, args.episodes, args.rounds, settings, on_run=save) | {
            "complete": True
        }
        for r in result["ratios"]:
            print(json.dumps({k: r[k] for k in ("task", "obs_type", "use_videos", "ratio_median")}))
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
