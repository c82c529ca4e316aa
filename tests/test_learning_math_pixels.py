"""The learning core on images and with n-step targets, against references computed here with plain torch ops.

Setup: one image key of 2 channels x 8x8 px (float32 frames in [0, 1), so the encoders' default statistics make
the normalisation the identity), one conv layer of 2 filters (3x3, stride 2, a 3x3 map), feature_dim 4,
hidden_dims=[4], 2-dim actions, random shifts of up to PAD = 1 pixel, T = 4 (gamma = 3/4, q_min = -4,
q_max = 4). Every network's weights are seeded and distinct (a target network is not its online copy), and the
references read them back: the conv (F.conv2d), ReLU or tanh, the "drq" projection (linear, LayerNorm, tanh),
the MLP heads, and the replicate-padded shift (F.pad + crop). A forward hook on each encoder's trunk counts the
frames it encodes: the spec asks for every distinct frame to be encoded once per encoder and update.
"""

import pytest
import torch
import torch.nn.functional as F
from lerobot.configs import FeatureType, PolicyFeature
from test_learning_math import (
    GOAL,
    STATE,
    T,
    batch_of,
    close,
    differs,
    linears,
    loss_and_stats,
    make_policy,
    mlp_ref,
    pi_ref,
    q_ref,
    set_policy_weights,
    weights,
)
from torch import Tensor, nn

from lerobot_indicator.keys import goal_key
from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy
from lerobot_indicator.policy.networks_indicator_ddpg import ObservationEncoder

IMG = "observation.images.cam"
GOAL_IMG = goal_key(IMG)
C, H, W = 2, 8, 8
PAD = 1
B = 6
GAMMA = (T - 1) / T

# ----------------------------------------------------------------------------------------------- helpers


def image_policy(image_encoder: str = "drq", **kwargs) -> IndicatorDDPGPolicy:
    """A tiny image policy whose four networks (and so the online and target encoders) have distinct seeded
    weights; the target critic's last layer is scaled down so that TD targets stay inside (q_min, q_max). The
    paper's preset (one-step target, no inverse dynamics, Q the MLP's output) unless a test names others."""
    cfg = IndicatorDDPGConfig(
        device="cpu",
        **{
            "preset": "paper",
            "observation_keys": [IMG],
            "horizon": T,
            "hidden_dims": [4],
            "conv_channels": [2],
            "conv_kernel_size": 3,
            "conv_strides": [2],
            "feature_dim": 4,
            "augment_pad": PAD,
            "conv_precision": "float32",
            "image_encoder": image_encoder,
            **kwargs,
        },
    )
    cfg.input_features = {k: PolicyFeature(FeatureType.VISUAL, (C, H, W)) for k in (IMG, GOAL_IMG)}
    cfg.output_features = {"action": PolicyFeature(FeatureType.ACTION, (2,))}
    policy = IndicatorDDPGPolicy(cfg)
    nets = (policy.actor, policy.critic, policy.target_actor, policy.target_critic)
    with torch.no_grad():
        for seed, net in enumerate(nets):
            gen = torch.Generator().manual_seed(200 + seed)
            for p in net.parameters():
                p.copy_(torch.randn(p.shape, generator=gen) * 0.5)
        linears(policy.target_critic)[-1].weight.mul_(0.3)
    return policy


def frames(seed: int, n: int = B) -> Tensor:
    """``n`` distinct random frames (no two rows bit-equal)."""
    return torch.rand(n, C, H, W, generator=torch.Generator().manual_seed(seed))


def shifted(x: Tensor, shift: Tensor | None) -> Tensor:
    """Row i translated by shift[:, i] = (dy, dx): pad PAD pixels replicating the edges, crop back at +dy, +dx."""
    if shift is None:
        return x
    rows = []
    for i in range(x.shape[0]):
        padded = F.pad(x[i : i + 1], (PAD, PAD, PAD, PAD), mode="replicate")
        dy, dx = PAD + int(shift[0, i]), PAD + int(shift[1, i])
        rows.append(padded[:, :, dy : dy + H, dx : dx + W])
    return torch.cat(rows)


