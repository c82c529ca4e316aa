"""The two ways ``indicator_core.encode_batch`` encodes an update give the same features, losses and gradients:
the plain DrQ-v2 path (``encode_plain``) and the encode-once path (``encode_once.encode_distinct_frames``, the
default), on hand-made batches whose goals repeat o_{t+1} so that the encode-once path skips frames.

Setup as tests/test_learning_math_pixels.py: one 2-channel 8x8 image key, one conv layer, seeded distinct
weights in all four networks, random shifts of up to 1 pixel (drawn from torch's global RNG, seeded the same
for both paths) or none.
"""

import pytest
import torch
from test_learning_math import make_policy, set_policy_weights
from test_learning_math_pixels import (
    GOAL_IMG,
    GOAL_IS_NEXT,
    IMG,
    B,
    count_frames,
    frames,
    goals_with_next,
    image_policy,
)
from torch import Tensor

from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

RTOL, ATOL = 1e-5, 1e-6  # the same float32 ops over differently batched frames

# Every branch of the encoders' wiring: the shared encoder with the online or an EMA target encoder, the
# inverse-dynamics features, the filter's target-critic view, and the paper's four encoders.
CONFIGS = {
    "drq": {},
    "drq, inverse dynamics": {"inverse_dynamics": 1.0},
    "drq, target filter": {"filter_q": "target"},
    "drq, target encoder": {"target_encoder": True, "filter_q": "target", "inverse_dynamics": 1.0},
    "paper": {"image_encoder": "paper"},
    "paper, target filter": {"image_encoder": "paper", "filter_q": "target"},
}
PADS = {"shifted": 1, "unshifted": 0}


def close(actual: Tensor | None, expected: Tensor | None) -> None:
    assert (actual is None) == (expected is None)
    if actual is not None:
        torch.testing.assert_close(actual.detach(), expected.detach(), rtol=RTOL, atol=ATOL)


def features(policy: IndicatorDDPGPolicy, encode_once: bool, obs, nxt, goal, is_next, transition_next=None):
    torch.manual_seed(5)  # the same shifts for both paths
    return core.encode_batch(
        {IMG: obs},
        {IMG: nxt},
        {IMG: goal},
        is_next,
        policy.actor,
        policy.critic,
        policy.target_actor,
        policy.target_critic,
        policy.config,
        None if transition_next is None else {IMG: transition_next},
        encode_once=encode_once,
    )


def trainable(policy: IndicatorDDPGPolicy) -> list[tuple[str, torch.nn.Parameter]]:
    return [(n, p) for n, p in policy.named_parameters() if p.requires_grad]


def gradients(loss: Tensor, policy: IndicatorDDPGPolicy) -> dict[str, Tensor]:
    """Every trainable parameter's gradient (zeros for those the loss does not reach)."""
    named = trainable(policy)
    grads = torch.autograd.grad(loss, [p for _, p in named], allow_unused=True)
    return {n: torch.zeros_like(p) if g is None else g for (n, p), g in zip(named, grads, strict=True)}


def assert_same_gradients(got: dict[str, Tensor], want: dict[str, Tensor]) -> None:
    assert got.keys() == want.keys()
    for name in want:
        torch.testing.assert_close(got[name], want[name], rtol=RTOL, atol=ATOL, msg=name)


@pytest.mark.parametrize("pad", PADS.values(), ids=PADS.keys())
@pytest.mark.parametrize("config", CONFIGS.values(), ids=CONFIGS.keys())
@pytest.mark.parametrize("goal_is_next", GOAL_IS_NEXT[:3])
def test_both_paths_give_the_same_features_and_gradients(config, pad, goal_is_next):
    """Every network's features agree, and so do the encoders' gradients from a loss on the features that
    carry gradients (the critic's, the paper actor's, the inverse-dynamics ones); the encode-once path puts
    fewer frames through the convs (goals that are o_{t+1} reuse its encoding)."""
    policy = image_policy(augment_pad=pad, **config)
    obs, nxt = frames(1), frames(2)
    goal, is_next = goals_with_next(nxt, goal_is_next)
    nets = (policy.actor, policy.critic, policy.target_actor, policy.target_critic)
    counts = [count_frames(e) for e in {id(n.encoder): n.encoder for n in nets}.values()]
    out = {}
    for encode_once in (True, False):
        for c in counts:
            c.clear()
        f = features(policy, encode_once, obs, nxt, goal, is_next)
        # The (o_t, o_{t+1}) features mean something only with the inverse-dynamics head to read them.
        if policy.critic.inverse is None:
            f.transition = None
        weight = torch.Generator().manual_seed(3)
        with_grad = [x for x in (f.critic, f.actor, f.transition) if x is not None]
        loss = sum((x * torch.randn(x.shape, generator=weight)).sum() for x in with_grad)
        out[encode_once] = (f, gradients(loss, policy), sum(sum(c) for c in counts))
    (fast, fast_grads, fast_frames), (plain, plain_grads, plain_frames) = out[True], out[False]
    for name in ("critic", "actor", "target_critic", "target_actor", "target_critic_obs", "transition"):
        close(getattr(fast, name), getattr(plain, name))
    for f in (fast, plain):
        assert (
            f.critic.requires_grad and not f.target_critic.requires_grad and not f.target_actor.requires_grad
        )
    assert fast.actor.requires_grad == plain.actor.requires_grad == (not policy.config.shared_encoder)
    assert_same_gradients(fast_grads, plain_grads)
    assert fast_frames < plain_frames


