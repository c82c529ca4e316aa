"""An offline check of what an ``indicator_ddpg`` policy learned, on recorded episodes: no simulator needed.

Data of a real robot has no simulator to evaluate in, but its held-out episodes still say two things a
goal-conditioned policy should have learned from the method's own signal (goals = later frames of the same
episode). For each held-out episode ``o_0..o_L`` with recorded actions ``a_0..a_{L-1}``:

``q_rank_corr`` (value ordering of goals; in [-1, 1], 1 = perfect)
    For each start ``t`` the critic's values Q(o_t, g = o_{t+k}, a_t) over the offsets ``k`` (``offsets``, those
    with t + k <= L) are rank-correlated (Spearman) with -k: a goal fewer steps away should be worth more,
    since under the indicator reward Q estimates the discounted time to reach the goal. Averaged over the
    starts of an episode, then over episodes (``q_rank_corr_per_episode``). A start whose Q is the same for
    every offset has no ordering: its correlation is undefined and left out of the means
    (``q_rank_undefined_frac`` says how many starts were); an episode with no defined start is NaN and left
    out; all undefined gives NaN. 0 = Q tells near goals from far ones no better than chance. Starts with
    fewer than ``MIN_OFFSETS`` valid offsets are skipped.
``q_by_offset`` (per offset ``k``)
    The mean of Q(o_t, o_{t+k}, a_t) over every start with t + k <= L: the curve whose downward slope the
    correlation summarises.
``action_error`` (the actor toward near goals; lower is better, 0 = the recorded actions exactly)
    mean |pi(o_t, g = o_{t+k}) - a_t| over the action dimensions and every start with t + k <= L, for ``k`` in
    ``near_offsets``: the recorded action is one way to reach o_{t+k} from o_t in k steps. Also per offset
    (``action_error_by_offset``).
``action_error_mean_action``, ``action_error_zero``, ``action_error_random`` (baselines, same pairs)
    the same error for always answering the mean recorded action of the checked episodes (a baseline that
    has seen the answers' mean), the zero action, and a uniformly random action in [-1, 1]
    (its exact expectation, E|u - a| = (1 + a^2) / 2 per dimension for a in [-1, 1]). An actor below
    ``action_error_mean_action`` used the goal to choose its action. With exploratory (random) data the
    recorded action is one of many that reach o_{t+k}, so for k > 1 even a perfect policy need not match it.

The computation takes tensors and callables (:func:`check_episodes`; the critic and the actor as functions of
``(obs, goal, action)`` and ``(obs, goal)``); :func:`check_policy` runs it for a policy, and both trainers use
it: ``lerobot-indicator-train --dataset.*`` logs it with every evaluation (``offline_*`` in
``metrics.jsonl``), and ``lerobot-indicator-offline-check --policy.path=... --dataset.repo_id=...
--dataset.root=... --episodes=[...]`` checks any checkpoint (a ``lerobot-train`` one too) and writes
``offline_check.json`` and ``offline_check.png``.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from lerobot.configs.default import DatasetConfig
from torch import Tensor

# Offsets k of the value ordering, and the near goals of the action error (the check's defaults).
OFFSETS = (1, 2, 3, 4, 6, 8, 12, 16, 24, 32)
NEAR_OFFSETS = (1, 2, 3)
# A rank correlation over fewer points says little: starts with fewer valid offsets are skipped.
MIN_OFFSETS = 3
RESULT_FILE, FIGURE_FILE = "offline_check.json", "offline_check.png"

Episode = dict[str, Tensor]  # key -> (L + 1, ...) frames o_0..o_L; "action" -> (>= L, A), a_t for t < L
CriticFn = Callable[[dict[str, Tensor], dict[str, Tensor], Tensor], Tensor]  # (obs, goal, action) -> (B,)
ActorFn = Callable[[dict[str, Tensor], dict[str, Tensor]], Tensor]  # (obs, goal) -> (B, A)


def spearman(x: Tensor, y: Tensor) -> float:
    """Spearman's rank correlation of two 1-d tensors (scipy's, ties at their average rank); NaN when either
    is constant (no ordering to compare)."""
    if x.numel() != y.numel():
        raise ValueError(f"spearman: {x.numel()} values against {y.numel()}")
    if bool((x == x.flatten()[0]).all()) or bool((y == y.flatten()[0]).all()):
        return math.nan
    from scipy.stats import spearmanr  # here, not at module level: scipy.stats adds ~1 s to every CLI's start

    return float(spearmanr(x.double().flatten().numpy(), y.double().flatten().numpy()).statistic)


def nanmean(values: Sequence[float]) -> float:
    finite = [v for v in values if not math.isnan(v)]
    return float(np.mean(finite)) if finite else math.nan


def value_ranking(q: Tensor, offsets: Sequence[int]) -> tuple[float, int, int]:
    """One episode's value ordering from ``q`` (S, K): Q(o_t, o_{t+k_j}, a_t) for S starts and the K
    ``offsets``, NaN where t + k_j is past the episode. Returns (mean Spearman correlation of each start's Q
    with -k over its valid offsets, NaN if no start has one; starts with an undefined correlation; starts used).
    """
    minus_k = -torch.as_tensor(list(offsets), dtype=torch.float64)
    correlations, undefined = [], 0
    for row in q.double():
        valid = ~torch.isnan(row)
        if int(valid.sum()) < MIN_OFFSETS:
            continue
        c = spearman(row[valid], minus_k[valid])
        undefined += math.isnan(c)
        correlations.append(c)
    return nanmean(correlations), undefined, len(correlations)


def action_errors(predicted: Tensor, recorded: Tensor, mean_action: Tensor) -> dict[str, float]:
    """mean |predicted - recorded| and the baselines' (module docstring) on (N, A) actions in [-1, 1]."""
    recorded = recorded.double()
    return {
        "action_error": float((predicted.double() - recorded).abs().mean()),
        "action_error_mean_action": float((mean_action.double() - recorded).abs().mean()),
        "action_error_zero": float(recorded.abs().mean()),
        "action_error_random": float(((1 + recorded.clamp(-1, 1) ** 2) / 2).mean()),
    }


