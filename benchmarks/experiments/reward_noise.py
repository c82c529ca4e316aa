"""The paper's section-4 study (Fig. 2): which hurts learning more, false positive or false negative rewards?

DDPG + goal relabeling (the Oracle arm, ``--policy.preset=paper``) on state Sawyer reach, its ground-truth
reward flipped at random (``--policy.reward_false_negative_rate`` / ``reward_false_positive_rate``) over the
grid of ``presets.REWARD_NOISE``, 3 seeds each. The runs go through the comparison's runner
(``benchmarks.experiments.run``), ``jobs`` runner processes at a time, each resumable: rerunning the command
resumes the sweep. Then the runner's summary and table, and ``reward_noise.png``: success rate against env
steps, one curve per rate, false negatives and false positives side by side as in the paper's figure.

    python -m benchmarks.experiments.reward_noise --out=docs/results/reward_noise \\
        --runs_dir=outputs/reward_noise/runs --jobs=2
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import draccus
import matplotlib
import numpy as np

from benchmarks.experiments.presets import LABELS, REWARD_NOISE, STYLES
from lerobot_indicator.stop_signals import exit_code, raise_interrupted

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

TASK = "reach_state"


@dataclass
class RewardNoiseConfig:
    # Summary, table and figure (commit them); run directories go to runs_dir.
    out: Path = Path("outputs/reward_noise")
    runs_dir: Path = Path("outputs/reward_noise/runs")
    seeds: list[int] = field(default_factory=lambda: [0, 1, 2])
    # Updates per run (None: the reach_state preset's 1600 = 4000 env steps).
    steps: int | None = None
    # Runner processes at a time (each runs one torch thread's worth of training at a time).
    jobs: int = 2
    # Only redraw reward_noise.png from <out>/summary.json.
    plot_only: bool = False


def noise_methods() -> dict[str, list[str]]:
    """Per panel ("fn", "fp"), the arms from no noise (the plain Oracle) to the largest rate."""
    return {
        kind: ["oracle", *(f"oracle_{kind}{rate:g}" for rate in rates)]
        for kind, rates in REWARD_NOISE.items()
    }


def runner_command(
    cfg: RewardNoiseConfig, methods: list[str], seeds: list[int], plot_only: bool = False
) -> list[str]:
    cmd = [
        sys.executable,
        "-m",
        "benchmarks.experiments.run",
        f"--tasks=[{TASK}]",
        f"--methods=[{','.join(methods)}]",
        f"--seeds=[{','.join(map(str, seeds))}]",
        f"--out={cfg.out}",
        f"--runs_dir={cfg.runs_dir}",
    ]
    if cfg.steps is not None:
        cmd.append(f"--steps={cfg.steps}")
    if plot_only:
        cmd.append("--plot_only=true")
    return cmd


def sweep_groups(cfg: RewardNoiseConfig) -> list[list[str]]:
    """The sweep as ``jobs``-balanced runner commands: per seed, the arms split in halves."""
    arms = list(dict.fromkeys(m for ms in noise_methods().values() for m in ms))
    half = (len(arms) + 1) // 2
    return [runner_command(cfg, part, [seed]) for seed in cfg.seeds for part in (arms[:half], arms[half:])]


def run_sweep(cfg: RewardNoiseConfig) -> None:
    """At most ``jobs`` runner processes at once; a signal is passed on to each and stops the sweep (rerun to
    resume); a failed runner stops it with its exit code."""
    pending, running = sweep_groups(cfg), []
    handler = signal.signal(signal.SIGTERM, raise_interrupted)
    try:
        while pending or running:
            while pending and len(running) < cfg.jobs:
                running.append(subprocess.Popen(pending.pop(0), start_new_session=True))
            done = [p for p in running if p.poll() is not None]
            for p in done:
                running.remove(p)
                if p.returncode != 0:
                    raise SystemExit(f"stopped: {' '.join(p.args)} exited with {p.returncode}")
            if not done:
                time.sleep(2)
    except KeyboardInterrupt as exc:
        print("interrupted: rerun the same command to resume the sweep", file=sys.stderr)
        raise SystemExit(exit_code(exc)) from None
    finally:
        for p in running:
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
                p.wait()
        signal.signal(signal.SIGTERM, handler)


def plot(summary: dict, path: Path) -> plt.Figure:
    """Success rate against env steps, mean over seeds with a +-1 std band: false negatives left, false
    positives right, the noise-free Oracle in both."""
    methods = summary["tasks"][TASK]
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8), sharey=True)
    for ax, (kind, arms) in zip(axes, noise_methods().items(), strict=True):
        for arm in arms:
            if arm not in methods:
                continue
            m = methods[arm]
            x = np.asarray(m["env_steps"])
            mean = np.asarray(m["series"]["eval_success_rate"]["mean"], dtype=float)
            std = np.asarray(m["series"]["eval_success_rate"]["std"], dtype=float)
            colour, dash = ("black", "-") if arm == "oracle" else STYLES[arm]
            label = f"p_{kind.upper()} = 0" if arm == "oracle" else LABELS[arm].split(", ")[1]
            ax.plot(x, mean, color=colour, linestyle=dash, label=label)
            ax.fill_between(x, mean - std, mean + std, color=colour, alpha=0.12, linewidth=0)
        ax.set_title(f"false {'negative' if kind == 'fn' else 'positive'} rewards")
        ax.set_xlabel("environment steps")
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="lower right")
    axes[0].set_ylabel("success rate (state reach)")
    fig.suptitle(
        "DDPG + relabeling with a flipped ground-truth reward (paper section 4, Fig. 2)", fontsize=10
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return fig


def main() -> None:
    cfg = draccus.parse(RewardNoiseConfig)
    cfg.out.mkdir(parents=True, exist_ok=True)
    if not cfg.plot_only:
        run_sweep(cfg)
        arms = list(dict.fromkeys(m for ms in noise_methods().values() for m in ms))
        subprocess.run(runner_command(cfg, arms, cfg.seeds, plot_only=True), check=True)
    summary = json.loads((cfg.out / "summary.json").read_text())
    plot(summary, cfg.out / "reward_noise.png")
    print(f"wrote {cfg.out / 'reward_noise.png'}")


if __name__ == "__main__":
    main()
