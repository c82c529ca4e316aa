"""The learning math on hand-made batches, against values computed here from first principles.

Every expected number is recomputed with plain torch/numpy ops on the networks' (hand-set, read-back) weights,
never by calling the code under test again. Setup: state inputs of 1-2 dims, hidden_dims=[2], horizon T = 4,
so gamma = 3/4, and with R+ = 1, R- = -1: q_min = -4, q_max = 4, q0 = 0.5 (-1 + 3 + 4) = 3. The encoder's
default statistics (mean 0, std 1, clip 5) make the normalisation the identity for the |x| < 5 used here.
"""

import numpy as np
import pytest
import torch
from lerobot.configs import FeatureType, PolicyFeature
from torch import nn

from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy
from lerobot_indicator.training.batches import to_transition_batch
from lerobot_indicator.training.replay_buffer import EpisodeReplayBuffer

STATE, GOAL = "observation.state", "observation.goal_state"
VEL, GOAL_VEL = "observation.velocity", "observation.goal_velocity"
T = 4
RTOL, ATOL = 1e-5, 1e-6  # float32 sums in a different order than the reference computation
REWARDS = [(1.0, -1.0), (0.0, -1.0)]

# ----------------------------------------------------------------------------------------------- helpers


def make_policy(
    state_dim: int = 1, action_dim: int = 1, keys: tuple[str, ...] = (STATE,), **kwargs
) -> IndicatorDDPGPolicy:
    """A tiny state policy: every compared key has ``state_dim`` dims, one hidden layer of 2 units, and Q the
    MLP's output (critic_output_scale="paper"), which the reference computations read."""
    goals = {STATE: GOAL, VEL: GOAL_VEL}
    defaults = {
        "hidden_dims": [2],
        "horizon": T,
        "observation_keys": list(keys),
        "critic_output_scale": "paper",
    }
    cfg = IndicatorDDPGConfig(device="cpu", **{**defaults, **kwargs})
    cfg.input_features = {}
    for k in keys:
        cfg.input_features[k] = PolicyFeature(FeatureType.STATE, (state_dim,))
        cfg.input_features[goals[k]] = PolicyFeature(FeatureType.STATE, (state_dim,))
    cfg.output_features = {"action": PolicyFeature(FeatureType.ACTION, (action_dim,))}
    return IndicatorDDPGPolicy(cfg)


def linears(module: nn.Module) -> list[nn.Linear]:
    return [m for m in module.net if isinstance(m, nn.Linear)]


def randomize(module: nn.Module, seed: int, scale: float = 1.0) -> None:
    """Fixed pseudo-random weights (seeded) for one network's MLP, written into the module."""
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in module.net.parameters():
            p.copy_(torch.randn(p.shape, generator=gen) * scale)


def set_policy_weights(policy: IndicatorDDPGPolicy) -> None:
    """Four distinct weight sets: online and target networks must give different values."""
    for seed, net in enumerate((policy.actor, policy.critic, policy.target_actor, policy.target_critic)):
        randomize(net, 100 + seed)


def weights(module: nn.Module, requires_grad: bool = False) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """The MLP's (W, b) pairs read back as fresh leaf tensors (for the reference computation)."""
    return [
        (
            lin.weight.detach().clone().requires_grad_(requires_grad),
            lin.bias.detach().clone().requires_grad_(requires_grad),
        )
        for lin in linears(module)
    ]


def mlp_ref(layers: list[tuple[torch.Tensor, torch.Tensor]], x: torch.Tensor) -> torch.Tensor:
    """x W1^T + b1 -> tanh -> ... -> x Wn^T + bn (no activation on the last layer)."""
    for i, (w, b) in enumerate(layers):
        x = x @ w.T + b
        if i < len(layers) - 1:
            x = torch.tanh(x)
    return x