def enc_ref(encoder: ObservationEncoder, x: Tensor, shift: Tensor | None, drq: bool = True) -> Tensor:
    """The encoder from its read-back weights: conv -> ReLU -> linear -> LayerNorm -> tanh ("drq"), or
    conv -> tanh -> flatten ("paper")."""
    conv = encoder.conv[0]
    h = F.conv2d(shifted(x, shift), conv.weight.detach(), conv.bias.detach(), stride=2)
    if not drq:
        return torch.tanh(h).flatten(1)
    lin, norm = encoder.trunk[1], encoder.trunk[2]
    # The projection reads the feature maps in (H, W, C) order: their channels-last memory order.
    h = torch.relu(h).permute(0, 2, 3, 1).flatten(1) @ lin.weight.detach().T + lin.bias.detach()
    return torch.tanh(F.layer_norm(h, (h.shape[1],), norm.weight.detach(), norm.bias.detach()))


def count_frames(encoder: ObservationEncoder) -> list[int]:
    """The number of frames of each conv pass of ``encoder`` (appended by a forward hook on its trunk)."""
    seen: list[int] = []
    encoder.trunk.register_forward_hook(lambda _m, inputs, _out: seen.append(int(inputs[0].shape[0])))
    return seen


def record_shifts(monkeypatch) -> list[Tensor]:
    """The shifts ``encode_batch`` draws (one (2, B) tensor per call)."""
    seen: list[Tensor] = []
    original = core.draw_shifts

    def spy(n, pad, device):
        out = original(n, pad, device)
        seen.append(out)
        return out

    monkeypatch.setattr(core, "draw_shifts", spy)
    return seen


def encode(policy: IndicatorDDPGPolicy, obs, nxt, goal, goal_is_next, transition_next=None) -> core.Features:
    return core.encode_batch(
        {IMG: obs},
        {IMG: nxt},
        {IMG: goal},
        goal_is_next,
        policy.actor,
        policy.critic,
        policy.target_actor,
        policy.target_critic,
        policy.config,
        None if transition_next is None else {IMG: transition_next},
    )


def goals_with_next(nxt: Tensor, goal_is_next: list[bool]) -> tuple[Tensor, Tensor]:
    """Goals that are o_{t+1} (bit for bit) where ``goal_is_next``, other distinct frames elsewhere."""
    is_next = torch.tensor(goal_is_next)
    goal = frames(99)
    goal[is_next] = nxt[is_next]
    return goal, is_next


def inverse_ref(critic: nn.Module, features: Tensor) -> Tensor:
    """tanh(MLP(features)) of the critic's inverse-dynamics head, from its read-back weights."""
    layers = [(m.weight.detach(), m.bias.detach()) for m in critic.inverse if isinstance(m, nn.Linear)]
    return torch.tanh(mlp_ref(layers, features))


# One mix of goals that are o_{t+1} and goals that are not, one with a single goal that is not (the deduped
# index list has one entry), every goal o_{t+1} (nothing left to encode) and none.
GOAL_IS_NEXT = [
    [True, False, True, False, False, True],
    [True, True, True, False, True, True],
    [True] * B,
    [False] * B,
]


# ------------------------------------------------------------------------ 1. encode_batch, shared encoder


