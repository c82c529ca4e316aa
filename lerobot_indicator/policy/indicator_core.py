"""The learning core of Lin, Baweja, Held (CoRL 2019): relabel -> indicator reward -> filter -> DDPG losses.

Pure tensors, shared by every training path (``lerobot-train`` through ``IndicatorDDPGPolicy.forward`` and
the online trainer). It works on a *transition batch*: a flat dict with, for every compared key ``k`` of
``config.observation_keys`` (B = batch size):

==========================================  ===========================================================
``k``                                        o_t
``next.k``                                   o_{t+1}
``future.k``                                 o_{t'}, one candidate future frame with t' >= t+2
``goal_key(k)``                              the recorded goal (what the episode was collected for)
``action``                                   a_t, (B, A) in [-1, 1]
``future.valid``                             bool (B,): False when no t' >= t+2 exists (o_{t'} ignored)
``future.count`` (optional)                  long (B,): how many t' the candidate was drawn from
``next.valid`` (optional)                    bool (B,): False drops the transition (no o_{t+1})
``path.k`` (``n_step`` > 1)                  o_{t+2..t+n}, (B, n-1, ...); steps past o_T hold o_T
``path.valid`` (``n_step`` > 1)              bool (B, n-1): t+i <= T for i = 2..n
``path.observation.gt_achieved_goal`` (o)    ground truth of o_{t+2..t+n} (oracle reward)
``next.observation.gt_achieved_goal`` (opt)  ground truth of o_{t+1}   } oracle reward and the reward
``future.observation.gt_achieved_goal`` (o)  ground truth of o_{t'}    } accuracy / false-negative
``observation.gt_desired_goal`` (optional)   ground truth of the goal  } statistics
==========================================  ===========================================================

Every context key ``c`` of ``config.context_keys`` comes as ``c`` (o_t's), ``next.c`` (o_{t+1}'s) and, for
``n_step`` > 1, ``path.c``: network inputs beside the frame they belong to, never compared, relabeled or in a
goal. Ground truth is never a network input: it only feeds the oracle reward and the logged reward statistics.
"""

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import Tensor, nn

from lerobot_indicator.keys import OBS_GT_ACHIEVED_GOAL, OBS_GT_DESIRED_GOAL, goal_key
from lerobot_indicator.policy.configuration_indicator_ddpg import LEARNED_REWARDS, IndicatorDDPGConfig
from lerobot_indicator.policy.encode_once import encode_distinct_frames
from lerobot_indicator.policy.networks_indicator_ddpg import (
    Critic,
    Features,
    draw_shifts,
    encode_frames,
    widest_word,
)

# Transition-batch keys (the table above).
ACTION = "action"
NEXT = "next."
FUTURE = "future."
HAS_FUTURE = FUTURE + "valid"
FUTURE_COUNT = FUTURE + "count"
NEXT_VALID = NEXT + "valid"
PATH = "path."
PATH_VALID = PATH + "valid"
GT_PATH_ACHIEVED = PATH + OBS_GT_ACHIEVED_GOAL
GT_NEXT_ACHIEVED = NEXT + OBS_GT_ACHIEVED_GOAL
GT_FUTURE_ACHIEVED = FUTURE + OBS_GT_ACHIEVED_GOAL
GT_DESIRED = OBS_GT_DESIRED_GOAL  # the recorded goal's ground truth: o_t's own key, no prefix

# Relabel branches / goal sources.
SOURCE_NEXT, SOURCE_FUTURE, SOURCE_RECORDED = 0, 1, 2


@dataclass
class Relabeling:
    """The probability branch each transition drew and the goal it got (they differ for fallbacks)."""

    branch: Tensor  # long (B,): SOURCE_* drawn with p_next / p_future / rest
    source: Tensor  # long (B,): SOURCE_* of the goal actually used


