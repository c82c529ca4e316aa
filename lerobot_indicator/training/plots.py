"""Learning-curve figures from a run's ``metrics.jsonl`` (one JSON object per cycle)."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

PANELS = (
    ("success rate", ("eval_success_rate", "train_success_rate")),
    ("final distance to goal (ground truth)", ("eval_final_distance", "train_final_distance")),
    ("indicator reward vs ground truth", ("reward_accuracy", "false_negative_rate")),
    ("mean Q(o, g, a)", ("q_mean", "q_target_mean")),
    ("fraction of sampled transitions", ("frac_positive", "frac_filtered")),
)


def read_metrics(path: Path) -> list[dict]:
    return [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]


def plot_learning_curve(metrics_path: Path, png_path: Path, title: str | None = None) -> Path:
    """Panels vs environment steps; series absent from the log (e.g. no ground truth) are skipped."""
    rows = read_metrics(metrics_path)
    fig, axes = plt.subplots(1, len(PANELS), figsize=(5 * len(PANELS), 3.8))
    for ax, (ylabel, keys) in zip(axes, PANELS, strict=True):
        for key in keys:
            pts = [(r["env_steps"], r[key]) for r in rows if key in r]
            if pts:
                xs, ys = zip(*pts, strict=True)
                ax.plot(xs, ys, marker="o" if key.startswith("eval") else None, ms=3, label=key)
        ax.set_xlabel("environment steps")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
        if ax.lines:
            ax.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)
    plt.close(fig)
    return Path(png_path)