@pytest.mark.parametrize("goal_is_next", GOAL_IS_NEXT)
def test_shared_encoder_features_and_conv_passes_over_distinct_frames(monkeypatch, goal_is_next):
    """ "drq": critic = [enc(o_t), enc(g)] with gradients, actor = the same values detached, both targets =
    [enc(o_{t+1}), enc(g)] from the online encoder without gradients, transition = [enc(o_t), enc(o_{t+1})];
    every frame of transition i shifted by the same shift[:, i]. Each distinct frame is encoded once: o_t, the
    goals, and the o_{t+1} that are goals in one pass with gradients (2B frames), the other o_{t+1} (which only
    the targets read) in a second pass without."""
    policy = image_policy()
    obs, nxt = frames(1), frames(2)
    goal, is_next = goals_with_next(nxt, goal_is_next)
    shifts = record_shifts(monkeypatch)
    online, target = count_frames(policy.critic.encoder), count_frames(policy.target_critic.encoder)
    torch.manual_seed(5)
    f = encode(policy, obs, nxt, goal, is_next)

    (shift,) = shifts
    assert shift.shape == (2, B) and bool((shift != 0).any()) and int(shift.abs().max()) <= PAD
    enc = policy.critic.encoder
    e_o, e_next, e_g = (enc_ref(enc, x, shift) for x in (obs, nxt, goal))
    close(f.critic, torch.cat([e_o, e_g], 1))
    assert f.critic.requires_grad
    close(f.actor, torch.cat([e_o, e_g], 1))
    assert not f.actor.requires_grad
    for target_features in (f.target_critic, f.target_actor):
        close(target_features, torch.cat([e_next, e_g], 1))
        assert not target_features.requires_grad
    close(f.transition, torch.cat([e_o, e_next], 1))
    assert f.transition.requires_grad
    assert f.target_critic_obs is None  # filter_q="online": no target-critic view of (o_t, g)
    assert differs(f.critic, torch.cat([enc_ref(enc, obs, None), enc_ref(enc, goal, None)], 1))
    rest = int((~is_next).sum())
    assert online == [2 * B] + ([rest] if rest else []) and target == []


@pytest.mark.parametrize("goal_is_next", GOAL_IS_NEXT)
def test_shared_encoder_gradient_reaches_goals_that_are_o_next(monkeypatch, goal_is_next):
    """The encoder's gradient from a loss on the critic's [enc(o_t), enc(g)] equals the reference encoder's,
    also where g is o_{t+1} and its encoding comes from o_{t+1}'s rows; o_{t+1} that are not goals add none."""
    policy = image_policy()
    obs, nxt = frames(1), frames(2)
    goal, is_next = goals_with_next(nxt, goal_is_next)
    shifts = record_shifts(monkeypatch)
    torch.manual_seed(5)
    f = encode(policy, obs, nxt, goal, is_next)
    (shift,) = shifts
    enc = policy.critic.encoder
    weight = torch.randn(f.critic.shape, generator=torch.Generator().manual_seed(3))
    params = [enc.conv[0].weight, enc.conv[0].bias, enc.trunk[1].weight]
    got = torch.autograd.grad((f.critic * weight).sum(), params)

    def ref_loss() -> Tensor:
        conv, lin, norm = enc.conv[0], enc.trunk[1], enc.trunk[2]

        def e(x: Tensor) -> Tensor:
            h = F.conv2d(shifted(x, shift), conv.weight, conv.bias, stride=2)
            h = torch.relu(h).permute(0, 2, 3, 1).flatten(1) @ lin.weight.T + lin.bias
            return torch.tanh(F.layer_norm(h, (h.shape[1],), norm.weight, norm.bias))

        return (torch.cat([e(obs), e(goal)], 1) * weight).sum()

    want = torch.autograd.grad(ref_loss(), params)
    for g, w in zip(got, want, strict=True):
        close(g, w)


def test_every_goal_is_encoded_while_compiling(monkeypatch):
    """Under torch.compile (static shapes) no goal reuses o_{t+1}'s encoding: one pass over 3B frames, the
    same values as the deduped pass."""
    policy = image_policy()
    obs, nxt = frames(1), frames(2)
    goal, is_next = goals_with_next(nxt, GOAL_IS_NEXT[0])
    shifts = record_shifts(monkeypatch)
    online = count_frames(policy.critic.encoder)
    monkeypatch.setattr(torch.compiler, "is_compiling", lambda: True)
    torch.manual_seed(5)
    f = encode(policy, obs, nxt, goal, is_next)
    (shift,) = shifts
    enc = policy.critic.encoder
    e_o, e_next, e_g = (enc_ref(enc, x, shift) for x in (obs, nxt, goal))
    close(f.critic, torch.cat([e_o, e_g], 1))
    close(f.target_critic, torch.cat([e_next, e_g], 1))
    close(f.transition, torch.cat([e_o, e_next], 1))
    assert online == [3 * B]


