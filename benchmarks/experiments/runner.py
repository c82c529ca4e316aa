"""The paper's comparison (Figure 3 / supplementary ablations) on our tasks: ``python -m benchmarks.experiments.run``'s runner.

Runs ``lerobot-indicator-train`` for every (task, method, seed), resumably (a finished run is skipped,
an interrupted one continues with ``--resume=true``), then aggregates the runs' ``metrics.jsonl`` into
``<out>/summary.json``, learning-curve plots and a markdown table.

    python -m benchmarks.experiments.run --tasks='[reach_state]' --seeds='[0,1,2]' --out=docs/results/experiments \
        --runs_dir=outputs/experiments/runs
    python -m benchmarks.experiments.run --tasks='[reach_state]' --plot_only=true ...   # aggregate only
"""

import json
import os
import platform
import re
import shlex
import signal
import subprocess
import sys
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import draccus
import matplotlib
import numpy as np

from benchmarks.experiments.presets import LABELS, METHODS, PAPER_METHODS, STYLES, TASKS
from lerobot_indicator.stop_signals import Interrupted, exit_code, raise_interrupted, stopping_signal
from lerobot_indicator.training import atomic_dir
from lerobot_indicator.training.plots import read_metrics
from lerobot_indicator.training.run_state import RESUME_DIR

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from benchmarks.records import command_line

BIN = Path(sys.executable).parent

# Panels that only mean something for some methods (default: every method with the series).
PANEL_METHODS = {
    "reward_accuracy": [m for m in METHODS if m != "oracle"],
    "false_negative_rate_kept": [m for m in METHODS if m != "oracle"],
    "filtered_gt_success_rate": [m for m, args in METHODS.items() if "--policy.filter=true" in args],
}


@dataclass
class ExperimentConfig:
    tasks: list[str] = field(default_factory=lambda: ["reach_state"])
    methods: list[str] = field(default_factory=lambda: list(PAPER_METHODS))
    seeds: list[int] = field(default_factory=lambda: [0, 1, 2])
    # Summary, plot and table (small; commit them). Run directories (checkpoints, replay) go to runs_dir.
    out: Path = Path("outputs/experiments")
    runs_dir: Path = Path("outputs/experiments/runs")
    # Overrides of the task presets' budget (None = preset).
    steps: int | None = None
    device: str = "cpu"
    n_envs: int = 2
    plot_only: bool = False
    # Extra table rows at these env-step budgets (methods run to different budgets compare at a shared one).
    table_env_steps: list[int] = field(default_factory=list)
    extra_args: list[str] = field(default_factory=list)
    # Committed summary.json files whose seeds (of --methods and --seeds, for --tasks) join the summary, plot
    # and table where runs_dir has no run of that seed: runs made elsewhere, whose run directories are not here.
    include_summaries: list[Path] = field(default_factory=list)
    # Redraw the figures from <out>/summary.json alone (no runs read, summary and table kept): comparison.png
    # with plot_methods (the paper's arms of that figure), ablations.png with ablation_methods when given.
    replot: bool = False
    plot_methods: list[str] = field(default_factory=list)
    ablation_methods: list[str] = field(default_factory=list)
    # ceiling.json goal set of the rope reference lines (e.g. cache:10000); None: the cache of the folder's
    # start-distance record, else cache:4000
    rope_goal_set: str | None = None

    def __post_init__(self) -> None:
        for name, known, values in (
            ("tasks", TASKS, self.tasks),
            ("methods", METHODS, self.methods),
            ("plot_methods", METHODS, self.plot_methods),
            ("ablation_methods", METHODS, self.ablation_methods),
        ):
            unknown = [v for v in values if v not in known]
            if unknown:
                raise ValueError(f"--{name}: unknown {unknown}; choose from {list(known)}")


def run_dir(cfg: ExperimentConfig, task: str, method: str, seed: int) -> Path:
    return cfg.runs_dir / task / method / f"seed_{seed}"


def read_rows(path: Path) -> list[dict]:
    """A run's metrics rows (none before it starts), a torn last line skipped, null as NaN."""
    return read_metrics(path) if path.exists() else []


class RunFailedError(RuntimeError):
    """One training run of the sweep exited with an error."""