def relabel_sources(
    has_future: Tensor,
    config: IndicatorDDPGConfig,
    future_count: Tensor | None = None,
    generator: torch.Generator | None = None,
) -> Relabeling:
    """Draw each transition's goal source (Algorithm 1).

    balance=True: o_{t+1} with p_next, o_{t'} (t' >= t+2) with p_future, the recorded goal otherwise; when no
    t' >= t+2 exists (t = T-1) the future branch falls back to ``config.balance_fallback``: o_{t+1} (default;
    t' clipped to T) or the recorded goal (the branch stays a mostly negative example).
    balance=False (HER-style "Indicator" baseline): with p_future_unbalanced the goal is uniform over
    {t+1} + the ``future_count`` candidates (so o_{t+1} with probability 1/(future_count+1)), else recorded.
    ``future_count`` defaults to one candidate where ``has_future``.
    """
    batch_size, device = has_future.shape[0], has_future.device
    gen_device = generator.device if generator is not None else device
    u = torch.rand(batch_size, generator=generator, device=gen_device).to(device)
    recorded = torch.full_like(u, SOURCE_RECORDED, dtype=torch.long)
    if config.balance:
        branch = torch.where(
            u < config.p_next,
            SOURCE_NEXT,
            torch.where(u < config.p_next + config.p_future, SOURCE_FUTURE, recorded),
        )
        fallback = SOURCE_NEXT if config.balance_fallback == "next" else SOURCE_RECORDED
        source = torch.where((branch == SOURCE_FUTURE) & ~has_future, fallback, branch)
        return Relabeling(branch=branch, source=source)

    branch = torch.where(u < config.p_future_unbalanced, SOURCE_FUTURE, recorded)
    count = has_future.long() if future_count is None else future_count.to(device).long() * has_future
    v = torch.rand(batch_size, generator=generator, device=gen_device).to(device)
    pick_next = v < 1.0 / (count + 1).to(v.dtype)
    source = torch.where((branch == SOURCE_FUTURE) & pick_next, SOURCE_NEXT, branch)
    return Relabeling(branch=branch, source=source)


def _pick(source: Tensor, nxt: Tensor, future: Tensor, recorded: Tensor) -> Tensor:
    """Row i of ``nxt``, ``future`` or ``recorded`` as ``source[i]`` says, bit for bit."""
    rows = [nxt, future, recorded]
    if torch.compiler.is_compiling() or len({t.dtype for t in rows}) > 1 or nxt.dim() < 2:
        s = source.view((-1,) + (1,) * (nxt.dim() - 1))
        return torch.where(s == SOURCE_NEXT, nxt, torch.where(s == SOURCE_FUTURE, future, recorded))
    # A 100x100 RGB frame is 3750 int64 selects instead of 30,000 uint8 ones. (Inductor cannot lower the dtype
    # view back, hence the plain path when compiling.)
    nxt_w, future_w, recorded_w = (row_words(t) for t in rows)
    s = source.view(-1, 1)
    picked = torch.where(s == SOURCE_NEXT, nxt_w, torch.where(s == SOURCE_FUTURE, future_w, recorded_w))
    return picked.view(nxt.dtype).view(nxt.shape)


def row_words(x: Tensor) -> Tensor:
    """Each row of ``x`` as the widest machine words that tile its bytes, (B, n_words): rows moved or compared
    as words are moved or compared bit for bit, in the fewest operations."""
    return x.reshape(x.shape[0], -1).view(widest_word(math.prod(x.shape[1:]) * x.element_size()))


def select_goals(batch: dict[str, Tensor], keys: list[str], source: Tensor) -> dict[str, Tensor]:
    """Goal observation per transition, keyed by the compared observation keys."""
    return {k: _pick(source, batch[NEXT + k], batch[FUTURE + k], batch[goal_key(k)]) for k in keys}