@pytest.mark.parametrize("filter_q", ["online", "target"])
def test_target_encoder_encodes_the_target_frames_and_the_filter_view(monkeypatch, filter_q):
    """target_encoder=True: both targets = [enc'(o_{t+1}), enc'(g)] from the target critic's own (EMA) encoder,
    the online networks keep the online encoder; filter_q="target" adds the target critic's
    [enc'(o_t), enc'(g)], encoded in the same pass (else it is None and o_t is not encoded by enc')."""
    policy = image_policy(target_encoder=True, filter_q=filter_q)
    obs, nxt = frames(1), frames(2)
    goal, is_next = goals_with_next(nxt, GOAL_IS_NEXT[0])
    rest = int((~is_next).sum())
    shifts = record_shifts(monkeypatch)
    online, target = count_frames(policy.critic.encoder), count_frames(policy.target_critic.encoder)
    torch.manual_seed(5)
    f = encode(policy, obs, nxt, goal, is_next)
    (shift,) = shifts
    enc, enc_t = policy.critic.encoder, policy.target_critic.encoder
    assert enc_t is policy.target_actor.encoder and enc_t is not enc
    e_o, e_next, e_g = (enc_ref(enc, x, shift) for x in (obs, nxt, goal))
    t_o, t_next, t_g = (enc_ref(enc_t, x, shift) for x in (obs, nxt, goal))
    close(f.critic, torch.cat([e_o, e_g], 1))
    close(f.actor, torch.cat([e_o, e_g], 1))
    close(f.transition, torch.cat([e_o, e_next], 1))
    for target_features in (f.target_critic, f.target_actor):
        close(target_features, torch.cat([t_next, t_g], 1))
        assert not target_features.requires_grad
    assert differs(f.target_critic, torch.cat([e_next, e_g], 1))
    assert online == [2 * B, rest]
    if filter_q == "target":
        close(f.target_critic_obs, torch.cat([t_o, t_g], 1))
        assert target == [2 * B + rest]
    else:
        assert f.target_critic_obs is None
        assert target == [B + rest]


def test_filter_on_the_target_critic_without_target_encoder_sees_the_online_features(monkeypatch):
    """filter_q="target" with the shared encoder and no target_encoder: the target critic's view of (o_t, g)
    is the online encoder's [enc(o_t), enc(g)] without gradients, from the one conv pass."""
    policy = image_policy(filter_q="target")
    obs, nxt = frames(1), frames(2)
    goal, is_next = goals_with_next(nxt, GOAL_IS_NEXT[0])
    shifts = record_shifts(monkeypatch)
    online = count_frames(policy.critic.encoder)
    torch.manual_seed(5)
    f = encode(policy, obs, nxt, goal, is_next)
    (shift,) = shifts
    enc = policy.critic.encoder
    close(f.target_critic_obs, torch.cat([enc_ref(enc, obs, shift), enc_ref(enc, goal, shift)], 1))
    assert not f.target_critic_obs.requires_grad
    assert online == [2 * B, int((~is_next).sum())]


def test_transition_pairs_o_t_with_o_next_when_the_target_bootstraps_from_another_frame(monkeypatch):
    """With ``transition_next`` (n-step targets): the targets use the bootstrap frame o_{t+n} (and a goal that
    is that frame reuses its encoding), the inverse-dynamics features are [enc(o_t), enc(o_{t+1})]; one pass
    over o_t, o_{t+1}, o_{t+n} and the other goals."""
    policy = image_policy(inverse_dynamics=1.0)
    obs, nxt, boot = frames(1), frames(2), frames(3)
    goal, is_next = goals_with_next(boot, GOAL_IS_NEXT[0])
    shifts = record_shifts(monkeypatch)
    online = count_frames(policy.critic.encoder)
    torch.manual_seed(5)
    f = encode(policy, obs, boot, goal, is_next, transition_next=nxt)
    (shift,) = shifts
    enc = policy.critic.encoder
    e_o, e_next, e_boot, e_g = (enc_ref(enc, x, shift) for x in (obs, nxt, boot, goal))
    close(f.critic, torch.cat([e_o, e_g], 1))
    close(f.target_critic, torch.cat([e_boot, e_g], 1))
    close(f.transition, torch.cat([e_o, e_next], 1))
    assert online == [3 * B, int((~is_next).sum())]