def launch(cfg: ExperimentConfig, task: str, method: str, seed: int) -> float:
    """Run (or resume) one training run; returns its wall time, 0 if it was already complete."""
    preset, out = TASKS[task], run_dir(cfg, task, method, seed)
    steps = cfg.steps or preset.steps
    rows = read_rows(out / "metrics.jsonl")
    if rows and rows[-1]["step"] >= steps:
        return 0.0
    cmd = [
        str(BIN / "lerobot-indicator-train"),
        *preset.env_args,
        "--policy.type=indicator_ddpg",
        "--policy.push_to_hub=false",
        f"--policy.device={cfg.device}",
        *METHODS[method],
        f"--steps={steps}",
        f"--online.n_envs={cfg.n_envs}",
        f"--online.episodes_per_cycle={preset.episodes_per_cycle}",
        f"--online.updates_per_cycle={preset.updates_per_cycle}",
        f"--online.eval_episodes={preset.eval_episodes}",
        f"--env_eval_freq={preset.env_eval_freq}",
        f"--save_freq={steps}",
        f"--seed={seed}",
        f"--output_dir={out}",
        *cfg.extra_args,
    ]
    if atomic_dir.newest(out / RESUME_DIR) is not None:
        cmd.append("--resume=true")
    print("$ " + shlex.join(cmd), flush=True)
    t0 = time.perf_counter()
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    # Its own session, so a signal reaches the trainer once, forwarded from here: a terminal's Ctrl-C sent to
    # both would interrupt the trainer's own clean stop.
    with subprocess.Popen(cmd, env=env, start_new_session=True) as child:
        try:
            code = child.wait()
        except KeyboardInterrupt as exc:
            child.send_signal(getattr(exc, "signum", signal.SIGINT))
            child.wait()
            raise
    if (signum := stopping_signal(code)) is not None:  # the trainer itself was signalled (e.g. pkill)
        raise Interrupted(signum)
    if code != 0:
        raise RunFailedError(
            f"{task}/{method}/seed_{seed} failed with exit code {code} (its log is above): {out}"
        )
    return time.perf_counter() - t0


SERIES_KEYS = (
    "eval_success_rate",
    "eval_final_distance",
    "reward_accuracy",
    "false_negative_rate",
    "false_negative_rate_kept",
    "frac_filtered",
    "filtered_gt_success_rate",
)


def collect_runs(cfg: ExperimentConfig, task: str) -> dict[str, dict[int, list[dict]]]:
    """method -> seed -> the eval rows of the run in ``runs_dir`` (methods and seeds with none are left out)."""
    runs: dict[str, dict[int, list[dict]]] = {}
    for method in cfg.methods:
        for seed in cfg.seeds:
            rows = read_rows(run_dir(cfg, task, method, seed) / "metrics.jsonl")
            rows = [r for r in rows if "eval_success_rate" in r]
            if rows:
                runs.setdefault(method, {})[seed] = rows
    return runs


def summarize(runs: dict[int, list[dict]]) -> dict:
    """Mean and std over seeds of the eval metrics at each evaluation point the seeds share (``env_steps``),
    and every seed's whole curve (``per_seed``, in the order of ``seeds``, at the first evaluations of
    ``per_seed_env_steps``), so summaries can be merged seed by seed later without losing a longer seed."""
    seeds = sorted(runs)
    rows = [runs[s] for s in seeds]
    n = min(len(r) for r in rows)
    longest = max(rows, key=len)
    all_steps = [row["env_steps"] for row in longest]
    for seed, r in zip(seeds, rows, strict=True):
        if [row["env_steps"] for row in r] != all_steps[: len(r)]:
            raise ValueError(
                f"seed {seed}: evaluations at other env steps than seed {seeds[rows.index(longest)]}'s"
            )
    series, per_seed = {}, {}
    for key in SERIES_KEYS:
        if any(key in row for r in rows for row in r):
            # NaN where a row lacks the key (a metric added after the run started); null in the JSON.
            values = [np.array([_value(row, key) for row in r], dtype=float) for r in rows]
            shared = np.array([v[:n] for v in values])
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns stay NaN
                mean, std = np.nanmean(shared, 0), np.nanstd(shared, 0)
            series[key] = {"mean": _nan_to_none(mean), "std": _nan_to_none(std)}
            per_seed[key] = [_nan_to_none(v) for v in values]
    final_success = [r[n - 1]["eval_success_rate"] for r in rows]
    final_distance = [r[n - 1]["eval_final_distance"] for r in rows]
    wall = np.array([r[n - 1].get("wall_time_s", np.nan) for r in rows], dtype=float)
    return {
        "seeds": seeds,
        "per_seed": per_seed,
        "per_seed_env_steps": all_steps,
        "env_steps": all_steps[:n],
        "series": series,
        "n_seeds": len(rows),
        "final_env_steps": all_steps[n - 1],
        "final_success_rate": {"mean": float(np.mean(final_success)), "std": float(np.std(final_success))},
        "final_distance": {"mean": float(np.mean(final_distance)), "std": float(np.std(final_distance))},
        "wall_time_s_per_run": None if np.isnan(wall).all() else float(np.nanmean(wall)),
    }