def rows_equal(a: Tensor, b: Tensor) -> Tensor:
    """Per-row bit-for-bit equality (floats compared by their bit patterns: -0.0 != 0.0, NaN == same NaN)."""
    if a.shape != b.shape:
        raise ValueError(f"cannot compare observations of shapes {tuple(a.shape)} and {tuple(b.shape)}")
    dtype = torch.promote_types(a.dtype, b.dtype)  # the same answer in either argument order
    # A 64x64 RGB row: 1536 int64 compares instead of 12288 uint8 ones; equal words are equal bit patterns.
    return (row_words(a.to(dtype)) == row_words(b.to(dtype))).all(dim=1)


def indicator_reward(
    next_obs: dict[str, Tensor], goal: dict[str, Tensor], r_pos: float, r_neg: float
) -> Tensor:
    """R+ where o_{t+1} equals the goal on every compared key bit for bit, else R- (paper eq. 3)."""
    equal = torch.stack([rows_equal(next_obs[k], goal[k]) for k in goal]).all(dim=0)
    return torch.where(equal, r_pos, r_neg)


def ground_truth_success(gt_achieved_next: Tensor, gt_goal: Tensor, epsilon: float) -> Tensor:
    """The evaluation reward's success test ||s_{t+1} - s_g|| <= epsilon (paper appendix A)."""
    return torch.linalg.vector_norm((gt_achieved_next - gt_goal).flatten(1), dim=1) <= epsilon


def flip_rewards(
    success: Tensor,
    false_negative_rate: float,
    false_positive_rate: float,
    generator: torch.Generator | None = None,
) -> Tensor:
    """The paper's section-4 noisy reward (r_FN, r_FP): each true positive is given as negative with
    probability ``false_negative_rate`` and each true negative as positive with ``false_positive_rate``, drawn
    anew every time a reward is computed."""
    if false_negative_rate == 0 and false_positive_rate == 0:
        return success
    gen_device = generator.device if generator is not None else success.device
    u = torch.rand(success.shape, generator=generator, device=gen_device).to(success.device)
    return torch.where(success, u >= false_negative_rate, u < false_positive_rate)


def ground_truth_goal(batch: dict[str, Tensor], source: Tensor) -> Tensor | None:
    """Ground truth of the chosen goal: gt_achieved of o_{t+1} / o_{t'}, or gt_desired if recorded."""
    if not all(k in batch for k in (GT_NEXT_ACHIEVED, GT_FUTURE_ACHIEVED, GT_DESIRED)):
        return None
    return _pick(source, batch[GT_NEXT_ACHIEVED], batch[GT_FUTURE_ACHIEVED], batch[GT_DESIRED])


def filter_keep(reward: Tensor, q: Tensor, q0: float, r_neg: float) -> Tensor:
    """Keep all but the suspected false negatives: R- transitions with Q(o_t, o_g, a_t) > q0."""
    return ~((reward == r_neg) & (q > q0))


def filter_calibrated(
    reward: Tensor, q: Tensor, valid: Tensor, q0: float, r_pos: float, fraction: float
) -> Tensor:
    """0-d bool: at least ``fraction`` of the batch's valid R+ transitions have Q > q0 (False without any).

    R+ transitions are the relabeled positives (o_g = o_{t+1}, or a future frame equal to it), whose return
    is high whatever the critic says; Q above q0 on them is the evidence that Q > q0 on an R- transition means
    "probably reachable" rather than an uncalibrated critic.
    """
    positive = (reward == r_pos) & valid
    above = (positive & (q > q0)).sum()
    return (positive.sum() > 0) & (above >= fraction * positive.sum())


def masked_mean(x: Tensor, mask: Tensor) -> Tensor:
    return (x * mask).sum() / mask.sum().clamp_min(1)