def _pair(
    episode: Episode, obs_keys: Sequence[str], keys: Sequence[str], t: Tensor, k: int
) -> tuple[dict, dict]:
    """(o_t, g = o_{t+k}) for the starts ``t``: the observation's inputs and the compared keys' goal frames."""
    return {key: episode[key][t] for key in obs_keys}, {key: episode[key][t + k] for key in keys}


def _chunks(t: Tensor, batch_size: int) -> list[Tensor]:
    return [t[i : i + batch_size] for i in range(0, len(t), batch_size)]


def check_episodes(
    episodes: Sequence[Episode],
    keys: Sequence[str],
    critic: CriticFn,
    actor: ActorFn,
    context_keys: Sequence[str] = (),
    offsets: Sequence[int] = OFFSETS,
    near_offsets: Sequence[int] = NEAR_OFFSETS,
    batch_size: int = 1024,
) -> dict:
    """The check's numbers (module docstring) for ``episodes``; ``keys`` are the compared keys (a goal is
    ``o_{t+k}`` of those), ``context_keys`` other inputs of o_t. ``critic`` / ``actor`` return (B,) / (B, A)."""
    offsets, near_offsets = sorted(set(offsets)), sorted(set(near_offsets))
    if not offsets or min(offsets + near_offsets) < 1:
        raise ValueError(f"offsets must be >= 1, got {offsets} and near offsets {near_offsets}")
    obs_keys = list(keys) + [k for k in context_keys if k not in keys]
    per_episode, undefined, starts = [], 0, 0
    q_sums, q_counts = np.zeros(len(offsets)), np.zeros(len(offsets))
    predicted, recorded = {k: [] for k in near_offsets}, {k: [] for k in near_offsets}
    for episode in episodes:
        L = episode[keys[0]].shape[0] - 1  # frames o_0..o_L
        if L < 1:
            continue
        actions = episode["action"][:L]
        # Q of every (start t < L, offset k) pair with t + k <= L; NaN elsewhere.
        q = torch.full((L, len(offsets)), math.nan, dtype=torch.float64)
        for j, k in enumerate(offsets):
            if k > L:
                continue
            t = torch.arange(L - k + 1)  # every start with t + k <= L (so t < L: a_t exists)
            values = torch.cat(
                [critic(*_pair(episode, obs_keys, keys, c, k), actions[c]) for c in _chunks(t, batch_size)]
            )
            values = values.double().cpu()
            q[t, j] = values
            q_sums[j] += float(values.sum())
            q_counts[j] += len(t)
        corr, n_undefined, n_starts = value_ranking(q, offsets)
        per_episode.append(corr)
        undefined, starts = undefined + n_undefined, starts + n_starts
        for k in near_offsets:
            if k > L:
                continue
            t = torch.arange(L - k + 1)
            chosen = [actor(*_pair(episode, obs_keys, keys, c, k)) for c in _chunks(t, batch_size)]
            predicted[k].append(torch.cat(chosen).double().cpu())
            recorded[k].append(actions[t].double().cpu())
    all_recorded = [a for k in near_offsets for a in recorded[k]]
    if not all_recorded:
        raise ValueError("offline check: no episode has two frames")
    mean_action = torch.cat([e["action"][: e[keys[0]].shape[0] - 1] for e in episodes]).double().mean(0)
    errors = action_errors(
        torch.cat([p for k in near_offsets for p in predicted[k]]), torch.cat(all_recorded), mean_action
    )
    by_offset = {
        str(k): action_errors(torch.cat(predicted[k]), torch.cat(recorded[k]), mean_action)
        for k in near_offsets
        if recorded[k]
    }
    return {
        "q_rank_corr": nanmean(per_episode),
        "q_rank_corr_per_episode": per_episode,
        "q_rank_undefined_frac": undefined / starts if starts else math.nan,
        "q_rank_starts": starts,
        "offsets": offsets,
        "q_by_offset": [s / c if c else math.nan for s, c in zip(q_sums, q_counts, strict=True)],
        **errors,
        "near_offsets": near_offsets,
        "action_error_by_offset": by_offset,
        "episodes": len(episodes),
    }