# ---------------------------------------------------------------------- 2. encode_batch, paper encoders


@pytest.mark.parametrize("filter_q", ["online", "target"])
def test_paper_encoders_each_encode_their_own_network_frames(monkeypatch, filter_q):
    """ "paper": each of the four networks has its own encoder: critic = [encQ(o_t), encQ(g)], actor =
    [encPi(o_t), encPi(g)], target critic / actor = [encQ'(o_{t+1}), encQ'(g)] / [encPi'(o_{t+1}), encPi'(g)],
    all shifted per transition (augment_pad = 1 here); no transition features; filter_q="target" adds
    [encQ'(o_t), encQ'(g)]. The targets reuse o_{t+1}'s encoding for goals that are o_{t+1}."""
    policy = image_policy("paper", filter_q=filter_q)
    obs, nxt = frames(1), frames(2)
    goal, is_next = goals_with_next(nxt, GOAL_IS_NEXT[0])
    rest = int((~is_next).sum())
    shifts = record_shifts(monkeypatch)
    nets = (policy.critic, policy.actor, policy.target_critic, policy.target_actor)
    assert len({id(n.encoder) for n in nets}) == 4
    counts = [count_frames(n.encoder) for n in nets]
    torch.manual_seed(5)
    f = encode(policy, obs, nxt, goal, is_next)
    (shift,) = shifts
    assert bool((shift != 0).any())

    def pair(net, first):
        return torch.cat(
            [enc_ref(net.encoder, first, shift, drq=False), enc_ref(net.encoder, goal, shift, False)], 1
        )

    close(f.critic, pair(policy.critic, obs))
    assert f.critic.requires_grad
    close(f.actor, pair(policy.actor, obs))
    assert f.actor.requires_grad
    close(f.target_critic, pair(policy.target_critic, nxt))
    close(f.target_actor, pair(policy.target_actor, nxt))
    assert f.transition is None
    assert differs(
        f.critic, torch.cat([enc_ref(policy.critic.encoder, x, None, False) for x in (obs, goal)], 1)
    )
    assert differs(
        f.actor, torch.cat([enc_ref(policy.actor.encoder, x, None, False) for x in (obs, goal)], 1)
    )
    if filter_q == "target":
        close(f.target_critic_obs, pair(policy.target_critic, obs))
    else:
        assert f.target_critic_obs is None
    target_obs = B if filter_q == "target" else 0
    assert counts == [[2 * B], [2 * B], [target_obs + B + rest], [B + rest]]


# ------------------------------------------------------------------------- 3. encode_batch, no images


def test_state_inputs_draw_no_shift_from_the_global_rng():
    """State keys have no image to shift: a state update consumes nothing from torch's global RNG (which the
    trainers seed), so the random numbers drawn after it are those drawn without it."""
    policy = make_policy(filter=False)
    set_policy_weights(policy)
    assert policy.config.augment_pad > 0  # the "drq" preset's pad: only the absence of images stops a draw
    batch = batch_of([0.3, -0.8], [0.5, -0.4], [0.5, 0.2], [0.2, -0.5])
    torch.manual_seed(11)
    expected = torch.rand(4)
    torch.manual_seed(11)
    policy.forward(batch, generator=torch.Generator().manual_seed(0))
    assert torch.equal(torch.rand(4), expected)