def encode_batch(
    obs: dict[str, Tensor],
    next_obs: dict[str, Tensor],
    goal: dict[str, Tensor],
    goal_is_next: Tensor,
    actor: nn.Module,
    critic: Critic,
    target_actor: nn.Module,
    target_critic: nn.Module,
    config: IndicatorDDPGConfig,
    transition_next: dict[str, Tensor] | None = None,
    encode_once: bool = True,
) -> Features:
    """Every network's features for one update: ``encode_plain``'s, or with ``encode_once`` the same values
    with each distinct frame encoded once per encoder (``encode_once.encode_distinct_frames``).

    ``next_obs`` is the frame the TD target bootstraps from (o_{t+1}; o_{t+n} for n-step targets) and
    ``goal_is_next`` marks the goals that are that frame, bit for bit (the encode-once path reuses its
    encoding). ``transition_next``: o_{t+1} for the inverse-dynamics features where ``next_obs`` is another
    frame.
    """
    # One random shift per transition, shared by its o_t, o_{t+1} and goal: the critic compares where things
    # are in two images, so shifting them independently (as DrQ does for single observations) would blur the
    # few-pixel displacement an action makes into the shift noise.
    batch_size, device = goal_is_next.shape[0], goal_is_next.device
    shift = draw_shifts(batch_size, config.augment_pad, device) if config.image_keys else None
    nets = (actor, critic, target_actor, target_critic)
    if encode_once:
        return encode_distinct_frames(
            obs, next_obs, goal, goal_is_next, *nets, config, shift, transition_next
        )
    return encode_plain(obs, next_obs, goal, *nets, config, shift, transition_next)


def encode_plain(
    obs: dict[str, Tensor],
    next_obs: dict[str, Tensor],
    goal: dict[str, Tensor],
    actor: nn.Module,
    critic: Critic,
    target_actor: nn.Module,
    target_critic: nn.Module,
    config: IndicatorDDPGConfig,
    shift: Tensor | None = None,
    transition_next: dict[str, Tensor] | None = None,
) -> Features:
    """Every network's features as DrQ-v2's update computes them: the shifted o_t and goal encoded with
    gradients, the bootstrap frame ``next_obs`` without (only the TD target reads it).

    "paper" encoders: each network encodes its own inputs. Shared ("drq") encoder: the critic's encoder
    serves the actor, which sees its features detached (only the critic loss trains it), and the targets,
    unless they have their own EMA encoder (``target_encoder``); the inverse-dynamics features pair o_t with
    o_{t+1} (``transition_next``, else ``next_obs``), encoded with gradients.
    """
    target_obs = config.filter and config.filter_q == "target"  # the filter reads the target critic's Q
    if not config.shared_encoder:
        with torch.no_grad():
            targets = [net.encode(next_obs, goal, shift) for net in (target_critic, target_actor)]
            target_o = target_critic.encode(obs, goal, shift) if target_obs else None
        critic_f, actor_f = critic.encode(obs, goal, shift), actor.encode(obs, goal, shift)
        return Features(critic_f, actor_f, *targets, target_critic_obs=target_o)

    h_obs, h_goal = encode_frames(critic.encoder, [obs, goal], None if shift is None else [shift, shift])
    features = critic.encoder.join(h_obs, h_goal, obs)
    target_net = target_critic if config.target_encoder else critic
    with torch.no_grad():
        target = target_net.encode(next_obs, goal, shift)
        target_o = target_net.encode(obs, goal, shift) if target_obs else None
    transition = None
    if critic.inverse is not None:
        h_next = critic.encoder(next_obs if transition_next is None else transition_next, shift)
        transition = torch.cat([h_obs, h_next], dim=1)
    return Features(features, features.detach(), target, target, transition, target_o)


def soft_update(target: nn.Module, online: nn.Module, tau: float) -> None:
    """target <- tau * target + (1 - tau) * online (paper: target network smoothing 0.98).

    One ``_foreach_lerp_`` over all parameters (torch's own EMA helpers use it): a per-tensor loop costs ~4%
    of a state-based update on CPU."""
    with torch.no_grad():
        torch._foreach_lerp_(list(target.parameters()), list(online.parameters()), 1.0 - tau)
        for t, o in zip(target.buffers(), online.buffers(), strict=True):
            t.copy_(o)