# ---------------- a policy, a dataset, the trainer and the CLI ----------------


def policy_functions(policy) -> tuple[CriticFn, ActorFn]:
    """An ``IndicatorDDPGPolicy``'s critic and actor as the check calls them (inputs moved to its device)."""
    device = next(policy.parameters()).device

    def to(x: dict[str, Tensor]) -> dict[str, Tensor]:
        return {k: v.to(device) for k, v in x.items()}

    def critic(obs, goal, action):
        return policy.critic(to(obs), to(goal), action.to(device).float())

    def actor(obs, goal):
        return policy.actor(to(obs), to(goal))

    return critic, actor


@torch.no_grad()
def check_policy(policy, episodes: Sequence[Episode], **kwargs) -> dict:
    """:func:`check_episodes` for an ``IndicatorDDPGPolicy`` (evaluation mode, restored afterwards)."""
    was_training = policy.training
    policy.eval()
    try:
        critic, actor = policy_functions(policy)
        cfg = policy.config
        return check_episodes(episodes, cfg.observation_keys, critic, actor, cfg.context_keys or (), **kwargs)
    finally:
        policy.train(was_training)


def load_episodes(dataset, keys: Sequence[str]) -> list[Episode]:
    """Every episode of a ``LeRobotDataset`` (as loaded: ``episodes=[...]`` selects them) as ``keys`` +
    ``action`` tensors, frames in the layout the policy trains on."""
    from lerobot_indicator.data.integrity import read_frame

    missing = [k for k in [*keys, "action"] if k not in dataset.features]
    if missing:
        raise KeyError(f"dataset {dataset.repo_id} lacks {missing}; it has {sorted(dataset.features)}")
    episode_index = np.asarray(dataset.hf_dataset.with_format("arrow")["episode_index"])
    episodes = []
    for ep in np.unique(episode_index):
        frames = [read_frame(dataset, int(i)) for i in np.flatnonzero(episode_index == ep)]
        episodes.append({k: torch.stack([f[k] for f in frames]) for k in [*keys, "action"]})
    return episodes


@dataclass
class OfflineCheckConfig:
    """``--offline_check.*`` of ``lerobot-indicator-train`` (with ``--dataset.*``): the offline check, logged
    with every evaluation as ``offline_*`` metrics."""

    # Episodes of --dataset.repo_id to check on. None = the dataset's episodes not in --dataset.episodes
    # (held out), or, when every episode trains, the last `max_episodes` of them (offline_held_out = 0).
    episodes: list[int] | None = None
    max_episodes: int = 20
    offsets: list[int] = field(default_factory=lambda: list(OFFSETS))
    near_offsets: list[int] = field(default_factory=lambda: list(NEAR_OFFSETS))
    enable: bool = True


def trainer_check_episodes(dataset_cfg, cfg: OfflineCheckConfig, keys: Sequence[str]) -> tuple[list, bool]:
    """The episodes ``lerobot-indicator-train`` checks on and whether they are held out (``OfflineCheckConfig``)."""
    from lerobot.datasets import LeRobotDatasetMetadata

    from lerobot_indicator.training.dataset_seed import load_dataset

    meta = LeRobotDatasetMetadata(dataset_cfg.repo_id, root=dataset_cfg.root, revision=dataset_cfg.revision)
    trained = set(range(meta.total_episodes) if dataset_cfg.episodes is None else dataset_cfg.episodes)
    chosen = cfg.episodes
    if chosen is None:
        chosen = [e for e in range(meta.total_episodes) if e not in trained][-cfg.max_episodes :]
        if not chosen:
            chosen = sorted(trained)[-cfg.max_episodes :]
    held_out = not set(chosen) & trained
    check_cfg = type(dataset_cfg)(repo_id=dataset_cfg.repo_id, root=dataset_cfg.root, episodes=list(chosen),
                                  revision=dataset_cfg.revision, video_backend=dataset_cfg.video_backend)  # fmt: skip
    episodes = load_episodes(load_dataset(check_cfg), keys)
    logging.info(
        "offline check on %d %s episodes of %s (offline_* metrics with each evaluation)",
        len(episodes),
        "held-out" if held_out else "training (none held out)",
        dataset_cfg.repo_id,
    )
    return episodes, held_out