def test_image_loss_creates_its_tensors_on_the_batch_device(monkeypatch):
    """Every tensor the loss creates lives on the batch's device, not on torch's default device: with the
    default device set to another one ("meta" here, as a CUDA batch under a CPU default), the loss of an
    image policy (shifts, the all-valid mask of a batch without next.valid) is the same."""
    policy = image_policy(filter=False)
    obs, nxt = frames(1), frames(2)
    goal, _ = goals_with_next(nxt, GOAL_IS_NEXT[0])
    batch = {
        IMG: obs,
        core.NEXT + IMG: nxt,
        core.FUTURE + IMG: frames(4),
        GOAL_IMG: goal,
        "action": torch.rand(B, 2, generator=torch.Generator().manual_seed(6)) * 2 - 1,
        core.HAS_FUTURE: torch.ones(B, dtype=torch.bool),
    }

    def loss() -> Tensor:
        torch.manual_seed(5)
        total, _ = loss_and_stats(policy, batch, seed=3)
        return total

    expected = loss()
    with torch.device("meta"):
        total = loss()
    assert total.device.type == "cpu"
    close(total, expected)


# --------------------------------------------------------------------------------- 4. n_step_return


def test_n_step_return_sums_discounted_path_rewards_up_to_the_episode_end():
    """sum_{i=1..n'} gamma^(i-1) r_{t+i}, discount gamma^n' and bootstrap frame o_{t+n'} = the path's last entry,
    n' = 1 + #valid path steps, for n = 4 and n' = 4, 3, 2, 1. Each r_{t+i} (i >= 2) is ``step_reward`` of the
    path frame o_{t+i} with its ground truth; steps past the episode end add nothing (their rewards here are
    large on purpose). Rewards other than +-1 tell r from 1/r."""
    cfg = make_policy(n_step=4).config
    g = GAMMA
    assert cfg.gamma == g
    first = torch.tensor([0.5, -2.0, 3.0, 0.25])
    path = torch.tensor([[2.0, -4.0, 0.5], [-0.5, 8.0, 100.0], [4.0, 100.0, 100.0], [100.0, 100.0, 100.0]])[
        :, :, None
    ]
    valid = torch.tensor(
        [[True, True, True], [True, True, False], [True, False, False], [False, False, False]]
    )
    gt_path = path + 1000.0
    batch = {core.PATH + STATE: path, core.PATH_VALID: valid, core.GT_PATH_ACHIEVED: gt_path}
    calls: list[tuple[Tensor, Tensor | None]] = []

    def step_reward(frames: dict[str, Tensor], gt: Tensor | None) -> Tensor:
        calls.append((frames[STATE], gt))
        return frames[STATE][:, 0]

    returns, discount, bootstrap = core.n_step_return(batch, [STATE], first, step_reward, cfg)
    expected = torch.tensor(
        [
            0.5 + g * 2.0 + g**2 * -4.0 + g**3 * 0.5,
            -2.0 + g * -0.5 + g**2 * 8.0,
            3.0 + g * 4.0,
            0.25,
        ]
    )
    close(returns, expected)
    close(discount, torch.tensor([g**4, g**3, g**2, g]))
    assert list(bootstrap) == [STATE] and torch.equal(bootstrap[STATE], path[:, 2])
    assert len(calls) == 3
    for i, (frame, gt) in enumerate(calls):
        assert torch.equal(frame, path[:, i]) and torch.equal(gt, gt_path[:, i])
    assert torch.equal(first, torch.tensor([0.5, -2.0, 3.0, 0.25]))  # r_{t+1} itself is left as it was

    calls.clear()
    del batch[core.GT_PATH_ACHIEVED]
    returns_no_gt, _, _ = core.n_step_return(batch, [STATE], first, step_reward, cfg)
    close(returns_no_gt, expected)
    assert [gt for _, gt in calls] == [None, None, None]


