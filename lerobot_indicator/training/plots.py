"""Learning-curve figures from a run's ``metrics.jsonl`` (one JSON object per cycle)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from matplotlib.figure import Figure

# (y label, series, whether the series are rates in [0, 1] and get a fixed [0, 1] axis)
PANELS = (
    ("success rate", ("eval_success_rate", "train_success_rate"), True),
    ("final distance to goal (ground truth)", ("eval_final_distance", "train_final_distance"), False),
    ("indicator reward vs ground truth", ("reward_accuracy", "false_negative_rate"), True),
    ("mean Q(o, g, a)", ("q_mean", "q_target_mean"), False),
    ("fraction of sampled transitions", ("frac_positive", "frac_filtered"), True),
)
# The second series of a panel is dashed and drawn thinner on top, so a first series it covers stays visible.
STYLES = ({"lw": 2.2, "ls": "-"}, {"lw": 1.2, "ls": "--"})


def pyplot():
    """matplotlib.pyplot on the Agg backend, imported on first use: it adds ~0.6 s to every CLI's start."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def read_metrics(path: Path) -> list[dict]:
    """The rows of ``metrics.jsonl`` (a last line cut short is skipped), ``null`` values as NaN."""
    from lerobot_indicator.training.run_state import read_metrics_rows

    return [{k: math.nan if v is None else v for k, v in row.items()} for row in read_metrics_rows(path)]


def learning_curve_figure(rows: list[dict], title: str | None = None) -> Figure:
    """Panels vs environment steps (vs optimisation steps for a run that collects none, e.g. offline);
    series absent from the log (e.g. no ground truth) are skipped."""
    offline = len({r["env_steps"] for r in rows}) <= 1
    x_key, x_label = ("step", "optimisation steps") if offline else ("env_steps", "environment steps")
    fig, axes = pyplot().subplots(1, len(PANELS), figsize=(5 * len(PANELS), 3.8))
    for ax, (ylabel, keys, rate) in zip(axes, PANELS, strict=True):
        for key, style in zip(keys, STYLES, strict=True):
            pts = [(r[x_key], r[key]) for r in rows if key in r]
            if pts:
                xs, ys = zip(*pts, strict=True)
                ax.plot(xs, ys, marker="o" if key.startswith("eval") else None, ms=3, label=key, **style)
        if rate:
            ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel(x_label)
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
        if ax.lines:
            ax.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_learning_curve(metrics_path: Path, png_path: Path, title: str | None = None) -> Path:
    fig = learning_curve_figure(read_metrics(metrics_path), title)
    fig.savefig(png_path, dpi=110)
    pyplot().close(fig)
    return Path(png_path)
