"""Loss curves of ``lerobot-train --policy.type=indicator_ddpg`` in 1 process vs N processes (DDP through
``accelerate launch``) at the same global batch size, on CPU (gloo), from the runs' own log lines."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

BIN = Path(sys.executable).parent
LOG_LINE = re.compile(
    r"step:(\d+)\s.*?\sloss:([-\d.e+]+)\s.*?critic_loss:([-\d.e+]+)\s+actor_loss:([-\d.e+]+)"
)


def train_command(processes: int, train_args: list[str]) -> list[str]:
    train = [str(BIN / "lerobot-train"), *train_args]
    if processes == 1:
        return train
    # `accelerate launch --cpu` alone runs one process; --multi_gpu launches N through torchrun, and
    # lerobot-train's Accelerator(cpu=True) (policy on CPU) makes it DDP over gloo.
    launch = [
        str(BIN / "accelerate"),
        "launch",
        "--multi_gpu",
        f"--num_processes={processes}",
        "--num_machines=1",
    ]
    return [*launch, "--mixed_precision=no", "--dynamo_backend=no", *train]


def parse_losses(log: str) -> dict[str, list[float]]:
    """``step`` and the logged losses of every lerobot-train log line (the main process's)."""
    rows = sorted({int(m[1]): m for m in LOG_LINE.finditer(log)}.items())
    return {
        "step": [s for s, _ in rows],
        "loss": [float(m[2]) for _, m in rows],
        "critic_loss": [float(m[3]) for _, m in rows],
        "actor_loss": [float(m[4]) for _, m in rows],
    }


def window_means(values: list[float], window: int) -> list[float]:
    v = np.asarray(values, dtype=np.float64)
    n = len(v) // window
    return v[: n * window].reshape(n, window).mean(axis=1).tolist()


def run(processes: int, train_args: list[str], out: Path) -> dict:
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "CUDA_VISIBLE_DEVICES": "", "OMP_NUM_THREADS": "1"}
    t0 = time.perf_counter()
    proc = subprocess.run(
        [*train_command(processes, [*train_args, f"--output_dir={out}"])],
        capture_output=True,
        text=True,
        env=env,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"lerobot-train with {processes} processes failed:\n{proc.stderr[-4000:]}")
    return {"wall_s": time.perf_counter() - t0, **parse_losses(proc.stdout + proc.stderr)}


def compare(
    dataset_root: Path,
    repo_id: str,
    global_batch: int,
    steps: int,
    processes: list[int],
    extra: list[str],
    out: Path,
    window: int,
) -> dict:
    """One run per process count, each with a per-process batch of ``global_batch / processes``."""
    runs = {}
    for n in processes:
        if global_batch % n:
            raise ValueError(f"global batch {global_batch} does not split over {n} processes")
        args = [
            "--policy.type=indicator_ddpg", f"--dataset.repo_id={repo_id}", f"--dataset.root={dataset_root}",
            "--policy.push_to_hub=false", "--policy.device=cpu", f"--batch_size={global_batch // n}",
            "--num_workers=0", "--log_freq=1", f"--steps={steps}", "--save_checkpoint=false",
            "--wandb.enable=false", "--seed=1000", *extra,
        ]  # fmt: skip
        runs[str(n)] = run(n, args, out / f"procs_{n}")
        runs[str(n)]["batch_per_process"] = global_batch // n
    curves = {n: window_means(r["critic_loss"], window) for n, r in runs.items()}
    base = str(processes[0])
    shape = {}
    for n, c in curves.items():
        if n == base:
            continue
        m = min(len(c), len(curves[base]))
        a, b = np.asarray(curves[base][:m]), np.asarray(c[:m])
        shape[n] = {
            "pearson_r_of_window_means": float(np.corrcoef(a, b)[0, 1]),
            "max_relative_difference_of_window_means": float(np.max(np.abs(b - a) / np.abs(a))),
            "first_over_last_window": {base: float(a[0] / a[-1]), n: float(b[0] / b[-1])},
        }
    return {
        "global_batch": global_batch,
        "steps": steps,
        "window": window,
        "critic_loss_window_means": curves,
        f"shape_vs_{base}_process": shape,
        "runs": runs,
    }


def plot(result: dict, png: Path) -> None:
    """Per-step critic loss of each process count (thin) and its window means (thick), one axis."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    window = result["window"]
    for (n, run), color in zip(result["runs"].items(), ("tab:blue", "tab:orange"), strict=False):
        label = f"{n} process{'es' if n != '1' else ''}, batch {run['batch_per_process']} each"
        ax.plot(run["step"], run["critic_loss"], color=color, alpha=0.3, linewidth=0.8)
        means = result["critic_loss_window_means"][n]
        centres = [window * (i + 0.5) for i in range(len(means))]
        ax.plot(centres, means, color=color, linewidth=2, marker="o", label=label)
    ax.set_xlabel("lerobot-train step")
    ax.set_ylabel("critic loss (main process)")
    ax.set_title(f"lerobot-train, global batch {result['global_batch']}: 2 processes vs 1")
    ax.legend()
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)