def n_step_return(
    batch: dict[str, Tensor],
    keys: list[str],
    first_reward: Tensor,
    step_reward: Callable[[dict[str, Tensor], Tensor | None], Tensor],
    config: IndicatorDDPGConfig,
) -> tuple[Tensor, Tensor, dict[str, Tensor]]:
    """sum_{i=1..n'} gamma^(i-1) r_{t+i}, gamma^n' and o_{t+n'}, with n' = min(n, T - t).

    ``first_reward`` is r_{t+1}; r_{t+i} (i >= 2) is ``step_reward`` of the batch's ``path`` frame o_{t+i} (the
    same goal, the same comparison). Steps past the episode end add nothing; the path's last entry holds
    o_{min(t+n, T)}, the frame the target bootstraps from.
    """
    path_valid = batch[PATH_VALID].bool()
    gt_path = batch.get(GT_PATH_ACHIEVED)
    returns, scale = first_reward.clone(), torch.ones_like(first_reward)
    for i in range(path_valid.shape[1]):
        scale = scale * torch.where(path_valid[:, i], config.gamma, 1.0)
        frames = {k: batch[PATH + k][:, i] for k in keys}
        r = step_reward(frames, None if gt_path is None else gt_path[:, i])
        returns = returns + torch.where(path_valid[:, i], scale * r, 0.0)
    # scale is gamma^(n'-1) after the loop: the bootstrap term is one discount further.
    return returns, scale * config.gamma, {k: batch[PATH + k][:, -1] for k in keys}


