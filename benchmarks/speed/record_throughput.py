"""Recording throughput (frames/s of ``record()``) per task and observation type, optionally against another
version of this package in interleaved rounds.

``measure`` times ``record()`` end to end (env construction, stepping, rendering, LeRobotDataset writing
and committing) and, separately, the env set-up alone (construction + first reset after a warm-up build),
so ``loop_frames_per_s`` excludes that per-recording constant. It uses only ``RecordConfig``,
``make_single_env`` and ``record``, which every version of the recorder has, so ``measure_in`` can run it
in a subprocess against any source tree of this package (``git archive <commit> | tar -x -C <dir>``):
this file is executed by path with ``PYTHONPATH=<tree>``. ``compare`` alternates the trees setting by
setting and swaps who goes first each round, so load from other jobs hits both versions alike; the
per-round ratios are the reliable numbers on a shared machine.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from lerobot.envs.configs import EnvConfig

import lerobot_indicator.envs  # noqa: F401  (registers the tasks)
from lerobot_indicator.data.recorder import RecordConfig, make_single_env, record

POLICY = {"sawyer_reach": "noisy_scripted", "rope_push": "noisy_scripted"}
# (obs_type, use_videos) per task: state, lossless RGB-D frames, RGB-D video.
NAMED_SETTINGS = {"state": ("state", False), "rgbd": ("rgbd", False), "rgbd_video": ("rgbd", True)}
SETTINGS = tuple(NAMED_SETTINGS.values())
THIS_TREE = Path(__file__).resolve().parents[2]


def measure(task: str, obs_type: str, episodes: int, use_videos: bool) -> dict:
    env = EnvConfig.get_choice_class(task)(obs_type=obs_type)
    load_before = os.getloadavg()[0]
    make_single_env(env).close()  # warm-up: imports and caches are one-off costs, not per-recording ones
    start = time.perf_counter()
    vec_env = make_single_env(env)
    vec_env.reset(seed=0)
    setup_s = time.perf_counter() - start
    vec_env.close()
    with tempfile.TemporaryDirectory() as tmp:
        cfg = RecordConfig(
            env=env,
            repo_id=f"bench/{task}_{obs_type}",
            root=Path(tmp) / "ds",
            policy=POLICY[task],
            num_episodes=episodes,
            use_videos=use_videos,
        )
        start = time.perf_counter()
        dataset = record(cfg)
        seconds = time.perf_counter() - start
        frames = dataset.meta.total_frames
        size_mb = sum(p.stat().st_size for p in cfg.root.rglob("*") if p.is_file()) / 2**20
    return {
        "task": task,
        "obs_type": obs_type,
        "use_videos": use_videos,
        "policy": POLICY[task],
        "episodes": episodes,
        "frames": frames,
        "seconds": round(seconds, 2),
        "frames_per_s": round(frames / seconds, 1),
        "env_setup_seconds": round(setup_s, 2),
        "loop_frames_per_s": round(frames / (seconds - setup_s), 1),
        "dataset_mb": round(size_mb, 2),
        "load_average_1min_before": round(load_before, 2),
    }


def measure_in(tree: Path, task: str, obs_type: str, episodes: int, use_videos: bool) -> dict:
    """``measure`` with the recorder of the package in source tree ``tree``, in a fresh process."""
    if not (tree / "lerobot_indicator" / "data" / "recorder.py").is_file():
        raise FileNotFoundError(
            f"{tree} holds no lerobot_indicator/data/recorder.py: not a source tree of it"
        )
    args = {"task": task, "obs_type": obs_type, "episodes": episodes, "use_videos": use_videos}
    env = {**os.environ, "PYTHONPATH": f"{tree}{os.pathsep}{THIS_TREE}"}
    done = subprocess.run(
        [sys.executable, "-m", __name__, json.dumps(args)],
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["(no output)"])[-1]
        raise RuntimeError(f"measuring {args} in {tree} failed (exit code {done.returncode}): {last}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def compare(
    trees: dict[str, Path],
    tasks: list[str],
    episodes: int,
    rounds: int,
    settings: tuple[tuple[str, bool], ...] = SETTINGS,
    on_run: Callable[[dict], None] | None = None,
) -> dict:
    """Every setting of every task measured once per tree per round, the trees alternating setting by
    setting; ``ratios`` holds frames/s of the first tree over each other tree, per round and their median.
    ``on_run`` gets the result so far (``ratios`` over the complete rounds) after every measurement."""
    labels = list(trees)
    runs = []
    for r in range(rounds):
        order = labels if r % 2 == 0 else labels[::-1]
        for task in tasks:
            for obs_type, use_videos in settings:
                for label in order:
                    run = measure_in(trees[label], task, obs_type, episodes, use_videos)
                    runs.append({"version": label, "round": r, **run})
                    print(json.dumps(runs[-1]), flush=True)
                    if on_run is not None:
                        on_run({"runs": runs, "ratios": ratios_of(runs, labels, tasks, settings)})
    return {"runs": runs, "ratios": ratios_of(runs, labels, tasks, settings)}


def ratios_of(
    runs: list[dict], labels: list[str], tasks: list[str], settings: tuple[tuple[str, bool], ...]
) -> list[dict]:
    """frames/s of ``labels[0]`` over each other version, per setting, over the rounds both completed."""
    ratios = []
    first, others = labels[0], labels[1:]
    for task in tasks:
        for obs_type, use_videos in settings:

            def fps(label: str, task=task, obs_type=obs_type, use_videos=use_videos) -> list[float]:
                return [
                    x["frames_per_s"]
                    for x in runs
                    if (x["version"], x["task"], x["obs_type"], x["use_videos"])
                    == (label, task, obs_type, use_videos)
                ]

            for other in others:
                per_round = [a / b for a, b in zip(fps(first), fps(other), strict=False)]
                if not per_round:
                    continue
                ratios.append(
                    {
                        "task": task,
                        "obs_type": obs_type,
                        "use_videos": use_videos,
                        "versions": f"{first} / {other}",
                        f"frames_per_s_{first}": fps(first),
                        f"frames_per_s_{other}": fps(other),
                        "ratio_per_round": [round(x, 3) for x in per_round],
                        "ratio_median": round(statistics.median(per_round), 3),
                    }
                )
    return ratios


if __name__ == "__main__":
    print(json.dumps(measure(**json.loads(sys.argv[1]))))