def test_n_step_oracle_loss_reads_the_path_ground_truth(monkeypatch):
    """Through the loss with reward="oracle", n = 2: r_{t+1} from o_{t+1}'s ground truth, r_{t+2} from the path
    frame's (row 0 reaches the goal at t+2 only, row 1 never, row 2's path is past the episode end); y =
    clip(r_{t+1} + gamma r_{t+2} + gamma^n' Q'(o_{t+n'}, g, pi'(o_{t+n'}, g)))."""
    policy = make_policy(
        p_next=0.0, p_future=0.0, filter=False, n_step=2, reward="oracle", oracle_epsilon=0.05
    )
    set_policy_weights(policy)
    with torch.no_grad():
        linears(policy.target_critic)[-1].weight.mul_(0.3)
    batch = batch_of([0.0, 0.0, 0.3], [0.1, 0.2, 0.4], [0.5, 0.5, 0.5], [0.1, 0.1, -0.2])
    batch[core.PATH + STATE] = torch.tensor([[[0.3]], [[0.9]], [[0.4]]])
    batch[core.PATH_VALID] = torch.tensor([[True], [True], [False]])
    batch[core.GT_NEXT_ACHIEVED] = torch.tensor([[0.1], [0.2], [0.52]])
    batch[core.GT_FUTURE_ACHIEVED] = torch.tensor([[4.0], [4.0], [4.0]])
    batch[core.GT_DESIRED] = torch.tensor([[0.5], [0.5], [0.5]])
    batch[core.GT_PATH_ACHIEVED] = torch.tensor([[[0.52]], [[0.9]], [[0.52]]])
    _, stats = policy.forward(batch, generator=torch.Generator().manual_seed(0))
    g, o, a, boot = batch[GOAL], batch[STATE], batch["action"], batch[core.PATH + STATE][:, -1]
    tpa, tqc = weights(policy.target_actor), weights(policy.target_critic)
    next_q = q_ref(tqc, boot, g, pi_ref(tpa, boot, g))
    y = torch.tensor([-1 + GAMMA, -1 - GAMMA, 1.0]) + torch.tensor([GAMMA**2, GAMMA**2, GAMMA]) * next_q
    assert bool((y.abs() < 4).all()), "this test wants y strictly inside the bounds"
    q = q_ref(weights(policy.critic), o, g, a)
    assert stats["critic_loss"] == pytest.approx(((q - y) ** 2).mean().item(), rel=1e-5)


# ------------------------------------------------------------------- 5. the image loss, n-step targets


def image_batch(n_step: int, path_valid: list[bool]) -> dict[str, Tensor]:
    """o_t, o_{t+1}, a future frame, a recorded goal, actions, next.valid False on row 4; with n_step = 2 the
    path o_{t+2}, which holds o_T = o_{t+1} where it is past the episode end (``path_valid`` False)."""
    nxt = frames(2)
    batch = {
        IMG: frames(1),
        core.NEXT + IMG: nxt,
        core.FUTURE + IMG: frames(4),
        GOAL_IMG: frames(5),
        "action": torch.rand(B, 2, generator=torch.Generator().manual_seed(6)) * 2 - 1,
        core.HAS_FUTURE: torch.ones(B, dtype=torch.bool),
        core.NEXT_VALID: torch.tensor([True, True, True, True, False, True]),
    }
    if n_step > 1:
        valid = torch.tensor(path_valid)
        batch[core.PATH + IMG] = torch.where(valid[:, None, None, None], frames(3), nxt)[:, None]
        batch[core.PATH_VALID] = valid[:, None]
    return batch


PATH_VALID = [True, False, True, True, False, True]
RELABEL_SEED = 1  # with p_next = 0.5: goals o_{t+1} on rows 1, 2, 4, future frames on rows 0, 3, 5