def aggregate(cfg: ExperimentConfig, task: str) -> dict:
    """method -> ``summarize`` of its runs in ``runs_dir``."""
    return {method: summarize(runs) for method, runs in collect_runs(cfg, task).items()}


def summary_runs(res: dict, where: str) -> dict[int, list[dict]]:
    """seed -> eval rows, rebuilt from one method's entry of a summary.json (what ``summarize`` keeps of them).

    A one-seed entry written before ``per_seed`` held every metric gives them from its mean series."""
    if "seeds" not in res:
        raise ValueError(f"{where}: no 'seeds' list, so its seeds cannot be told apart from the runs here")
    per_seed = dict(res["per_seed"])
    for key, values in res["series"].items():
        if key not in per_seed:
            if res["n_seeds"] != 1:
                raise ValueError(f"{where}: {res['n_seeds']} seeds but no per-seed values of {key!r}")
            per_seed[key] = [values["mean"]]
    runs = {}
    for i, seed in enumerate(res["seeds"]):
        steps = res.get("per_seed_env_steps", res["env_steps"])[: len(per_seed["eval_success_rate"][i])]
        rows = [{"env_steps": x} for x in steps]
        for key, values in per_seed.items():
            for row, v in zip(rows, values[i], strict=True):
                row[key] = np.nan if v is None else v
        if res["n_seeds"] == 1 and res.get("wall_time_s_per_run") is not None:
            rows[-1]["wall_time_s"] = res["wall_time_s_per_run"]
        runs[seed] = rows
    return runs


def include_summaries(
    runs: dict[str, dict[str, dict[int, list[dict]]]], paths: list[Path], methods: list[str], seeds: list[int]
) -> dict[str, list[str]]:
    """Add to ``runs`` (task -> method -> seed -> eval rows) the seeds of ``methods`` among ``seeds`` that the
    summary.json files at ``paths`` hold and ``runs`` lacks: runs made elsewhere, whose run directories are
    not here. A seed run here is kept. Returns what came from where (``task/method/seed_N``)."""
    added: dict[str, list[str]] = {}
    for path in paths:
        for task, results in json.loads(Path(path).read_text())["tasks"].items():
            if task not in runs:
                continue
            for method, res in results.items():
                if method not in methods:
                    continue
                for seed, rows in summary_runs(res, f"{path}: {task}/{method}").items():
                    if seed in seeds and seed not in runs[task].get(method, {}):
                        runs[task].setdefault(method, {})[seed] = rows
                        added.setdefault(str(path), []).append(f"{task}/{method}/seed_{seed}")
    return added


def _value(row: dict, key: str) -> float:
    """A logged metric, NaN where undefined: missing, or the filter's precision in a cycle that filtered nothing
    (logged as 0)."""
    if key == "filtered_gt_success_rate" and not row.get("frac_filtered"):
        return np.nan
    return row.get(key, np.nan)


def _nan_to_none(values: np.ndarray) -> list[float | None]:
    return [None if np.isnan(v) else float(v) for v in values]


def start_distances(out: Path, tasks: list[str]) -> dict[str, float]:
    """Per task, the eval goals' distance at reset (``benchmarks/experiments/start_distance.py --out=<out>/start_distance_<task>
    .json``), if measured: what a policy that never moves scores, drawn as a reference line."""
    files = {task: out / f"start_distance_{task}.json" for task in tasks}
    return {t: json.loads(f.read_text())["start_distance_mean"] for t, f in files.items() if f.exists()}


