"""How well a trained AE / VAE baseline's learned reward ranks ground truth, on its own run's episodes.

The paper reports that the learned-reward baselines fail from images because the agent exploits the proxy:
it reaches observations the reward scores highly that are far from the goal in ground truth. This measures
that directly for a saved ``--policy.reward=ae|vae`` run, at its checkpoints:

* **on-policy**: the episodes of the last ``last_cycles`` cycles before the checkpoint (the policy's own
  recent rollouts), scored at their final observation against their recorded goal: the learned reward and
  the ground-truth distance, their Spearman rank correlation, and how much each improved from the start
  observation. Exploitation shows as the reward rising while the distance does not fall, or as a weak
  correlation between the two at the states the policy reaches.
* **pairs**: ``pairs`` (observation, goal) pairs drawn over the whole buffer, a third each with the
  episode's recorded goal, another frame of the same episode, and a frame of another episode; per kind, the
  Spearman rank correlation of reward against ground-truth distance and the trainer's own reward statistics
  (``indicator_core.reward_statistics``: the AUC for ground-truth success, distance <= the oracle's epsilon,
  against failure, and the error rates at the reward's positive threshold).

Ground truth is read here only, never by training.
"""

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from scipy.stats import spearmanr

from benchmarks.probes.filter_diagnostics import step_checkpoints
from benchmarks.records import command_line, write_json
from lerobot_indicator.keys import goal_key
from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy
from lerobot_indicator.training.run_state import CHUNK_GT_ACHIEVED, CHUNK_GT_DESIRED, RunDir

# What of ``indicator_core.reward_statistics`` applies to a reward without a filter.
RANKING_STATS = ("reward_auc", "reward_accuracy", "false_negative_rate", "false_positive_rate")


@dataclass
class LearnedRewardProbeConfig:
    run_dirs: list[Path] = field(default_factory=list)
    last_cycles: int = 25
    pairs: int = 3000
    batch_size: int = 100
    seed: int = 0
    out: Path | None = None


def load_episodes(run_dir: Path, keys: list[str], n_cycles: int) -> dict[str, np.ndarray]:
    """Observations (E, T+1, ...), their goal images (E, 1, ...) and ground truth of the replay buffer at the
    end of cycle ``n_cycles``: the run's replay chunks of the cycles before it that are still kept (a full
    buffer has evicted the oldest)."""
    state = RunDir(run_dir)
    files = state.read_progress().replay_files
    kept = [(name, i) for name, i in files if cycle_of(name) < n_cycles]
    if not kept or cycle_of(kept[-1][0]) != n_cycles - 1:
        held = f"cycles {cycle_of(files[0][0])}..{cycle_of(files[-1][0])}" if files else "no cycles"
        raise ValueError(
            f"{run_dir}: replay/ holds {held}, not cycle {n_cycles - 1}, the last before the checkpoint"
        )
    parts: dict[str, list[np.ndarray]] = {}
    for chunk in state.replay_chunks(kept):
        if CHUNK_GT_ACHIEVED not in chunk:
            raise ValueError(f"{run_dir}: the replay chunks hold no ground truth to compare the reward with")
        for name in [*(f"obs/{k}" for k in keys), CHUNK_GT_ACHIEVED, CHUNK_GT_DESIRED]:
            parts.setdefault(name, []).append(chunk[name])
        for k in keys:  # the goal images are the same at every frame of an episode
            parts.setdefault(f"obs/{goal_key(k)}", []).append(chunk[f"obs/{goal_key(k)}"][:, :1])
    return {name: np.concatenate(arrays) for name, arrays in parts.items()}


def cycle_of(replay_file: str) -> int:
    """The cycle that wrote a ``replay/cycle_<cycle>.npz`` chunk."""
    return int(Path(replay_file).stem.removeprefix("cycle_"))


@torch.no_grad()
def score(
    policy: IndicatorDDPGPolicy, obs: dict[str, np.ndarray], goal: dict[str, np.ndarray], bs: int
) -> np.ndarray:
    """The learned reward r(obs, goal), row by row, both dicts keyed by the compared observation keys."""
    out = []
    n = len(next(iter(obs.values())))
    for i in range(0, n, bs):
        frames = {k: torch.from_numpy(np.ascontiguousarray(v[i : i + bs])) for k, v in obs.items()}
        goals = {k: torch.from_numpy(np.ascontiguousarray(v[i : i + bs])) for k, v in goal.items()}
        out.append(policy.reward_model.reward(frames, goals).float().numpy())
    return np.concatenate(out)


def distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.linalg.norm((a - b).reshape(len(a), -1), axis=1)