def indicator_ddpg_loss(
    batch: dict[str, Tensor],
    actor: nn.Module,
    critic: Critic,
    target_actor: nn.Module,
    target_critic: nn.Module,
    config: IndicatorDDPGConfig,
    generator: torch.Generator | None = None,
    reward_model: nn.Module | None = None,
    encode_once: bool = True,
) -> tuple[Tensor, dict[str, Tensor]]:
    """One DDPG step's loss on a transition batch (module docstring), with relabeling, rewards and filtering.

    ``reward_model`` (``learned_reward.LearnedReward``, for ``reward`` "ae" / "vae") gives the reward from
    (o_{t+1}, g) and adds its own reconstruction loss on the batch's o_t to the returned loss.

    Returns ``critic_loss + actor_loss``: the critic gets gradients only from the TD loss (targets and the
    filter's Q are computed without gradients) and the actor only from -Q(o, g, pi(o, g)) + action_l2 *
    pi^2 (evaluated through the critic's head with detached weights, on the same detached encoding of
    (o, g) as Q(o, g, a)), so one backward and one optimizer step over both
    parameter sets equals separate actor and critic updates. ``encode_once``: ``encode_batch``'s path (the
    default encodes each distinct frame once; False: the plain DrQ-v2 encoding, the same values).

    Logging stats are 0-d tensors (``stats_to_floats`` reads them): no host sync inside, so
    ``torch.compile`` captures the whole function as one graph.
    """
    keys = config.observation_keys
    # The networks' inputs: the compared keys and the context keys (never compared, relabeled or in a goal).
    inputs = keys + (config.context_keys or [])
    obs = {k: batch[k] for k in inputs}
    next_obs = {k: batch[NEXT + k] for k in inputs}
    action = batch[ACTION]
    batch_size = action.shape[0]
    has_future = batch[HAS_FUTURE].bool()
    valid = batch.get(NEXT_VALID, torch.ones(batch_size, dtype=torch.bool, device=action.device)).bool()

    relabel = relabel_sources(has_future, config, batch.get(FUTURE_COUNT), generator)
    goal = select_goals(batch, keys, relabel.source)
    gt_goal = ground_truth_goal(batch, relabel.source)

    learned_reward = reward_model.reward_to(goal) if reward_model is not None else None

    def step_reward(frames: dict[str, Tensor], gt_achieved: Tensor | None) -> Tensor:
        """The reward of arriving at ``frames`` with the batch's goals: indicator, learned or oracle."""
        if config.reward == "indicator":
            return indicator_reward(frames, goal, config.positive_reward, config.negative_reward)
        if learned_reward is not None:
            return learned_reward(frames)
        if config.reward != "oracle":
            raise ValueError(f"reward={config.reward!r} needs the policy's reward_model")
        if gt_goal is None or gt_achieved is None:
            raise ValueError(
                f"reward='oracle' needs ground truth in the batch: {GT_NEXT_ACHIEVED}, {GT_FUTURE_ACHIEVED}, "
                f"{GT_DESIRED}" + (f", {GT_PATH_ACHIEVED}" if config.n_step > 1 else "")
            )
        success = ground_truth_success(gt_achieved, gt_goal, config.oracle_epsilon)
        success = flip_rewards(
            success, config.reward_false_negative_rate, config.reward_false_positive_rate, generator
        )
        return torch.where(success, config.positive_reward, config.negative_reward)

    reward = step_reward(next_obs, batch.get(GT_NEXT_ACHIEVED))  # r_{t+1}: the filter's and the stats'
    returns, discount, bootstrap_obs = reward, torch.full_like(reward, config.gamma), next_obs
    if config.n_step > 1:
        returns, discount, bootstrap_obs = n_step_return(batch, inputs, reward, step_reward, config)
    # Where the goal is the frame the target bootstraps from, encode_once shares its encoding.
    goal_is_next = relabel.source == SOURCE_NEXT
    if config.n_step > 1:
        goal_is_next = goal_is_next & ~batch[PATH_VALID].any(dim=1)
    # The inverse-dynamics features pair o_t with o_{t+1}, which an n-step target does not bootstrap from.
    transition_next = next_obs if config.n_step > 1 and critic.inverse is not None else None
    f = encode_batch(
        obs,
        bootstrap_obs,
        goal,
        goal_is_next,
        actor,
        critic,
        target_actor,
        target_critic,
        config,
        transition_next,
        encode_once,
    )
    q = critic.head(f.critic, action)
    with torch.no_grad():
        next_q = target_critic.head(f.target_critic, target_actor.head(f.target_actor))
        # No terminal masking: episodes end by time limit only (as in HER). Clip to the return's range.
        target = (returns + discount * next_q).clamp(config.q_min, config.q_max)
        keep, filter_on = valid, None
        if config.filter:
            q_filter = (
                q.detach() if f.target_critic_obs is None else target_critic.head(f.target_critic_obs, action)
            )
            drop = ~filter_keep(reward, q_filter, config.q0, config.negative_reward)
            if config.filter_start == "calibrated":
                filter_on = filter_calibrated(
                    reward, q_filter, valid, config.q0, config.positive_reward, config.filter_calibration
                )
                drop = drop & filter_on
            keep = valid & ~drop
    keep_f = keep.to(q.dtype)
    critic_loss = masked_mean((q - target) ** 2, keep_f)

    pi = actor.head(f.actor)
    q_pi = critic.head(f.critic.detach(), pi, frozen=True)
    actor_loss = masked_mean(-q_pi + config.action_l2 * (pi**2).mean(dim=1), keep_f)

    valid_f = valid.float()
    loss = critic_loss + actor_loss
    inverse_loss = None
    if critic.inverse is not None and f.transition is not None:
        predicted = torch.tanh(critic.inverse(f.transition))
        inverse_loss = masked_mean(((predicted - action) ** 2).mean(dim=1), valid_f)
        loss = loss + config.inverse_dynamics * inverse_loss
    positive = (reward >= config.reward_positive_threshold).float()
    stats = {
        "critic_loss": critic_loss.detach(),
        "actor_loss": actor_loss.detach(),
        "q_mean": masked_mean(q.detach(), valid_f),
        # ~0 when the critic no longer depends on its input (a saturated last tanh layer): OnlineTrainer warns.
        "q_std": masked_mean((q.detach() - masked_mean(q.detach(), valid_f)) ** 2, valid_f).sqrt(),
        "q_target_mean": masked_mean(target, valid_f),
        "frac_positive": masked_mean(positive, valid_f),
        "frac_filtered": masked_mean((~keep).float(), valid_f),
        "frac_goal_next": masked_mean((relabel.source == SOURCE_NEXT).float(), valid_f),
        "frac_goal_future": masked_mean((relabel.source == SOURCE_FUTURE).float(), valid_f),
        "frac_goal_recorded": masked_mean((relabel.source == SOURCE_RECORDED).float(), valid_f),
    }
    if inverse_loss is not None:
        stats["inverse_dynamics_loss"] = inverse_loss.detach()
    if filter_on is not None:
        stats["filter_active"] = filter_on.float()
    if reward_model is not None:
        model_loss, model_stats = reward_model.loss(obs)
        loss = loss + model_loss
        stats |= model_stats | {"reward_mean": masked_mean(reward, valid_f)}
    if gt_goal is not None:
        stats |= reward_statistics(reward, batch[GT_NEXT_ACHIEVED], gt_goal, keep, valid, config)
    return loss, stats