def pi_ref(layers, o: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
    """pi(o, g) = tanh(MLP([o, g]))."""
    return torch.tanh(mlp_ref(layers, torch.cat([o, g], dim=1)))


def q_ref(layers, o: torch.Tensor, g: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
    """Q(o, g, a) = MLP([o, g, a])."""
    return mlp_ref(layers, torch.cat([o, g, a], dim=1)).squeeze(1)


def col(values) -> torch.Tensor:
    return torch.tensor(values, dtype=torch.float32)[:, None]


def batch_of(obs, nxt, goal, action, future=None, has_future=None) -> dict[str, torch.Tensor]:
    """A one-key transition batch from columns of python floats (exact float32 values, so equal python
    floats give bit-equal tensors)."""
    n = len(obs)
    return {
        STATE: col(obs),
        core.NEXT + STATE: col(nxt),
        core.FUTURE + STATE: col(future if future is not None else [4.0 + i / 8 for i in range(n)]),
        GOAL: col(goal),
        "action": torch.tensor(action, dtype=torch.float32).reshape(n, -1),
        core.HAS_FUTURE: torch.tensor(has_future if has_future is not None else [True] * n),
    }


class LossSpy:
    """Runs ``policy.forward`` and records the core's masked means: call 0 is the critic loss, call 1 the
    actor loss (the order of ``indicator_ddpg_loss``), each as (value, x, mask)."""

    def __init__(self, monkeypatch):
        self.calls: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = []
        original = core.masked_mean

        def spy(x, mask):
            out = original(x, mask)
            self.calls.append((out, x, mask))
            return out

        monkeypatch.setattr(core, "masked_mean", spy)

    def run(self, policy: IndicatorDDPGPolicy, batch: dict, seed: int = 0):
        self.calls.clear()
        total, stats = policy.forward(batch, generator=torch.Generator().manual_seed(seed))
        (critic, _, critic_mask), (actor, _, actor_mask) = self.calls[0], self.calls[1]
        return total, critic, actor, critic_mask, actor_mask, stats


def loss_and_stats(policy: IndicatorDDPGPolicy, batch: dict, seed: int = 0, reward_model=None):
    """The core's loss and its stats (0-d tensors), with the policy's networks and config."""
    return core.indicator_ddpg_loss(
        batch,
        policy.actor,
        policy.critic,
        policy.target_actor,
        policy.target_critic,
        policy.config,
        torch.Generator().manual_seed(seed),
        reward_model,
    )


def close(actual: torch.Tensor, expected: torch.Tensor) -> None:
    torch.testing.assert_close(actual.detach(), expected.detach(), rtol=RTOL, atol=ATOL)


def differs(a: torch.Tensor, b: torch.Tensor, margin: float = 1e-3) -> bool:
    """Clearly different (far beyond RTOL/ATOL): a wrong formula could not pass ``close``."""
    return bool((a - b).abs().max() > margin)


# A batch with the recorded goal used for every row (p_next = p_future = 0): rows 0, 2, 3 have g = o_{t+1}
# exactly (R+), the others R-.
OBS = [0.3, -0.8, 1.2, -0.1, 0.6, -1.5]
NXT = [0.5, -0.4, 0.9, 0.7, -1.1, -0.2]
GOALS = [0.5, 0.2, 0.9, 0.7, -1.0, 1.3]
ACT = [0.2, -0.5, 0.9, -0.9, 0.1, 0.4]
POSITIVE_ROWS = [True, False, True, True, False, False]


# ------------------------------------------------------------------------------------- 1. the TD target


@pytest.mark.parametrize("r_pos, r_neg", REWARDS)
def test_critic_loss_is_mean_squared_td_error_with_target_networks_on_next_obs(monkeypatch, r_pos, r_neg):
    """critic_loss = mean_i (Q(o_i, g_i, a_i) - y_i)^2 with y = clip(r + gamma Q'(o', g, pi'(o', g)),
    q_min, q_max), gamma = (T-1)/T, Q' and pi' the *target* networks evaluated on o_{t+1} (not o_t). Here
    no y reaches a bound, and dropping gamma, using an online network in y or o_t in place of o_{t+1}
    each changes the expected value by far more than the tolerance."""
    policy = make_policy(p_next=0.0, p_future=0.0, filter=False, positive_reward=r_pos, negative_reward=r_neg)
    set_policy_weights(policy)
    # Centre r + gamma Q' in (q_min, q_max) so that no y is clipped here (the next tests clip).
    with torch.no_grad():
        last = linears(policy.target_critic)[-1]
        last.weight.mul_(0.5)
        last.bias.fill_((0.5 * (r_pos + r_neg) * T - 0.5 * (r_pos + r_neg)) / 0.75)
    batch = batch_of(OBS, NXT, GOALS, ACT)
    total, critic_loss, actor_loss, _, _, _ = LossSpy(monkeypatch).run(policy, batch)

    cfg = policy.config
    gamma = (T - 1) / T
    assert cfg.gamma == gamma and (cfg.q_min, cfg.q_max) == (r_neg * T, r_pos * T)
    o, o1, g, a = batch[STATE], batch[core.NEXT + STATE], batch[GOAL], batch["action"]
    r = torch.where(torch.tensor(POSITIVE_ROWS), r_pos, r_neg)
    pa, qc, tpa, tqc = (
        weights(n) for n in (policy.actor, policy.critic, policy.target_actor, policy.target_critic)
    )
    q = q_ref(qc, o, g, a)

    def td(critic_w, actor_w, frame, discount=gamma):
        return (r + discount * q_ref(critic_w, frame, g, pi_ref(actor_w, frame, g))).clamp(
            r_neg * T, r_pos * T
        )

    y = td(tqc, tpa, o1)
    assert bool(((y > r_neg * T) & (y < r_pos * T)).all()), "this test wants y strictly inside the bounds"
    expected = ((q - y) ** 2).mean()
    close(critic_loss, expected)
    close(total, critic_loss + actor_loss)
    for wrong in (td(tqc, tpa, o1, 1.0), td(qc, pa, o1), td(qc, tpa, o1), td(tqc, pa, o1), td(tqc, tpa, o)):
        assert differs(((q - wrong) ** 2).mean(), expected)


@pytest.mark.parametrize("scale", ["paper", "return"])
def test_critic_output_scale_multiplies_every_q_and_keeps_the_initial_q(monkeypatch, scale):
    """critic_output_scale="return": Q = T MLP(...) for the online and the target critic (T = 1/(1-gamma) = 4),
    in Q(o, g, a), in the TD target and in the actor's Q; a critic whose last layer has zero weights gives
    Q = initial_q for every input under either scale. The logged q_std is Q's population std over the batch."""
    s = {"paper": 1.0, "return": float(T)}[scale]
    policy = make_policy(p_next=0.0, p_future=0.0, filter=False, critic_output_scale=scale)
    for critic in (policy.critic, policy.target_critic):
        assert linears(critic)[-1].bias.item() == pytest.approx(policy.config.initial_q / s)
    set_policy_weights(policy)
    with torch.no_grad():  # keep y = r + gamma Q' inside (q_min, q_max) = (-4, 4)
        for critic in (policy.critic, policy.target_critic):
            linears(critic)[-1].weight.mul_(0.25 / s)
            linears(critic)[-1].bias.fill_(0.0)
    batch = batch_of(OBS, NXT, GOALS, ACT)
    _, critic_loss, actor_loss, _, _, stats = LossSpy(monkeypatch).run(policy, batch)
    o, o1, g, a = batch[STATE], batch[core.NEXT + STATE], batch[GOAL], batch["action"]
    r = torch.where(torch.tensor(POSITIVE_ROWS), 1.0, -1.0)
    pa, qc, tpa, tqc = (
        weights(n) for n in (policy.actor, policy.critic, policy.target_actor, policy.target_critic)
    )
    q = s * q_ref(qc, o, g, a)
    y = r + 0.75 * s * q_ref(tqc, o1, g, pi_ref(tpa, o1, g))
    assert bool((y.abs() < T).all()), "this test wants y strictly inside the bounds"
    close(critic_loss, ((q - y) ** 2).mean())
    pi = pi_ref(pa, o, g)
    close(actor_loss, (-s * q_ref(qc, o, g, pi) + (pi**2).mean(dim=1)).mean())
    close(torch.tensor(stats["q_std"]), q.std(unbiased=False))
    with torch.no_grad():
        linears(policy.critic)[-1].weight.zero_()
        linears(policy.critic)[-1].bias.fill_(policy.config.initial_q / s)
    close(policy.critic({STATE: o}, {STATE: g}, a), torch.full((len(OBS),), policy.config.initial_q))


@pytest.mark.parametrize("bias, bound", [(1000.0, "q_max"), (-1000.0, "q_min")])
def test_td_target_is_clipped_at_both_bounds_by_the_target_critic(monkeypatch, bias, bound):
    """y = clip(r + gamma Q', q_min, q_max): with the target critic's output bias at +-1000, every y is
    q_max (= R+ T = 4) or q_min (= R- T = -4), so critic_loss = mean (Q - bound)^2 exactly."""
    policy = make_policy(p_next=0.0, p_future=0.0, filter=False)
    set_policy_weights(policy)
    with torch.no_grad():
        linears(policy.target_critic)[-1].bias.fill_(bias)
    batch = batch_of(OBS, NXT, GOALS, ACT)
    _, critic_loss, _, _, _, stats = LossSpy(monkeypatch).run(policy, batch)
    y = {"q_max": 4.0, "q_min": -4.0}[bound]
    q = q_ref(weights(policy.critic), batch[STATE], batch[GOAL], batch["action"])
    close(critic_loss, ((q - y) ** 2).mean())
    assert stats["q_target_mean"] == pytest.approx(y)


def test_td_target_clips_each_row_at_its_own_bound(monkeypatch):
    """Per-row clipping at both ends in one batch: the target critic is +-50 by the sign of o_{t+1}
    (Q' = 50 tanh(20 o')), so y = clip(r + 0.75 Q', -4, 4) is 4 on some rows and -4 on others."""
    policy = make_policy(p_next=0.0, p_future=0.0, filter=False)
    set_policy_weights(policy)
    first, last = linears(policy.target_critic)
    with torch.no_grad():
        first.weight.copy_(torch.tensor([[20.0, 0.0, 0.0], [0.0, 0.0, 0.0]]))
        first.bias.zero_()
        last.weight.copy_(torch.tensor([[50.0, 0.0]]))
        last.bias.zero_()
    batch = batch_of(OBS, NXT, GOALS, ACT)
    _, critic_loss, _, _, _, _ = LossSpy(monkeypatch).run(policy, batch)
    o1 = batch[core.NEXT + STATE].squeeze(1)
    r = torch.where(torch.tensor(POSITIVE_ROWS), 1.0, -1.0)
    unclipped = r + 0.75 * 50 * torch.tanh(20 * o1)
    y = unclipped.clamp(-4.0, 4.0)
    assert set(y.tolist()) == {4.0, -4.0}
    q = q_ref(weights(policy.critic), batch[STATE], batch[GOAL], batch["action"])
    close(critic_loss, ((q - y) ** 2).mean())
    assert differs(((q - unclipped) ** 2).mean(), ((q - y) ** 2).mean())


def test_balanced_relabeling_loss_matches_sources_drawn_with_the_same_seed(monkeypatch):
    """With the default balanced mix (0.45 next / 0.45 future / 0.1 recorded, fallback "next" where no
    t' >= t+2 exists), the loss uses, row by row, the goal of ``relabel_sources`` drawn with the same
    generator seed: g = o_{t+1} / o_{t'} / recorded goal, r = R+ iff g == o_{t+1}, and the critic and actor
    losses recomputed from those goals match."""
    n = 64
    gen = torch.Generator().manual_seed(7)
    obs, nxt = (
        (torch.rand(n, generator=gen) * 2 - 1).tolist(),
        (torch.rand(n, generator=gen) * 2 - 1).tolist(),
    )
    fut = (torch.rand(n, generator=gen) + 2).tolist()  # never equal to o_{t+1}
    rec = [x if i % 5 == 0 else x + 3 for i, x in enumerate(nxt)]  # some recorded goals are reached
    act = (torch.rand(n, generator=gen) * 2 - 1).tolist()
    has_future = [i % 4 != 0 for i in range(n)]
    policy = make_policy(filter=False)
    set_policy_weights(policy)
    batch = batch_of(obs, nxt, rec, act, future=fut, has_future=has_future)
    _, critic_loss, actor_loss, _, _, stats = LossSpy(monkeypatch).run(policy, batch, seed=11)

    relabel = core.relabel_sources(
        batch[core.HAS_FUTURE], policy.config, None, torch.Generator().manual_seed(11)
    )
    src = relabel.source[:, None]
    o, o1, a = batch[STATE], batch[core.NEXT + STATE], batch["action"]
    g = torch.where(src == 0, o1, torch.where(src == 1, batch[core.FUTURE + STATE], batch[GOAL]))
    # The three sources all occur, and the fallback happened: future branch rows without a future use o_{t+1}.
    assert {0, 1, 2} <= set(relabel.source.tolist())
    fallback = (relabel.branch == 1) & ~batch[core.HAS_FUTURE]
    assert fallback.any() and bool((relabel.source[fallback] == 0).all())
    r = torch.where((g == o1).all(dim=1), 1.0, -1.0)
    pa, qc, tpa, tqc = (
        weights(m) for m in (policy.actor, policy.critic, policy.target_actor, policy.target_critic)
    )
    y = (r + 0.75 * q_ref(tqc, o1, g, pi_ref(tpa, o1, g))).clamp(-4.0, 4.0)
    close(critic_loss, ((q_ref(qc, o, g, a) - y) ** 2).mean())
    pi = pi_ref(pa, o, g)
    close(actor_loss, (-q_ref(qc, o, g, pi) + (pi**2).mean(dim=1)).mean())
    assert stats["frac_positive"] == pytest.approx(((r == 1).float().mean()).item())


# ------------------------------------------------------------------------------------- 2. the filter mask


def filter_batch_and_policy(r_pos: float, r_neg: float, filter_on: bool = True):
    """Q(o, g, a) = q0 + 2 tanh(3 o) + 0.1 tanh(.): Q > q0 + 1.5 for o = +0.5, < q0 - 1.5 for o = -0.5.
    Rows: (Q high, R-) x2, (Q high, R+) x2, (Q low, R-) x2, (Q low, R+) x2."""
    policy = make_policy(
        p_next=0.0, p_future=0.0, filter=filter_on, positive_reward=r_pos, negative_reward=r_neg
    )
    set_policy_weights(policy)
    q0 = policy.config.q0
    assert q0 == pytest.approx(0.5 * (r_neg + 0.75 * r_pos * T + r_pos * T))
    first, last = linears(policy.critic)
    with torch.no_grad():
        first.weight[0] = torch.tensor([3.0, 0.0, 0.0])
        first.bias[0] = 0.0
        last.weight.copy_(torch.tensor([[2.0, 0.1]]))
        last.bias.fill_(q0)
    obs = [0.5, 0.5, 0.5, 0.5, -0.5, -0.5, -0.5, -0.5]
    nxt = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8]
    goal = [-0.1, -0.2, 0.3, 0.4, -0.5, -0.6, 0.7, 0.8]
    act = [0.3, -0.2, 0.6, -0.7, 0.1, 0.9, -0.4, 0.5]
    return policy, batch_of(obs, nxt, goal, act)


@pytest.mark.parametrize("r_pos, r_neg", REWARDS)
def test_filter_excludes_negative_high_q_rows_from_both_losses(monkeypatch, r_pos, r_neg):
    """keep = not (r == R- and Q(o, g, a) > q0), q0 = 0.5 [R- + gamma R+ T + R+ T]; critic_loss =
    sum_keep (Q - y)^2 / |keep| and actor_loss = sum_keep (-Q(o, g, pi) + l2 mean_a pi^2) / |keep|. R+ rows
    with Q far above q0 stay; the two (R-, Q > q0) rows are dropped from both means (the all-row means
    differ)."""
    policy, batch = filter_batch_and_policy(r_pos, r_neg)
    _, critic_loss, actor_loss, critic_mask, actor_mask, stats = LossSpy(monkeypatch).run(policy, batch)
    o, o1, g, a = batch[STATE], batch[core.NEXT + STATE], batch[GOAL], batch["action"]
    q0 = policy.config.q0
    pa, qc, tpa, tqc = (
        weights(m) for m in (policy.actor, policy.critic, policy.target_actor, policy.target_critic)
    )
    q = q_ref(qc, o, g, a)
    r = torch.where((g == o1).all(dim=1), r_pos, r_neg)
    assert r.tolist() == [r_neg, r_neg, r_pos, r_pos, r_neg, r_neg, r_pos, r_pos]
    assert bool((q[:4] > q0 + 1.5).all() and (q[4:] < q0 - 1.5).all())
    keep = torch.tensor([False, False, True, True, True, True, True, True])
    assert torch.equal(critic_mask.bool(), keep) and torch.equal(actor_mask.bool(), keep)

    y = (r + 0.75 * q_ref(tqc, o1, g, pi_ref(tpa, o1, g))).clamp(r_neg * T, r_pos * T)
    pi = pi_ref(pa, o, g)
    per_row_actor = -q_ref(qc, o, g, pi) + (pi**2).mean(dim=1)
    close(critic_loss, ((q - y) ** 2)[keep].mean())
    close(actor_loss, per_row_actor[keep].mean())
    assert differs(((q - y) ** 2)[keep].mean(), ((q - y) ** 2).mean())
    assert differs(per_row_actor[keep].mean(), per_row_actor.mean())
    assert stats["frac_filtered"] == pytest.approx(2 / 8)


@pytest.mark.parametrize("r_pos, r_neg", REWARDS)
def test_filter_false_keeps_every_row(monkeypatch, r_pos, r_neg):
    """filter=False: the same batch, (R-, Q > q0) rows included, averages both losses over all 8 rows."""
    policy, batch = filter_batch_and_policy(r_pos, r_neg, filter_on=False)
    _, critic_loss, actor_loss, critic_mask, actor_mask, stats = LossSpy(monkeypatch).run(policy, batch)
    o, o1, g, a = batch[STATE], batch[core.NEXT + STATE], batch[GOAL], batch["action"]
    pa, qc, tpa, tqc = (
        weights(m) for m in (policy.actor, policy.critic, policy.target_actor, policy.target_critic)
    )
    r = torch.where((g == o1).all(dim=1), r_pos, r_neg)
    y = (r + 0.75 * q_ref(tqc, o1, g, pi_ref(tpa, o1, g))).clamp(r_neg * T, r_pos * T)
    pi = pi_ref(pa, o, g)
    assert bool(critic_mask.bool().all() and actor_mask.bool().all())
    close(critic_loss, ((q_ref(qc, o, g, a) - y) ** 2).mean())
    close(actor_loss, (-q_ref(qc, o, g, pi) + (pi**2).mean(dim=1)).mean())
    assert stats["frac_filtered"] == 0.0


# ------------------------------------------------------------------------------------- 3. the actor loss


def test_actor_loss_uses_the_online_critic_and_mean_over_action_dims(monkeypatch):
    """actor_loss = mean_i [-Q(o, g, pi(o, g)) + action_l2 * mean_a pi_a^2] with the ONLINE actor and
    critic and pi (not the batch action) fed to Q; A = 2 and action_l2 = 0.5 make sum-vs-mean over actions
    and a missing / unit l2 weight visible, as would the target critic or target actor."""
    policy = make_policy(action_dim=2, p_next=0.0, p_future=0.0, filter=False, action_l2=0.5)
    set_policy_weights(policy)
    act = [[a, -a / 2] for a in ACT]
    batch = batch_of(OBS, NXT, GOALS, act)
    _, _, actor_loss, _, _, _ = LossSpy(monkeypatch).run(policy, batch)
    o, g = batch[STATE], batch[GOAL]
    pa, qc, tpa, tqc = (
        weights(m) for m in (policy.actor, policy.critic, policy.target_actor, policy.target_critic)
    )

    def loss(critic_w, actor_w, l2=0.5, reduce=torch.mean, action=None):
        pi = pi_ref(actor_w, o, g)
        return (-q_ref(critic_w, o, g, pi if action is None else action) + l2 * reduce(pi**2, dim=1)).mean()

    expected = loss(qc, pa)
    close(actor_loss, expected)
    for wrong in (
        loss(tqc, pa),
        loss(qc, tpa),
        loss(qc, pa, l2=1.0),
        loss(qc, pa, reduce=torch.sum),
        loss(qc, pa, action=batch["action"]),
    ):
        assert differs(wrong, expected)


def test_each_loss_reaches_only_its_own_network_with_the_reference_gradient(monkeypatch):
    """d actor_loss / d theta_actor equals autograd through the reference formula, and the actor loss gives
    the critic no gradient (Q(o, g, pi) sees detached critic weights); d critic_loss / d theta_critic equals
    the reference's, and the critic loss gives the actor none (y is computed without gradients). Target
    networks get nothing from either."""
    policy = make_policy(action_dim=2, p_next=0.0, p_future=0.0, filter=False, action_l2=0.5)
    set_policy_weights(policy)
    batch = batch_of(OBS, NXT, GOALS, [[a, a / 3] for a in ACT])
    _, critic_loss, actor_loss, _, _, _ = LossSpy(monkeypatch).run(policy, batch)
    o, o1, g, a = batch[STATE], batch[core.NEXT + STATE], batch[GOAL], batch["action"]
    actor_params = [p for lin in linears(policy.actor) for p in (lin.weight, lin.bias)]
    critic_params = [p for lin in linears(policy.critic) for p in (lin.weight, lin.bias)]
    assert len(list(policy.actor.parameters())) == len(actor_params)  # the state encoder has no parameters
    assert len(list(policy.critic.parameters())) == len(critic_params)
    targets = [*policy.target_actor.parameters(), *policy.target_critic.parameters()]
    assert not any(p.requires_grad for p in targets)

    def grads(loss, params):
        return torch.autograd.grad(loss, params, retain_graph=True, allow_unused=True)

    assert all(gr is None for gr in grads(actor_loss, critic_params))
    assert all(gr is None for gr in grads(critic_loss, actor_params))

    pa, qc = weights(policy.actor, requires_grad=True), weights(policy.critic)
    pi = pi_ref(pa, o, g)
    ref_actor = (-q_ref(qc, o, g, pi) + 0.5 * (pi**2).mean(dim=1)).mean()
    expected = torch.autograd.grad(ref_actor, [t for wb in pa for t in wb])
    for got, want in zip(grads(actor_loss, actor_params), expected, strict=True):
        close(got, want)
        assert got.abs().max() > 1e-4

    qc = weights(policy.critic, requires_grad=True)
    tpa, tqc = weights(policy.target_actor), weights(policy.target_critic)
    r = torch.where(torch.tensor(POSITIVE_ROWS), 1.0, -1.0)
    y = (r + 0.75 * q_ref(tqc, o1, g, pi_ref(tpa, o1, g))).clamp(-4.0, 4.0)
    ref_critic = ((q_ref(qc, o, g, a) - y) ** 2).mean()
    expected = torch.autograd.grad(ref_critic, [t for wb in qc for t in wb])
    for got, want in zip(grads(critic_loss, critic_params), expected, strict=True):
        close(got, want)
        assert got.abs().max() > 1e-4


# ------------------------------------------------------------------------------------ 4. target updates


def test_update_moves_each_target_toward_its_online_network_with_tau():
    """After ``policy.update()``: target <- tau target + (1 - tau) online with tau = 0.98, for every
    parameter of the target actor AND target critic (the swapped direction 0.02 target + 0.98 online is far
    off); online parameters are untouched; the targets' buffers (input statistics) are copied."""
    policy = make_policy(action_dim=2)
    assert policy.config.tau == 0.98
    set_policy_weights(policy)
    stats = {STATE: {"mean": torch.tensor([0.25]), "std": torch.tensor([2.0])}}
    policy.actor.encoder.set_stats(stats)
    policy.critic.encoder.set_stats(stats)
    pairs = [(policy.actor, policy.target_actor), (policy.critic, policy.target_critic)]
    online_before = [[p.detach().clone() for p in on.parameters()] for on, _ in pairs]
    target_before = [[p.detach().clone() for p in tg.parameters()] for _, tg in pairs]
    policy.update()
    for (online, target), on0, tg0 in zip(pairs, online_before, target_before, strict=True):
        for p_on, p_tg, o_old, t_old in zip(online.parameters(), target.parameters(), on0, tg0, strict=True):
            assert torch.equal(p_on.detach(), o_old)
            expected = 0.98 * t_old + 0.02 * o_old
            torch.testing.assert_close(p_tg.detach(), expected, rtol=1e-6, atol=1e-7)
            assert differs(0.02 * t_old + 0.98 * o_old, expected, margin=1e-2)
        for b_on, b_tg in zip(online.buffers(), target.buffers(), strict=True):
            assert torch.equal(b_on, b_tg)
    assert float(policy.target_actor.encoder.std_0) == 2.0


def test_soft_update_refuses_networks_whose_buffers_do_not_pair_up():
    """A target with a buffer its online network lacks is not that network's copy: refused, not half-synced."""
    online, target = nn.Linear(1, 1), nn.Linear(1, 1)
    target.register_buffer("extra", torch.zeros(1))
    with pytest.raises(ValueError):
        core.soft_update(target, online, 0.98)


# --------------------------------------------------------------------------------- 5. indicator reward


@pytest.mark.parametrize("r_pos, r_neg", [(1.0, -1.0), (0.0, -1.0), (2.5, -0.5)])
def test_indicator_reward_is_bitwise_equality_of_next_obs_and_goal_on_every_key(r_pos, r_neg):
    """r = R+ iff o_{t+1} == g bit for bit on EVERY compared key, else R- (the values given)."""
    one = torch.tensor(1.0)
    up = torch.nextafter(one, torch.tensor(2.0))
    nxt = {STATE: torch.tensor([[1.0, 0.0], [1.0, 0.0], [0.0, 0.5], [1.0, 0.0], [3.0, 3.0]]),
           VEL: torch.tensor([[0.5], [0.5], [0.25], [float(up)], [7.0]])}  # fmt: skip
    goal = {STATE: torch.tensor([[1.0, 0.0], [1.0, -0.0], [0.0, 0.5], [1.0, 0.0], [3.0, 3.0]]),
            VEL: torch.tensor([[0.5], [0.5], [0.75], [1.0], [7.0]])}  # fmt: skip
    reward = core.indicator_reward(nxt, goal, r_pos, r_neg)
    assert reward.tolist() == [r_pos, r_neg, r_neg, r_neg, r_pos]


@pytest.mark.parametrize("r_pos, r_neg", [(1.0, -1.0), (0.0, -1.0), (2.5, -0.5)])
def test_loss_reward_uses_the_config_values_and_compares_next_obs(monkeypatch, r_pos, r_neg):
    """Through the loss with two compared keys: Q' = 0 (target critic's last layer zeroed) makes y = r and
    Q = 0.3 (online critic constant), so critic_loss = mean (0.3 - r)^2 for the hand-labelled rewards: R+ only
    on row 0 (both keys equal); R- for one ulp off on one key, +0.0 vs -0.0, o_t (not o_{t+1}) == g."""
    policy = make_policy(keys=(STATE, VEL), p_next=0.0, p_future=0.0, filter=False,
                         positive_reward=r_pos, negative_reward=r_neg)  # fmt: skip
    set_policy_weights(policy)
    with torch.no_grad():
        for net, value in ((policy.target_critic, 0.0), (policy.critic, 0.3)):
            linears(net)[-1].weight.zero_()
            linears(net)[-1].bias.fill_(value)
    up = float(torch.nextafter(torch.tensor(0.5), torch.tensor(1.0)))  # one float32 ulp above 0.5
    up07 = float(torch.nextafter(torch.tensor(0.7), torch.tensor(1.0)))
    batch = {
        STATE: col([0.1, 0.2, 0.3, 0.9, 0.5]),
        core.NEXT + STATE: col([0.4, 0.4, 0.0, 0.1, up]),
        core.FUTURE + STATE: col([4.0] * 5),
        GOAL: col([0.4, 0.4, -0.0, 0.9, 0.5]),
        VEL: col([1.0] * 5),
        core.NEXT + VEL: col([0.7, 0.7, 0.7, 0.7, 0.7]),
        core.FUTURE + VEL: col([4.0] * 5),
        GOAL_VEL: col([0.7, up07, 0.7, 0.7, 0.7]),
        "action": col([0.0] * 5),
        core.HAS_FUTURE: torch.ones(5, dtype=torch.bool),
    }
    _, critic_loss, _, _, _, stats = LossSpy(monkeypatch).run(policy, batch)
    r = torch.tensor([r_pos, r_neg, r_neg, r_neg, r_neg])
    close(critic_loss, ((0.3 - r) ** 2).mean())
    assert stats["q_target_mean"] == pytest.approx(r.mean().item())
    assert stats["frac_positive"] == pytest.approx(1 / 5)


# -------------------------------------------------------------------------- 6. replay buffer coverage


def coded_buffer(n_episodes: int = 3) -> EpisodeReplayBuffer:
    """Frame t of episode e is the state (e, t): a sample's frames name where they came from."""
    buf = EpisodeReplayBuffer(capacity_transitions=n_episodes * T, horizon=T)
    for e in range(n_episodes):
        steps = np.arange(T + 1, dtype=np.float32)
        state = np.stack([np.full(T + 1, e, np.float32), steps], axis=1)
        actions = np.stack([np.full(T, e), np.arange(T)], axis=1).astype(np.float32)
        buf.add_episode({STATE: state, GOAL: np.full((1, 2), 10 + e, np.float32)}, actions)
    return buf


def four_sigma(p: float, n: int) -> float:
    """4 standard deviations of a binomial frequency: a correct sampler fails one such check with
    probability ~6e-5 (and the seed is fixed)."""
    return 4 * np.sqrt(p * (1 - p) / n)


def test_replay_sample_covers_every_t_and_every_future_t_prime():
    """t is uniform over {0..T-1} (t = T-1 included); has_future is False exactly for t = T-1; the future
    frame is o_{t'} of the same episode with t' uniform over {t+2..T}, every allowed t' occurring; the
    next frame is o_{t+1} of the same episode; the action is a_t and the goal the episode's."""
    n = 20_000
    b = coded_buffer().sample(n, np.random.default_rng(0))
    ep, t, fut_t = b["episode"], b["t"], b["future_t"]
    obs, nxt, fut = b["obs"][STATE], b["next_obs"][STATE], b["future_obs"][STATE]
    assert np.array_equal(obs, np.stack([ep, t], axis=1).astype(np.float32))
    assert np.array_equal(nxt, np.stack([ep, t + 1], axis=1).astype(np.float32))
    assert np.array_equal(b["action"], obs)
    assert np.array_equal(b["obs"][GOAL][:, 0], 10 + ep)
    assert set(ep.tolist()) == {0, 1, 2}
    for step in range(T):
        assert abs((t == step).mean() - 1 / T) <= four_sigma(1 / T, n), step
    has = b["has_future"]
    assert np.array_equal(has, t != T - 1)
    assert np.array_equal(fut[has], np.stack([ep[has], fut_t[has]], axis=1).astype(np.float32))
    assert np.all((fut_t[has] >= t[has] + 2) & (fut_t[has] <= T))
    for step in range(T - 1):
        chosen = fut_t[t == step]
        allowed = list(range(step + 2, T + 1))
        assert sorted(set(chosen.tolist())) == allowed, step
        p = 1 / len(allowed)
        for tp in allowed:
            assert abs((chosen == tp).mean() - p) <= four_sigma(p, len(chosen)), (step, tp)


# ---------------------------------------------------------------- 7. future.count and HER relabeling


def test_future_count_and_unbalanced_relabeling_pick_next_with_probability_one_over_count_plus_one():
    """future.count = |{t+2..T}| = T - t - 1 (0 at t = T-1); with balance=False, p_future_unbalanced=1, the
    goal is o_{t+1} with probability 1/(count+1) (always at t = T-1), i.e. uniform over {t+1..T} together
    with the future draw. Tolerance: 4 binomial sigmas on ~20k rows per t (false alarm ~6e-5 per check)."""
    n = 80_000
    sample = coded_buffer().sample(n, np.random.default_rng(1))
    batch = to_transition_batch(sample, [STATE], T, torch.device("cpu"))
    t = torch.from_numpy(sample["t"])
    count = batch[core.FUTURE_COUNT]
    assert torch.equal(count, (T - t - 1).clamp_min(0))
    for step in range(T):
        assert bool((count[t == step] == len(range(step + 2, T + 1))).all())
    assert torch.equal(batch[core.HAS_FUTURE], count > 0)

    policy = make_policy(state_dim=2, balance=False, p_future_unbalanced=1.0)
    relabel = core.relabel_sources(
        batch[core.HAS_FUTURE], policy.config, count, torch.Generator().manual_seed(2)
    )
    assert bool((relabel.branch == core.SOURCE_FUTURE).all())
    goal_t = core.select_goals(batch, [STATE], relabel.source)[STATE][:, 1]
    for step in range(T):
        rows = t == step
        m = int(rows.sum())
        p = 1 / (T - step)
        frac_next = (relabel.source[rows] == core.SOURCE_NEXT).float().mean().item()
        if step == T - 1:
            assert frac_next == 1.0
        else:
            assert abs(frac_next - p) <= four_sigma(p, m), step
        for tp in range(step + 1, T + 1):  # the goal's frame index is uniform over {t+1..T}
            assert abs((goal_t[rows] == tp).float().mean().item() - p) <= four_sigma(p, m), (step, tp)

    none = make_policy(state_dim=2, balance=False, p_future_unbalanced=0.0).config
    relabel = core.relabel_sources(batch[core.HAS_FUTURE], none, count, torch.Generator().manual_seed(2))
    assert bool((relabel.source == core.SOURCE_RECORDED).all())


def test_loss_passes_future_count_to_unbalanced_relabeling():
    """The loss's own relabeling sees future.count: frac_goal_next = mean_i 1/(count_i + 1) (a loss that
    ignored the count would give 1/2 for every row with a future)."""
    n = 80_000
    sample = coded_buffer().sample(n, np.random.default_rng(3))
    batch = to_transition_batch(sample, [STATE], T, torch.device("cpu"))
    policy = make_policy(state_dim=2, action_dim=2, balance=False, p_future_unbalanced=1.0)
    _, stats = policy.forward(batch, generator=torch.Generator().manual_seed(4))
    p = (1.0 / (batch[core.FUTURE_COUNT] + 1).double()).mean().item()
    # Sum of independent Bernoulli(p_i): variance sum p_i (1 - p_i) / n^2 <= 1/(4n).
    assert abs(stats["frac_goal_next"] - p) < 4 * np.sqrt(0.25 / n)
    assert abs(0.5 * 3 / 4 + 0.25 - p) > 0.05  # what ignoring the count would give is far away


def test_dataset_batch_future_frame_is_a_valid_offset_and_count_counts_them():
    """lerobot-train batches: o_t = index 0, o_{t+1} = index 1, the future frame one of the non-padded
    offsets (uniformly), future.count = their number, next.valid = not is_pad[:, 1]."""
    policy = make_policy(future_offsets=[2, 3, 4])
    n = 6000
    frames = torch.arange(5, dtype=torch.float32).repeat(n, 1)[:, :, None]  # frame j holds the value j
    valid_futures = torch.tensor([3, 2, 1, 0, 0, 0]).repeat(n // 6)
    is_pad = torch.zeros(n, 5, dtype=torch.bool)
    for j in range(3):
        is_pad[:, 2 + j] = valid_futures <= j
    is_pad[valid_futures == 0, 1] = torch.arange(n)[valid_futures == 0] % 2 == 0
    batch = {
        STATE: frames,
        f"{STATE}_is_pad": is_pad,
        GOAL: torch.full((n, 5, 1), 9.0),
        "action": torch.zeros(n, 1),
    }
    out = core.dataset_batch_to_transitions(batch, policy.config, torch.Generator().manual_seed(0))
    assert torch.equal(out[core.FUTURE_COUNT], valid_futures)
    assert torch.equal(out[core.HAS_FUTURE], valid_futures > 0)
    assert torch.equal(out[core.NEXT_VALID], ~is_pad[:, 1])
    assert bool((out[STATE] == 0).all() and (out[core.NEXT + STATE] == 1).all() and (out[GOAL] == 9).all())
    fut = out[core.FUTURE + STATE].squeeze(1)
    for c in (1, 2, 3):
        rows = fut[valid_futures == c]
        assert sorted(set(rows.tolist())) == [float(2 + j) for j in range(c)]
        for j in range(c):
            assert abs((rows == 2 + j).float().mean().item() - 1 / c) <= four_sigma(1 / c, len(rows))


# --------------------------------------------------------------------------------------- 8. rows_equal


@pytest.mark.parametrize("dtype", [torch.float16, torch.float32, torch.float64])
def test_rows_equal_compares_bit_patterns(dtype):
    """Per row, all elements bit-equal: -0.0 != +0.0; a NaN equals the same NaN (its bits), not another
    payload; one differing element in a row makes that row unequal."""
    nan = torch.tensor([float("nan")], dtype=dtype)
    bits = {torch.float16: torch.int16, torch.float32: torch.int32, torch.float64: torch.int64}[dtype]
    other_nan = (nan.view(bits) + 1).view(dtype)
    assert bool(torch.isnan(other_nan).all())
    a = torch.cat(
        [
            torch.tensor([[0.0, 1.0], [0.0, 1.0], [2.0, 3.0]], dtype=dtype),
            torch.tensor([[0.0, 0.0]], dtype=dtype),
        ]
    )
    b = torch.cat(
        [
            torch.tensor([[0.0, 1.0], [-0.0, 1.0], [2.0, 3.5]], dtype=dtype),
            torch.tensor([[0.0, 0.0]], dtype=dtype),
        ]
    )
    a[3, 1], b[3, 1] = nan, nan
    assert core.rows_equal(a, b).tolist() == [True, False, False, True]
    b[3, 1] = other_nan
    assert core.rows_equal(a, b).tolist() == [True, False, False, False]
    assert core.rows_equal(b, a).tolist() == [True, False, False, False]
    with pytest.raises(ValueError, match="shapes"):
        core.rows_equal(a, b[:, :1])


@pytest.mark.parametrize(
    "a, b",
    [
        (torch.tensor([[0.1]], dtype=torch.float32), torch.tensor([[0.1]], dtype=torch.float64)),
        (torch.tensor([[0]], dtype=torch.int32), torch.tensor([[-0.0]], dtype=torch.float32)),
    ],
    ids=["float32-vs-float64", "int32-vs-float32"],
)
def test_rows_equal_does_not_depend_on_argument_order_across_dtypes(a, b):
    """rows_equal(a, b) == rows_equal(b, a) whatever the dtypes."""
    assert core.rows_equal(a, b).tolist() == core.rows_equal(b, a).tolist()


def test_rows_equal_same_dtype_is_symmetric():
    """Within one dtype the answer is the same in both orders."""
    a = torch.tensor([[0.1, -0.0], [0.1, 0.0]])
    b = torch.tensor([[0.1, 0.0], [0.1, 0.0]])
    assert core.rows_equal(a, b).tolist() == core.rows_equal(b, a).tolist() == [False, True]


def test_packed_replay_recorded_goal_reached_gets_r_plus():
    """An episode whose recorded goal is o_{T-1} (values k/255, packed as uint8): the transition t = T-2
    reaches it, so r = R+ and the goal the networks see is o_{T-1}'s float value, also after a later
    episode made the observation key widen to float32."""
    buf = EpisodeReplayBuffer(capacity_transitions=2 * T, horizon=T)
    state = np.arange(T + 1, dtype=np.float32)[:, None] / np.float32(255)
    actions = np.zeros((T, 1), np.float32)
    buf.add_episode({STATE: state, GOAL: state[T - 1 : T]}, actions)
    buf.add_episode({STATE: state + np.float32(0.123), GOAL: state[T - 1 : T]}, actions)  # widens STATE
    sample = buf.sample(256, np.random.default_rng(0), packed=True)
    batch = to_transition_batch(sample, [STATE], T, torch.device("cpu"))
    rows = torch.from_numpy((sample["episode"] == 0) & (sample["t"] == T - 2))
    assert rows.any()
    recorded = torch.full((256,), core.SOURCE_RECORDED)
    goal = core.select_goals(batch, [STATE], recorded)
    reward = core.indicator_reward({STATE: batch[core.NEXT + STATE]}, goal, 1.0, -1.0)
    assert bool((reward[rows] == 1.0).all())
    torch.testing.assert_close(goal[STATE][rows].float(), torch.full((int(rows.sum()), 1), 3 / 255))


# ------------------------------------------------------------------------------ 9. reward statistics

# (ground-truth success, reward R+, kept by the filter, valid) per row, and how many rows of each: the
# statistics below are counted by hand from this table.
ROW_KINDS = [
    ((True, True, True, True), 1),  # a true positive
    ((True, False, True, True), 2),  # false negatives the filter kept
    ((True, False, False, True), 1),  # a false negative the filter dropped
    ((False, True, True, True), 1),  # a false positive
    ((False, False, False, True), 3),  # true negatives the filter dropped
    ((False, False, True, True), 2),  # true negatives kept
    ((True, True, True, False), 1),  # invalid rows (no o_{t+1}): never counted
    ((False, False, False, False), 1),
    ((True, False, True, False), 1),
]


def statistics_inputs(kinds) -> tuple[torch.Tensor, ...]:
    """Ground truth 1-d: goal 3 + row/4, achieved at distance 0.5 (= epsilon: a success, the boundary) for
    the first success row, 0.25 for the other successes, 2 for failures."""
    rows = [kind for kind, n in kinds for _ in range(n)]
    success, positive, keep, valid = (torch.tensor(c) for c in zip(*rows, strict=True))
    goal = 3 + torch.arange(len(rows), dtype=torch.float32)[:, None] / 4
    distance = torch.where(success, 0.25, 2.0)
    distance[int(success.nonzero()[0])] = 0.5
    reward = torch.where(positive, 1.0, -1.0)
    return reward, goal + distance[:, None], goal, keep, valid


def test_ground_truth_success_is_distance_to_the_goal_at_most_epsilon():
    goal = torch.tensor([[3.0, -2.0], [3.0, -2.0], [3.0, -2.0], [1.0, 1.0]])
    achieved = goal + torch.tensor([[0.375, 0.5], [0.375, 0.5001], [0.0, 0.0], [0.0, -0.5]])  # |d| = 0.625...
    assert core.ground_truth_success(achieved, goal, 0.625).tolist() == [True, False, True, True]


def test_reward_statistics_count_each_kind_of_row():
    reward, gt_next, gt_goal, keep, valid = statistics_inputs(ROW_KINDS)
    cfg = make_policy(oracle_epsilon=0.5).config
    stats = core.reward_statistics(reward, gt_next, gt_goal, keep, valid, cfg)
    # 10 valid rows: 4 successes (3 of them R-), 6 failures (1 of them R+); 6 rewards agree with the truth;
    # the filter kept 3 successes (2 of them R-) and dropped 4 rows, 1 of them a success.
    expected = {
        "reward_accuracy": 6 / 10,
        "false_negative_rate": 3 / 4,
        "false_positive_rate": 1 / 6,
        "false_negative_rate_kept": 2 / 3,
        "frac_gt_positive": 4 / 10,
        "filtered_gt_success_rate": 1 / 4,
    }
    assert {k: round(float(v), 6) for k, v in stats.items()} == {k: round(v, 6) for k, v in expected.items()}


@pytest.mark.parametrize(
    "kinds, expected",
    [
        # one kept false negative and one false positive: each rate is 1 of 1, nothing filtered
        ([((True, False, True, True), 1), ((False, True, True, True), 1)], [0.0, 1.0, 1.0, 1.0, 0.5, 0.0]),
        # one dropped false negative and one false positive: no kept success, the one filtered row a success
        ([((True, False, False, True), 1), ((False, True, True, True), 1)], [0.0, 1.0, 1.0, 0.0, 0.5, 1.0]),
        # no valid success and nothing filtered: the empty rates are 0
        ([((False, False, True, True), 2), ((True, True, True, False), 1)], [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]),
    ],
)
def test_reward_statistics_rates_over_a_single_row_and_over_none(kinds, expected):
    reward, gt_next, gt_goal, keep, valid = statistics_inputs(kinds)
    cfg = make_policy(oracle_epsilon=0.5).config
    stats = core.reward_statistics(reward, gt_next, gt_goal, keep, valid, cfg)
    assert [float(v) for v in stats.values()] == expected


def test_loss_reports_reward_statistics_of_its_own_rewards_filter_and_valid_rows(monkeypatch):
    """The loss hands reward_statistics its reward, o_{t+1}'s ground truth, the chosen goal's, the filter's
    keep mask and next.valid (the recorded goal for every row: p_next = p_future = 0)."""
    policy = make_policy(p_next=0.0, p_future=0.0, oracle_epsilon=0.5)
    set_policy_weights(policy)
    batch = batch_of(OBS, NXT, GOALS, ACT)
    batch[core.NEXT_VALID] = torch.tensor([True, True, False, True, True, True])
    batch[core.GT_NEXT_ACHIEVED] = col(NXT)
    batch[core.GT_FUTURE_ACHIEVED] = col([9.0] * len(OBS))
    batch[core.GT_DESIRED] = col(GOALS)
    seen = {}
    original = core.reward_statistics

    def spy(reward, gt_next, gt_goal, keep, valid, config):
        seen.update(reward=reward, gt_next=gt_next, gt_goal=gt_goal, keep=keep, valid=valid)
        return original(reward, gt_next, gt_goal, keep, valid, config)

    monkeypatch.setattr(core, "reward_statistics", spy)
    _, stats = policy.forward(batch, generator=torch.Generator().manual_seed(0))
    assert torch.equal(seen["reward"], torch.where(torch.tensor(POSITIVE_ROWS), 1.0, -1.0))
    assert torch.equal(seen["gt_next"], col(NXT)) and torch.equal(seen["gt_goal"], col(GOALS))
    assert torch.equal(seen["valid"], batch[core.NEXT_VALID])
    assert seen["keep"].dtype == torch.bool and not bool(seen["keep"][2])
    # |NXT - GOALS| <= 0.5 on rows 0, 2, 3, 4; row 2 is invalid; row 4 (distance 0.1) is an oracle success
    # the indicator reward misses: 3 successes among 5 valid rows, 1 of them R-.
    assert stats["frac_gt_positive"] == pytest.approx(3 / 5)
    assert stats["false_negative_rate"] == pytest.approx(1 / 3)