@pytest.mark.parametrize("pad", PADS.values(), ids=PADS.keys())
def test_both_paths_pair_o_t_with_o_next_when_the_target_bootstraps_from_another_frame(pad):
    """With ``transition_next`` (n-step targets) the inverse-dynamics features [enc(o_t), enc(o_{t+1})] and the
    targets on the bootstrap frame o_{t+n} agree, with their gradients."""
    policy = image_policy(augment_pad=pad, inverse_dynamics=1.0)
    obs, nxt, boot = frames(1), frames(2), frames(3)
    goal, is_next = goals_with_next(boot, GOAL_IS_NEXT[0])
    out = {}
    for encode_once in (True, False):
        f = features(policy, encode_once, obs, boot, goal, is_next, transition_next=nxt)
        weight = torch.Generator().manual_seed(3)
        loss = sum((x * torch.randn(x.shape, generator=weight)).sum() for x in (f.critic, f.transition))
        out[encode_once] = (f, gradients(loss, policy))
    (fast, fast_grads), (plain, plain_grads) = out[True], out[False]
    for name in ("critic", "actor", "target_critic", "target_actor", "transition"):
        close(getattr(fast, name), getattr(plain, name))
    assert_same_gradients(fast_grads, plain_grads)


def image_transition_batch(n_step: int = 1) -> dict[str, Tensor]:
    """B transitions with distinct o_t, o_{t+1}, future and recorded-goal frames; rows 1 and 4 have no future
    frame, row 2's recorded goal is its o_{t+1}. With ``n_step`` = 2 the path frame o_{t+2} of rows 0, 3, 5
    (t + 2 <= T) is new, the others hold o_T = o_{t+1}."""
    nxt = frames(2)
    goal = frames(4)
    goal[2] = nxt[2]
    batch = {
        IMG: frames(1),
        core.NEXT + IMG: nxt,
        core.FUTURE + IMG: frames(3),
        GOAL_IMG: goal,
        "action": torch.rand(B, 2, generator=torch.Generator().manual_seed(6)) * 2 - 1,
        core.HAS_FUTURE: torch.tensor([True, False, True, True, False, True]),
    }
    if n_step == 2:
        valid = torch.tensor([True, False, False, True, False, True])
        batch[core.PATH + IMG] = torch.where(valid[:, None, None, None], frames(5), nxt)[:, None]
        batch[core.PATH_VALID] = valid[:, None]
    return batch


LOSS_CONFIGS = {
    **CONFIGS,
    "drq, calibrated filter": {"filter_start": "calibrated"},
    "drq, 2-step, inverse dynamics": {"n_step": 2, "inverse_dynamics": 1.0},
    "paper, 2-step": {"image_encoder": "paper", "n_step": 2},
}


def loss_stats_and_gradients(policy: IndicatorDDPGPolicy, batch: dict, encode_once: bool):
    torch.manual_seed(5)
    loss, stats = core.indicator_ddpg_loss(
        batch,
        policy.actor,
        policy.critic,
        policy.target_actor,
        policy.target_critic,
        policy.config,
        torch.Generator().manual_seed(0),
        encode_once=encode_once,
    )
    return loss, stats, gradients(loss, policy)


@pytest.mark.parametrize("pad", PADS.values(), ids=PADS.keys())
@pytest.mark.parametrize("config", LOSS_CONFIGS.values(), ids=LOSS_CONFIGS.keys())
def test_both_paths_give_the_same_loss_stats_and_gradients(config, pad):
    """``indicator_ddpg_loss`` with either path: the same total loss, every logged statistic and every
    parameter's gradient, on a batch where relabeling picks o_{t+1} as the goal of some rows and not others."""
    policy = image_policy(augment_pad=pad, **config)
    batch = image_transition_batch(policy.config.n_step)
    cfg = policy.config
    with torch.no_grad():  # Q above q0 where the filter reads it, so that it drops the R- rows
        filter_net = policy.target_critic if cfg.filter_q == "target" else policy.critic
        filter_net.net[-1].bias.fill_(cfg.q0 / cfg.q_output_scale + 2.0)
    fast_loss, fast_stats, fast_grads = loss_stats_and_gradients(policy, batch, encode_once=True)
    plain_loss, plain_stats, plain_grads = loss_stats_and_gradients(policy, batch, encode_once=False)
    assert 0 < float(fast_stats["frac_goal_next"]) < 1  # some goals are o_{t+1}: the dedup has work to do
    assert float(fast_stats["frac_filtered"]) > 0
    close(fast_loss, plain_loss)
    assert fast_stats.keys() == plain_stats.keys()
    for name in plain_stats:
        torch.testing.assert_close(fast_stats[name], plain_stats[name], rtol=RTOL, atol=ATOL, msg=name)
    assert_same_gradients(fast_grads, plain_grads)


def test_both_paths_give_the_same_loss_and_gradients_on_state_inputs():
    """Without images nothing is shifted or deduplicated: the two paths are the same computation."""
    policy = make_policy(state_dim=2, action_dim=2, filter=True)
    set_policy_weights(policy)
    gen = torch.Generator().manual_seed(0)
    nxt = torch.randn(B, 2, generator=gen)
    goal = torch.randn(B, 2, generator=gen)
    goal[::2] = nxt[::2]
    batch = {
        "observation.state": torch.randn(B, 2, generator=gen),
        core.NEXT + "observation.state": nxt,
        core.FUTURE + "observation.state": torch.randn(B, 2, generator=gen),
        "observation.goal_state": goal,
        "action": torch.rand(B, 2, generator=gen) * 2 - 1,
        core.HAS_FUTURE: torch.ones(B, dtype=torch.bool),
    }
    fast_loss, _, fast_grads = loss_stats_and_gradients(policy, batch, encode_once=True)
    plain_loss, _, plain_grads = loss_stats_and_gradients(policy, batch, encode_once=False)
    close(fast_loss, plain_loss)
    assert_same_gradients(fast_grads, plain_grads)