def stats_to_floats(stats: dict[str, Tensor]) -> dict[str, float]:
    """Python floats for logging, read back in one transfer (one ``.item()`` each would sync every time)."""
    return dict(zip(stats, torch.stack(list(stats.values())).tolist(), strict=True))


def reward_statistics(
    reward: Tensor, gt_next: Tensor, gt_goal: Tensor, keep: Tensor, valid: Tensor, config: IndicatorDDPGConfig
) -> dict[str, Tensor]:
    """How the proxy reward compares with the ground-truth one (paper section 4): accuracy and error rates.

    ``false_negative_rate`` = P(R- | ground-truth success); ``false_negative_rate_kept`` is the same among the
    transitions the filter kept, which shows what filtering removes. ``filtered_gt_success_rate`` = P(ground-truth
    success | filtered), the filter's precision: section 5.3 assumes the transitions it drops are mostly false
    negatives; the rest were genuine negative evidence (0 when nothing was filtered).
    """
    gt_pos = ground_truth_success(gt_next, gt_goal, config.oracle_epsilon) & valid
    gt_neg = ~gt_pos & valid
    pos = (reward >= config.reward_positive_threshold) & valid
    neg = ~pos & valid
    kept_gt_pos = gt_pos & keep
    filtered = valid & ~keep
    ranking = {}
    if config.reward in LEARNED_REWARDS:
        # P(r(ground-truth positive) > r(ground-truth negative)) over the batch's pairs, ties half: how well
        # the learned reward ranks, independent of the threshold (0.5 = no better than chance or no pairs).
        pairs = gt_pos[:, None] & gt_neg[None, :]
        order = (reward[:, None] > reward[None, :]).float() + 0.5 * (
            reward[:, None] == reward[None, :]
        ).float()
        n_pairs = pairs.sum()
        ranking["reward_auc"] = torch.where(n_pairs > 0, (order * pairs).sum() / n_pairs.clamp_min(1), 0.5)
    return ranking | {
        "reward_accuracy": masked_mean((pos == gt_pos).float(), valid.float()),
        "false_negative_rate": (neg & gt_pos).sum() / gt_pos.sum().clamp_min(1),
        "false_positive_rate": (pos & gt_neg).sum() / gt_neg.sum().clamp_min(1),
        "false_negative_rate_kept": (neg & kept_gt_pos).sum() / kept_gt_pos.sum().clamp_min(1),
        "frac_gt_positive": masked_mean(gt_pos.float(), valid.float()),
        "filtered_gt_success_rate": (filtered & gt_pos).sum() / filtered.sum().clamp_min(1),
    }