def goal_blind_distances(out: Path, tasks: list[str]) -> dict[str, float]:
    """Per task, the best final distance of a policy that ignores the goal (``goal_blind_distance_mean`` of the
    same start-distance records), where measured."""
    files = {task: out / f"start_distance_{task}.json" for task in tasks}
    records = {t: json.loads(f.read_text()) for t, f in files.items() if f.exists()}
    return {t: r["goal_blind_distance_mean"] for t, r in records.items() if "goal_blind_distance_mean" in r}


GOAL_BLIND = "goal-blind: one fixed point for all goals"
ROPE_CEILING = Path(__file__).resolve().parents[2] / "docs/results/rope_ceiling/ceiling.json"
ROPE_GOAL_SET = (
    "cache:4000"  # the start/goal pairs the rope tasks evaluate on unless a run names another cache
)
ROPE_EPSILON = 0.1  # the rope tasks' success threshold (the paper's table)


def rope_goal_set(out: Path, task: str, goal_set: str | None = None) -> tuple[str, int]:
    """The ceiling.json goal set and goal count matching ``task``'s evaluation in ``out``: ``goal_set`` if
    given, else the cache (e.g. ``rope_push_10k.npz`` -> "cache:10000") of its start-distance record, else
    ``ROPE_GOAL_SET``; the goal count of that record, else the task's eval_episodes."""
    record = out / f"start_distance_{task}.json"
    if not record.exists():
        return goal_set or ROPE_GOAL_SET, TASKS[task].eval_episodes
    measured = json.loads(record.read_text())
    size = re.search(r"rope_push_(\d+)k\.npz", measured["command"])
    cache = f"cache:{int(size.group(1)) * 1000}" if size else ROPE_GOAL_SET
    return goal_set or cache, measured["episodes"]


def reference_lines(
    out: Path, tasks: list[str], goal_set: str | None = None
) -> dict[str, dict[str, dict[str, float]]]:
    """Per task and panel, labelled horizontal lines: "no movement" on the final distance (``start_distances``)
    and, for rope tasks, what the task allows on the same evaluation goals (``rope_ceiling.json``: the true
    simulator's CEM plan, a uniformly random policy and not moving), on the success and distance panels."""
    from benchmarks.experiments.rope_ceiling import ceiling_lines

    lines: dict[str, dict[str, dict[str, float]]] = {}
    for task, distance in start_distances(out, tasks).items():
        lines.setdefault(task, {}).setdefault("eval_final_distance", {})["no movement (start distance)"] = (
            distance
        )
    for task, distance in goal_blind_distances(out, tasks).items():
        lines.setdefault(task, {}).setdefault("eval_final_distance", {})[GOAL_BLIND] = distance
    for task in tasks:
        if not task.startswith("rope") or task not in TASKS or not ROPE_CEILING.exists():
            continue
        goals, episodes = rope_goal_set(out, task, goal_set)
        for key, metric in (
            ("eval_final_distance", "final_distance"),
            ("eval_success_rate", f"success_{ROPE_EPSILON}"),
        ):
            ref = ceiling_lines(ROPE_CEILING, goals, episodes, metric)
            panel = lines.setdefault(task, {}).setdefault(key, {})
            panel["ceiling: CEM with the true simulator"] = ref["ceiling"]
            panel["uniformly random actions"] = ref["random"]
            panel.setdefault("no movement (start distance)", ref["not_moving"])
    return lines


REFERENCE_STYLES = {
    "no movement (start distance)": ("grey", ":"),
    "ceiling: CEM with the true simulator": ("black", "--"),
    "uniformly random actions": ("grey", "-."),
    GOAL_BLIND: ("tab:brown", ":"),
}