def probe(policy: IndicatorDDPGPolicy, episodes: dict[str, np.ndarray], cfg: LearnedRewardProbeConfig,
          episodes_per_cycle: int) -> dict:  # fmt: skip
    keys, eps = policy.config.observation_keys, policy.config.oracle_epsilon
    obs = {k: episodes[f"obs/{k}"] for k in keys}
    recorded = {k: episodes[f"obs/{goal_key(k)}"][:, 0] for k in keys}
    gt, gt_goal = episodes[CHUNK_GT_ACHIEVED], episodes[CHUNK_GT_DESIRED]
    n_ep, n_frames = gt.shape[:2]

    recent = np.arange(max(n_ep - cfg.last_cycles * episodes_per_cycle, 0), n_ep)
    at = {t: score(policy, {k: v[recent, t] for k, v in obs.items()}, {k: v[recent] for k, v in recorded.items()},
                   cfg.batch_size) for t in (0, n_frames - 1)}  # fmt: skip
    d_start, d_final = distance(gt[recent, 0], gt_goal[recent]), distance(gt[recent, -1], gt_goal[recent])
    on_policy = {
        "episodes": len(recent),
        "reward_start": float(at[0].mean()),
        "reward_final": float(at[n_frames - 1].mean()),
        "distance_start": float(d_start.mean()),
        "distance_final": float(d_final.mean()),
        "success_final": float((d_final <= eps).mean()),
        "spearman_final": float(spearmanr(at[n_frames - 1], -d_final).statistic),
    }

    rng = np.random.default_rng(cfg.seed)
    ep, t = rng.integers(n_ep, size=cfg.pairs), rng.integers(n_frames, size=cfg.pairs)
    kind = np.arange(cfg.pairs) % 3  # 0 recorded goal, 1 same episode, 2 another episode
    goal_ep = np.where(kind == 2, rng.integers(n_ep, size=cfg.pairs), ep)
    goal_t = rng.integers(n_frames, size=cfg.pairs)
    goal = {
        k: np.where((kind == 0)[:, None, None, None], recorded[k][ep], v[goal_ep, goal_t])
        for k, v in obs.items()
    }
    goal_gt = np.where((kind == 0)[:, None], gt_goal[ep], gt[goal_ep, goal_t])
    reward = score(policy, {k: v[ep, t] for k, v in obs.items()}, goal, cfg.batch_size)
    d = distance(gt[ep, t], goal_gt)
    pairs = {"pairs": cfg.pairs, "spearman": float(spearmanr(reward, -d).statistic)}
    for i, name in enumerate(("recorded_goal", "same_episode", "other_episode")):
        m = torch.from_numpy(kind == i)
        stats = core.reward_statistics(
            torch.from_numpy(reward)[m], torch.from_numpy(gt[ep, t])[m], torch.from_numpy(goal_gt)[m],
            torch.ones(int(m.sum()), dtype=torch.bool), torch.ones(int(m.sum()), dtype=torch.bool), policy.config,
        )  # fmt: skip
        pairs[name] = {"spearman": float(spearmanr(reward[kind == i], -d[kind == i]).statistic),
                       "success_share": float((d[kind == i] <= eps).mean()),
                       **{k: v for k, v in core.stats_to_floats(stats).items() if k in RANKING_STATS}}  # fmt: skip
    return {"on_policy": on_policy, "pairs": pairs}


def run(cfg: LearnedRewardProbeConfig) -> dict:
    """Probe every checkpoint of every run; writes ``cfg.out`` (JSON) when given."""
    if not cfg.run_dirs:
        raise ValueError("--run_dirs is empty: give online training output directories of ae / vae runs")
    runs = {}
    for run_dir in cfg.run_dirs:
        per_step = {}
        for step, policy, online in step_checkpoints(run_dir):
            if policy.reward_model is None:
                raise ValueError(
                    f"{run_dir} step {step}: reward={policy.config.reward!r} has no learned reward"
                )
            episodes = load_episodes(
                run_dir, policy.config.observation_keys, step // online["updates_per_cycle"]
            )
            per_step[step] = probe(policy, episodes, cfg, online["episodes_per_cycle"])
            p, o = per_step[step]["pairs"], per_step[step]["on_policy"]
            print(f"{run_dir} step {step}: pairs spearman {p['spearman']:.3f}, recorded-goal auc "
                  f"{p['recorded_goal']['reward_auc']:.3f}, "
                  f"on-policy spearman {o['spearman_final']:.3f}, reward {o['reward_start']:.3f} -> "
                  f"{o['reward_final']:.3f}, distance {o['distance_start']:.3f} -> {o['distance_final']:.3f}")  # fmt: skip
        runs[str(run_dir)] = {"reward": policy.config.reward, "steps": per_step}
    record = {"command": command_line(), "last_cycles": cfg.last_cycles, "pairs": cfg.pairs,
              "seed": cfg.seed, "runs": runs}  # fmt: skip
    write_json(cfg.out, record)
    return record