def dataset_batch_to_transitions(
    batch: dict[str, Tensor], config: IndicatorDDPGConfig, generator: torch.Generator | None = None
) -> dict[str, Tensor]:
    """Turn a ``lerobot-train`` batch into a transition batch.

    With ``observation_delta_indices = [0, 1, *future_offsets]`` every ``observation.*`` key arrives as
    (B, 2 + n_offsets, ...) with ``<key>_is_pad`` (B, 2 + n_offsets) marking frames past the episode end.
    Index 0 is o_t, 1 is o_{t+1}; the future frame is one *valid* offset picked uniformly per sample. When the
    config fetches the episode's end (``EPISODE_END_OFFSET``) one more frame follows: the episode's last frame,
    which stands in for the recorded goal of data without goal columns.
    """
    if config.n_step > 1:
        raise ValueError(
            f"n_step={config.n_step}: a lerobot-train sample holds o_t, o_{{t+1}} and future frames, not the "
            "frames in between that an n-step target compares with the goal; train with n_step=1 here, or "
            "with lerobot-indicator-train (--dataset.* seeds its episode buffer)"
        )
    first = config.observation_keys[0]
    pad_key = f"{first}_is_pad"
    n_frames = 2 + len(config.future_offsets)
    # A fresh lerobot-train fetches the episode's end before it knows whether the data has goal columns.
    if batch[first].dim() < 2 or batch[first].shape[1] not in (n_frames, n_frames + 1):
        raise ValueError(
            f"{first!r} has shape {tuple(batch[first].shape)}: expected (B, {n_frames}, ...) from "
            f"observation_delta_indices {config.observation_delta_indices}, or (B, {n_frames + 1}, ...) with "
            "the episode's last frame"
        )
    has_end = batch[first].shape[1] == n_frames + 1
    batch_size, device = batch[first].shape[0], batch[first].device
    if pad_key in batch:
        is_pad = batch[pad_key].bool()[:, :n_frames]
    else:
        is_pad = torch.zeros(batch_size, n_frames, dtype=torch.bool, device=device)
    future_ok = ~is_pad[:, 2:]
    count = future_ok.sum(dim=1)
    has_future = count > 0
    weights = torch.where(
        has_future[:, None], future_ok.float(), torch.ones_like(future_ok, dtype=torch.float)
    )
    gen_device = generator.device if generator is not None else device
    pick = torch.multinomial(weights.to(gen_device), 1, generator=generator).squeeze(1).to(device) + 2
    rows = torch.arange(batch_size, device=device)

    out = {
        ACTION: batch[ACTION],
        HAS_FUTURE: has_future,
        FUTURE_COUNT: count,
        NEXT_VALID: ~is_pad[:, 1],
    }
    for k in config.observation_keys:
        out[k] = batch[k][:, 0]
        out[NEXT + k] = batch[k][:, 1]
        out[FUTURE + k] = batch[k][rows, pick]
        out[goal_key(k)] = episode_goal(batch, k, has_end)
    for k in config.context_keys or []:
        out[k], out[NEXT + k] = batch[k][:, 0], batch[k][:, 1]
    if OBS_GT_ACHIEVED_GOAL in batch and OBS_GT_DESIRED_GOAL in batch:
        out[GT_NEXT_ACHIEVED] = batch[OBS_GT_ACHIEVED_GOAL][:, 1]
        out[GT_FUTURE_ACHIEVED] = batch[OBS_GT_ACHIEVED_GOAL][rows, pick]
        out[GT_DESIRED] = batch[OBS_GT_DESIRED_GOAL][:, 0]
    return out


def episode_goal(batch: dict[str, Tensor], key: str, has_end: bool) -> Tensor:
    """The recorded goal of ``key``'s episode, (B, ...): its goal column, else the episode's last frame."""
    gkey = goal_key(key)
    if gkey in batch:
        return batch[gkey][:, 0]
    if not has_end:
        raise ValueError(
            f"the batch has no goal {gkey!r} and no episode-end frame of {key!r}: data without goal columns "
            "needs --policy.episode_end_goal=true (the episode's last frame stands in for the recorded goal)"
        )
    return batch[key][:, -1]


def is_transition_batch(batch: dict[str, Tensor], config: IndicatorDDPGConfig) -> bool:
    return NEXT + config.observation_keys[0] in batch