def trainer_metrics(result: dict, held_out: bool) -> dict[str, float]:
    """The scalar numbers of a check, as ``metrics.jsonl`` keys (``offline_*``)."""
    names = ("q_rank_corr", "q_rank_undefined_frac", "action_error", "action_error_mean_action",
             "action_error_random")  # fmt: skip
    return {f"offline_{n}": float(result[n]) for n in names} | {"offline_held_out": float(held_out)}


def offline_check_figure(result: dict, path: Path, title: str = "") -> None:
    """Mean Q by goal offset, per-episode correlations, and the action errors against their baselines."""
    from lerobot_indicator.training.plots import pyplot

    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(15, 3.8))
    axes[0].plot(result["offsets"], result["q_by_offset"], "o-")
    axes[0].set(xlabel="goal offset k (steps ahead)", ylabel="mean Q(o_t, o_{t+k}, a_t)", xscale="log")
    axes[0].set_title(f"value ordering: Spearman(Q, -k) = {result['q_rank_corr']:.3f}")
    corr = [c for c in result["q_rank_corr_per_episode"] if not math.isnan(c)]
    axes[1].hist(corr, bins=20, range=(-1, 1))
    axes[1].set(xlabel="per-episode Spearman(Q, -k)", ylabel="episodes", title="per held-out episode")
    near = [str(k) for k in result["near_offsets"] if str(k) in result["action_error_by_offset"]]
    labels = ("action_error", "action_error_mean_action", "action_error_zero", "action_error_random")
    width = 0.8 / len(labels)
    for i, name in enumerate(labels):
        values = [result["action_error_by_offset"][k][name] for k in near]
        axes[2].bar(
            np.arange(len(near)) + i * width,
            values,
            width,
            label=name.replace("action_error_", "") if i else "actor",
        )
    axes[2].set_xticks(np.arange(len(near)) + 0.4 - width / 2, near)
    axes[2].set(xlabel="goal offset k", ylabel="mean |a - a_recorded|", title="action toward near goals")
    axes[2].legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


@dataclass
class PolicyPathConfig:
    # A checkpoint's pretrained_model directory (lerobot-train's or lerobot-indicator-train's).
    path: str


@dataclass
class OfflineCheckCLIConfig:
    """``lerobot-indicator-offline-check``: the offline check of a checkpoint on episodes of a dataset."""

    policy: PolicyPathConfig
    dataset: DatasetConfig
    # Episodes to check on (held out from training); None = every episode of the dataset.
    episodes: list[int] | None = None
    offsets: list[int] = field(default_factory=lambda: list(OFFSETS))
    near_offsets: list[int] = field(default_factory=lambda: list(NEAR_OFFSETS))
    output_dir: str = "offline_check"
    device: str = "cpu"


def main() -> None:
    import draccus
    from lerobot.datasets import LeRobotDataset
    from lerobot.utils.import_utils import register_third_party_plugins
    from lerobot.utils.utils import init_logging

    from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

    init_logging()
    register_third_party_plugins()
    cfg = draccus.parse(OfflineCheckCLIConfig)
    policy = IndicatorDDPGPolicy.from_pretrained(cfg.policy.path)
    policy.to(cfg.device)
    keys = list(dict.fromkeys(policy.config.observation_keys + (policy.config.context_keys or [])))
    dataset = LeRobotDataset(cfg.dataset.repo_id, root=cfg.dataset.root, episodes=cfg.episodes,
                             revision=cfg.dataset.revision, video_backend=cfg.dataset.video_backend)  # fmt: skip
    episodes = load_episodes(dataset, keys)
    result = check_policy(policy, episodes, offsets=cfg.offsets, near_offsets=cfg.near_offsets)
    result |= {"policy": cfg.policy.path, "dataset": cfg.dataset.repo_id, "dataset_episodes": cfg.episodes}
    out = Path(cfg.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / RESULT_FILE).write_text(json.dumps(result, indent=1))
    offline_check_figure(result, out / FIGURE_FILE, f"{cfg.policy.path} on {cfg.dataset.repo_id}")
    print(
        f"q_rank_corr={result['q_rank_corr']:.3f} action_error={result['action_error']:.3f} "
        f"(mean action {result['action_error_mean_action']:.3f}, random {result['action_error_random']:.3f}) "
        f"on {len(episodes)} episodes -> {out / RESULT_FILE}"
    )


if __name__ == "__main__":
    main()