@pytest.mark.parametrize(
    "n_step, inverse_dynamics, p_next",
    [(2, 0.5, 1.0), (2, 0.0, 1.0), (1, 0.5, 0.5), (1, 0.0, 0.5)],
    ids=["n2-inverse", "n2", "n1-inverse", "n1"],
)
def test_image_loss_matches_the_reference(monkeypatch, n_step, inverse_dynamics, p_next):
    """The whole "drq" loss from the reference encodings (shared encoder, one shift per transition):
    critic_loss = mean_valid (Q(o, g, a) - y)^2 with y = R + discount Q'([enc(o_b), enc(g)], pi'(.)), o_b the
    bootstrap frame (o_{t+2} with n = 2 where the path is inside the episode, else o_{t+1}); actor_loss =
    mean_valid (-Q(o, g, pi) + mean_a pi^2); inverse loss = mean_valid mean_a (tanh(g([enc(o_t),
    enc(o_{t+1})])) - a)^2 (o_{t+1}, not the bootstrap frame), total = critic + actor + inverse_dynamics *
    inverse. n = 2 uses goal = o_{t+1} for every row (R+ now, R- at t+2); n = 1 a mix of o_{t+1} and
    future goals. Each distinct frame encoded once: o_t, o_{t+1} only where the inverse loss needs it beside
    another bootstrap frame, the goals, and the bootstrap frames that are goals in one pass with gradients; the
    other bootstrap frames in a second pass without, unless the one-step inverse loss trains through them."""
    policy = image_policy(
        filter=False, n_step=n_step, inverse_dynamics=inverse_dynamics, p_next=p_next, p_future=1.0 - p_next
    )
    batch = image_batch(n_step, PATH_VALID)
    shifts = record_shifts(monkeypatch)
    online = count_frames(policy.critic.encoder)
    torch.manual_seed(5)
    total, stats = loss_and_stats(policy, batch, seed=RELABEL_SEED)
    (shift,) = shifts
    obs, nxt, a = batch[IMG], batch[core.NEXT + IMG], batch["action"]
    valid = batch[core.NEXT_VALID]
    if n_step == 1:
        source = core.relabel_sources(
            batch[core.HAS_FUTURE], policy.config, None, torch.Generator().manual_seed(RELABEL_SEED)
        )
        is_next = source.source == core.SOURCE_NEXT
        assert 0 < int(is_next.sum()) < B
        goal = torch.where(is_next[:, None, None, None], nxt, batch[core.FUTURE + IMG])
        boot = nxt
        returns = torch.where(is_next, 1.0, -1.0)
        discount = torch.full((B,), GAMMA)
        not_boot = ~is_next
    else:
        path_valid = torch.tensor(PATH_VALID)
        goal, boot = nxt, batch[core.PATH + IMG][:, -1]
        returns = torch.where(path_valid, 1.0 - GAMMA, 1.0)
        discount = torch.where(path_valid, GAMMA**2, GAMMA)
        not_boot = path_valid
    enc = policy.critic.encoder
    e_o, e_g, e_boot, e_next = (enc_ref(enc, x, shift) for x in (obs, goal, boot, nxt))
    features, target_features = torch.cat([e_o, e_g], 1), torch.cat([e_boot, e_g], 1)
    qc, pa = weights(policy.critic), weights(policy.actor)
    tqc, tpa = weights(policy.target_critic), weights(policy.target_actor)
    q = mlp_ref(qc, torch.cat([features, a], 1)).squeeze(1)
    next_q = mlp_ref(tqc, torch.cat([target_features, torch.tanh(mlp_ref(tpa, target_features))], 1)).squeeze(
        1
    )
    y = returns + discount * next_q
    assert bool((y.abs() < 4).all()), "this test wants y strictly inside the bounds"
    critic_loss = ((q - y) ** 2)[valid].mean()
    pi = torch.tanh(mlp_ref(pa, features))
    actor_loss = (-mlp_ref(qc, torch.cat([features, pi], 1)).squeeze(1) + (pi**2).mean(1))[valid].mean()
    assert stats["critic_loss"] == pytest.approx(critic_loss.item(), rel=1e-5)
    assert stats["actor_loss"] == pytest.approx(actor_loss.item(), rel=1e-5)
    expected_total = critic_loss + actor_loss
    extra = 0
    if inverse_dynamics:
        per_row = (inverse_ref(policy.critic, torch.cat([e_o, e_next], 1)) - a) ** 2
        inverse = per_row.mean(1)[valid].mean()
        assert differs(inverse, per_row.mean(1).mean(), margin=1e-4)  # next.valid masks the invalid row
        assert stats["inverse_dynamics_loss"] == pytest.approx(inverse.item(), rel=1e-5)
        expected_total = expected_total + inverse_dynamics * inverse
        extra = B if n_step > 1 else 0
    else:
        assert "inverse_dynamics_loss" not in stats
    close(total, expected_total)
    rest = int(not_boot.sum())
    if inverse_dynamics and n_step == 1:
        assert online == [2 * B + rest]
    else:
        assert online == [2 * B + extra] + ([rest] if rest else [])