def plot(
    summary: dict, path: Path, reference: dict[str, dict[str, dict[str, float]]] | None = None
) -> plt.Figure:
    """One row per task: success rate, final distance, and the reward's accuracy / FN rate and the filter's
    precision (both against ground truth). Success rate and precision keep a fixed [0, 1] axis, so a few
    lucky evaluations do not look like learning. ``reference``: task -> panel key -> label -> a horizontal
    line (``reference_lines``). Returns the (saved, closed) figure."""
    panels = (
        ("eval_success_rate", "success rate"),
        ("eval_final_distance", "final distance to goal"),
        ("reward_accuracy", "reward accuracy (vs ground truth)"),
        # Among the transitions trained on (after filtering): the rewards the critic is actually given.
        ("false_negative_rate_kept", "false-negative rate (kept transitions)"),
        # What filtering discards: the share of it that is a ground-truth success (a true false negative).
        ("filtered_gt_success_rate", "filter precision P(success | filtered)"),
    )
    fig, axes = plt.subplots(
        len(summary), len(panels), figsize=(5 * len(panels), 3.8 * len(summary) + 0.7), squeeze=False
    )
    legend: dict[str, object] = {}  # one legend for the figure: label -> handle
    for row, (task, methods) in zip(axes, summary.items(), strict=True):
        for ax, (key, label) in zip(row, panels, strict=True):
            for method, res in methods.items():
                if key not in res["series"] or method not in PANEL_METHODS.get(key, METHODS):
                    continue
                x = np.array(res["env_steps"])
                mean, std = (np.array(res["series"][key][s], dtype=float) for s in ("mean", "std"))
                if np.isnan(mean).all():
                    continue
                color, dash = STYLES[method]
                (line,) = ax.plot(x, mean, dash, color=color, lw=2, label=LABELS[method])
                ax.fill_between(x, mean - std, mean + std, color=color, alpha=0.15)
                legend.setdefault(LABELS[method], line)
            drawn = bool(ax.lines)
            for name, value in (reference or {}).get(task, {}).get(key, {}).items():
                color, dash = REFERENCE_STYLES[name]
                legend.setdefault(name, ax.axhline(value, color=color, ls=dash, lw=1.5))
            if not drawn:
                why = "nothing was filtered" if key == "filtered_gt_success_rate" else "not logged"
                ax.text(0.5, 0.5, f"no data: {why}", ha="center", transform=ax.transAxes)
            if key in ("eval_success_rate", "filtered_gt_success_rate"):
                ax.set_ylim(-0.02, 1.02)
            ax.set_title(f"{task}: {label}")
            ax.set_xlabel("environment steps")
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
    ncol = 4
    fig.legend(legend.values(), legend.keys(), loc="lower center", ncol=ncol, fontsize=9, frameon=False)
    legend_inches = 0.1 + 0.22 * -(-len(legend) // ncol)
    fig.tight_layout(rect=(0, legend_inches / fig.get_figheight(), 1, 1))
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return fig


SOLVED = 0.9  # the success rate the table's speed column waits for (mean curve over seeds)


def table(summary: dict, env_steps: list[int] | None = None, window: int = 5) -> str:
    """Success and final distance (mean ± std over seeds) per method at its last evaluation, then at each of
    ``env_steps`` for the methods that went past it; the last column averages each seed's final distance over
    the ``window`` evaluations ending there (one evaluation of 10-20 goals is noisy), and the first evaluation
    where the mean success over seeds reached ``SOLVED`` (learning speed, what the reach comparison measures),
    then that window's value for each seed (with few seeds, the spread a mean ± std hides)."""
    lines = [
        f"| task | method | seeds | env steps | success rate | final distance | final distance, last {window} evals "
        f"| first env steps with mean success >= {SOLVED} | last {window} evals per seed |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for budget in [None, *(env_steps or [])]:
        for task, methods in summary.items():
            for method, res in methods.items():
                steps = res["env_steps"]
                if budget is not None and (budget not in steps or budget == steps[-1]):
                    continue  # not reached, or already the final row
                i = len(steps) - 1 if budget is None else steps.index(budget)
                seeds = {k: [v[: len(steps)] for v in vs] for k, vs in res["per_seed"].items()}
                success = [v[i] for v in seeds["eval_success_rate"]]
                distance = [v[i] for v in seeds["eval_final_distance"]]
                recent = [np.mean(v[max(0, i - window + 1) : i + 1]) for v in seeds["eval_final_distance"]]
                mean_success = np.mean(seeds["eval_success_rate"], axis=0)[: i + 1]
                solved = [x for x, m in zip(steps, mean_success, strict=False) if m >= SOLVED]
                lines.append(
                    f"| {task} | {LABELS[method]} | {res['n_seeds']} | {steps[i]} | "
                    f"{np.mean(success):.2f} ± {np.std(success):.2f} | {np.mean(distance):.3f} ± {np.std(distance):.3f}"
                    f" | {np.mean(recent):.3f} ± {np.std(recent):.3f} | {solved[0] if solved else '-'} | "
                    + ", ".join(
                        f"s{seed} {r:.3f}" for seed, r in zip(res.get("seeds", []), recent, strict=False)
                    )
                    + " |"
                )
    return "\n".join(lines)


def launch_all(cfg: ExperimentConfig) -> dict[str, float]:
    """Every (task, method, seed) in turn, each task's seed 0 for every method before any seed 1, so a partial
    sweep still compares all methods.
    A signal or a failed run stops the sweep with one line and the shell's exit code; rerunning the same
    command resumes it."""
    wall = {}
    handler = signal.signal(signal.SIGTERM, raise_interrupted)
    try:
        for task in cfg.tasks:
            for seed in cfg.seeds:
                for method in cfg.methods:
                    wall[f"{task}/{method}/{seed}"] = launch(cfg, task, method, seed)
    except KeyboardInterrupt as exc:
        print("interrupted: rerun the same command to resume the sweep", file=sys.stderr)
        raise SystemExit(exit_code(exc)) from None
    except RunFailedError as exc:
        print(f"stopped: {exc}", file=sys.stderr)
        raise SystemExit(1) from None
    finally:
        signal.signal(signal.SIGTERM, handler)
    return wall


def replot(
    out: Path, plot_methods: list[str], ablation_methods: list[str], rope_goal_set: str | None = None
) -> list[Path]:
    """Redraw ``out``'s figures from its summary.json: ``comparison.png`` with ``plot_methods`` (every method
    of the summary when empty) and ``ablations.png`` with ``ablation_methods`` (none when empty)."""
    tasks = json.loads((out / "summary.json").read_text())["tasks"]
    reference = reference_lines(out, list(tasks), rope_goal_set)
    written = []
    for methods, name in ((plot_methods or None, "comparison.png"), (ablation_methods, "ablations.png")):
        if methods is not None and not methods:
            continue
        chosen = {t: {m: ms[m] for m in (methods or ms) if m in ms} for t, ms in tasks.items()}
        chosen = {t: ms for t, ms in chosen.items() if ms}
        if not chosen:
            raise ValueError(f"{out / 'summary.json'} holds none of the methods {methods}")
        plot(chosen, out / name, reference)
        written.append(out / name)
    return written


def main() -> None:
    cfg = draccus.parse(ExperimentConfig)
    if cfg.replot:
        for path in replot(cfg.out, cfg.plot_methods, cfg.ablation_methods, cfg.rope_goal_set):
            print(f"wrote {path}")
        return
    cfg.out.mkdir(parents=True, exist_ok=True)
    wall = {} if cfg.plot_only else launch_all(cfg)
    runs = {task: collect_runs(cfg, task) for task in cfg.tasks}
    included = include_summaries(runs, cfg.include_summaries, cfg.methods, cfg.seeds)
    summary = {
        task: {m: summarize(runs[task][m]) for m in cfg.methods if m in runs[task]} for task in cfg.tasks
    }
    meta = {
        "command": command_line(),
        "machine": f"{platform.node()} {platform.machine()} {os.cpu_count()} CPUs",
        "device": cfg.device,
        "launch_wall_s": wall,
    }
    previous = cfg.out / "summary.json"
    if cfg.plot_only and previous.exists():  # keep the command and wall times of the runs themselves
        old = json.loads(previous.read_text())["meta"]
        meta = {**old, "replotted_with": meta["command"]}
    if included:
        meta["included_from_summaries"] = included
    (cfg.out / "summary.json").write_text(json.dumps({"meta": meta, "tasks": summary}, indent=2))
    plot(summary, cfg.out / "comparison.png", reference_lines(cfg.out, cfg.tasks, cfg.rope_goal_set))
    text = table(summary, cfg.table_env_steps)
    (cfg.out / "table.md").write_text(text + "\n")
    print(text)
