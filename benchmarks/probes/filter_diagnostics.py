"""What reward filtering would discard, per goal source, for a saved online training run.

Section 5.3 of the paper filters R- transitions whose Q(o_t, o_g, a_t) exceeds q0, on the premise that they
are mostly false negatives (the goal *was* reached, within the evaluation epsilon, but not bit for bit). The
trainer logs the filter's overall precision; this breaks it down by where the goal came from (o_{t+1}, a
future o_{t'}, the recorded goal) and by checkpoint, which is what the training logs cannot show.

For each checkpoint of a run directory it rebuilds the replay buffer as it was at that step (the run's
``replay/`` chunks of the cycles before it), draws batches with the checkpoint's own relabeling settings,
and counts, per source: samples, indicator positives, ground-truth successes, the R- transitions with
Q > q0 (what the filter drops, whether or not the run filtered), and how many of those were ground-truth
successes (the filter's precision). Ground truth is only read here, never by training.
"""

import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from benchmarks.records import command_line, write_json
from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy
from lerobot_indicator.training.batches import to_transition_batch
from lerobot_indicator.training.replay_buffer import EpisodeReplayBuffer
from lerobot_indicator.training.run_state import CHUNK_ACTIONS, RunDir, add_replay_chunk

SOURCES = {core.SOURCE_NEXT: "next", core.SOURCE_FUTURE: "future", core.SOURCE_RECORDED: "recorded"}


@dataclass
class FilterDiagnosticsConfig:
    run_dirs: list[Path] = field(default_factory=list)
    batches: int = 20
    batch_size: int = 256
    seed: int = 0
    out: Path | None = None


def buffer_at(run_dir: Path, step: int, updates_per_cycle: int, horizon: int) -> EpisodeReplayBuffer:
    """The replay buffer after the cycles that precede training step ``step`` (unbounded: these runs never
    evicted; a run that did is refused rather than misrepresented)."""
    state = RunDir(run_dir)
    progress = state.read_progress()
    files = progress.replay_files
    if not files or files[0][1] != progress.seeded_episodes:
        raise ValueError(f"{run_dir}: the replay buffer evicted episodes or was seeded; not supported")
    chunks = list(state.replay_chunks(files[: step // updates_per_cycle]))
    buffer = EpisodeReplayBuffer(sum(len(c[CHUNK_ACTIONS]) for c in chunks) * horizon, horizon)
    for chunk in chunks:
        add_replay_chunk(buffer, chunk)
    return buffer


@torch.no_grad()
def diagnose(policy: IndicatorDDPGPolicy, buffer: EpisodeReplayBuffer, cfg: FilterDiagnosticsConfig) -> dict:
    c = policy.config
    rng, generator = np.random.default_rng(cfg.seed), torch.Generator().manual_seed(cfg.seed)
    counts = {name: dict.fromkeys(("samples", "positive", "gt_success", "dropped", "dropped_gt_success"), 0)
              for name in SOURCES.values()}  # fmt: skip
    q_sums = {name: {"gt_success": [0.0, 0], "gt_failure": [0.0, 0]} for name in SOURCES.values()}
    for _ in range(cfg.batches):
        batch = to_transition_batch(buffer.sample(cfg.batch_size, rng), c.observation_keys, c.horizon, "cpu")
        relabel = core.relabel_sources(batch[core.HAS_FUTURE].bool(), c, batch[core.FUTURE_COUNT], generator)
        goal = core.select_goals(batch, c.observation_keys, relabel.source)
        next_obs = {k: batch[core.NEXT + k] for k in c.observation_keys}
        reward = core.indicator_reward(next_obs, goal, c.positive_reward, c.negative_reward)
        gt_goal = core.ground_truth_goal(batch, relabel.source)
        success = core.ground_truth_success(batch[core.GT_NEXT_ACHIEVED], gt_goal, c.oracle_epsilon)
        obs = {k: batch[k] for k in c.observation_keys}
        q = policy.critic(obs, goal, batch[core.ACTION])
        dropped = ~core.filter_keep(reward, q, c.q0, c.negative_reward)
        for source, name in SOURCES.items():
            m = relabel.source == source
            n = counts[name]
            n["samples"] += int(m.sum())
            n["positive"] += int((m & (reward == c.positive_reward)).sum())
            n["gt_success"] += int((m & success).sum())
            n["dropped"] += int((m & dropped).sum())
            n["dropped_gt_success"] += int((m & dropped & success).sum())
            negative = m & (reward == c.negative_reward)
            for label, sel in (("gt_success", negative & success), ("gt_failure", negative & ~success)):
                q_sums[name][label][0] += float(q[sel].sum())
                q_sums[name][label][1] += int(sel.sum())
    total = {k: sum(n[k] for n in counts.values()) for k in next(iter(counts.values()))}
    out = {}
    for name, n in [*counts.items(), ("all", total)]:
        out[name] = {
            **n,
            "share": n["samples"] / max(total["samples"], 1),
            "frac_dropped": n["dropped"] / max(n["samples"], 1),
            "filter_precision": n["dropped_gt_success"] / n["dropped"] if n["dropped"] else None,
        }
        if name in q_sums:  # mean Q of the R- transitions, split by ground truth: what q0 must separate
            out[name] |= {
                f"q_mean_negative_{label}": (s / k if k else None) for label, (s, k) in q_sums[name].items()
            }
    return out


def step_checkpoints(run_dir: Path) -> Iterator[tuple[int, IndicatorDDPGPolicy, dict]]:
    """(step, policy on the CPU in eval mode, the run's ``online`` settings) of each step checkpoint of an
    online run directory, oldest first."""
    checkpoints = sorted(p for p in (run_dir / "checkpoints").glob("[0-9]*") if p.is_dir())
    if not checkpoints:
        raise FileNotFoundError(f"{run_dir}/checkpoints has no step checkpoints")
    for ckpt in checkpoints:
        model = ckpt / "pretrained_model"
        online = json.loads((model / "train_config.json").read_text())["online"]
        yield int(ckpt.name), IndicatorDDPGPolicy.from_pretrained(model).to("cpu").eval(), online


def run(cfg: FilterDiagnosticsConfig) -> dict:
    """Diagnose every checkpoint of every run; writes ``cfg.out`` (JSON) when given."""
    if not cfg.run_dirs:
        raise ValueError("--run_dirs is empty: give online training output directories")
    runs = {}
    for run_dir in cfg.run_dirs:
        per_step = {}
        for step, policy, online in step_checkpoints(run_dir):
            c = policy.config
            buffer = buffer_at(run_dir, step, online["updates_per_cycle"], c.horizon)
            per_step[step] = diagnose(policy, buffer, cfg)
            a = per_step[step]["all"]
            print(
                f"{run_dir} step {step}: dropped {a['frac_dropped']:.3f}, precision {a['filter_precision']}"
            )
        runs[str(run_dir)] = {"balance": c.balance, "filter": c.filter, "q0": c.q0, "steps": per_step}
    record = {"command": command_line(), "batches": cfg.batches, "batch_size": cfg.batch_size,
              "runs": runs}  # fmt: skip
    write_json(cfg.out, record)
    return record
