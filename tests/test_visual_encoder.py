"""The image path: the shared ("drq") encoder, random shifts, folded normalisation, one encoding per frame."""

from pathlib import Path

import pytest
import torch
from test_indicator_core import _losses

from benchmarks.speed.updates import STATE_FEATURES, make_batch, make_policy, rgbd_features
from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy import networks_indicator_ddpg as networks
from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfigError
from lerobot_indicator.policy.networks_indicator_ddpg import (
    as_float,
    draw_shifts,
    native_bf16,
    pack_frames,
    random_shift,
    use_bf16,
)

SMALL = {"hidden_dims": [16, 16, 16], "conv_precision": "float32"}
RGB, DEPTH = "observation.images.front", "observation.images.front_depth"


def policy_and_batch(size: int = 24, batch_size: int = 6, **config):
    torch.manual_seed(0)
    features = rgbd_features(size)
    policy = make_policy(features, **{**SMALL, **config})
    stats = {
        RGB: {
            "mean": torch.tensor([0.4, 0.5, 0.6]).view(3, 1, 1),
            "std": torch.tensor([0.2, 0.3, 0.1]).view(3, 1, 1),
        },
        DEPTH: {"mean": torch.full((1, 1, 1), 900.0), "std": torch.full((1, 1, 1), 400.0)},
    }
    policy.set_observation_stats(stats)
    return policy, make_batch(features, batch_size)


def test_presets_fill_the_conv_fields_and_explicit_values_win():
    paper, _ = policy_and_batch(image_encoder="paper")
    assert paper.config.conv_channels == [16, 32, 64, 64] and paper.config.augment_pad == 0
    assert not paper.config.shared_encoder and paper.actor.encoder is not paper.critic.encoder
    drq, _ = policy_and_batch(conv_channels=[8, 8, 8, 8])
    assert drq.config.conv_channels == [8, 8, 8, 8] and drq.config.augment_pad == 4
    assert drq.config.shared_encoder and drq.actor.encoder is drq.critic.encoder
    assert drq.target_actor.encoder is drq.target_critic.encoder is not drq.critic.encoder
    with pytest.raises(IndicatorDDPGConfigError, match="one stride per conv layer"):
        policy_and_batch(conv_channels=[8, 8])
    with pytest.raises(
        ValueError, match=r"images of 16x16 px are too small for the 'drq' encoder's conv layers"
    ):
        policy_and_batch(size=16)
    # The inverse-dynamics loss trains the shared encoder: the paper's separate encoders have none.
    with pytest.raises(
        IndicatorDDPGConfigError, match="inverse_dynamics=1.0 trains the shared image encoder"
    ):
        policy_and_batch(image_encoder="paper", inverse_dynamics=1.0)
    assert policy_and_batch(inverse_dynamics=1.0)[0].critic.inverse is not None
    with pytest.raises(
        ValueError, match=r"keys \['observation.state'\] hold no image: use inverse_dynamics=0"
    ):
        make_policy(STATE_FEATURES, inverse_dynamics=1.0)


@pytest.mark.parametrize("dtype", [torch.float32, torch.bfloat16, torch.uint8])
def test_random_shift_is_a_clamped_translation_shared_by_all_channels(dtype):
    """RGB and depth packed as one frame's channels (``pack_frames``) move together; pixels are gathered as
    2 int64 words (float32 x 4), 1 int64 word (bfloat16 x 4) or 4 bytes (uint8 x 4), all exact."""
    b, h, w, pad = 64, 9, 11, 2
    ys, xs = torch.meshgrid(torch.arange(h), torch.arange(w), indexing="ij")
    rgb = (ys * w + xs).to(torch.uint8).expand(b, 3, h, w).contiguous()
    depth = (100 + ys * w + xs).float().expand(b, 1, h, w).contiguous()  # exact in every dtype tested
    packed = pack_frames(
        [{"rgb": rgb[: b // 2], "d": depth[: b // 2]}, {"rgb": rgb[b // 2 :], "d": depth[b // 2 :]}],
        ["rgb", "d"],
        dtype,
    )
    assert packed.shape == (b, 4, h, w) and packed.dtype == dtype
    assert torch.equal(packed[:, :3].float(), rgb.float()) and torch.equal(packed[:, 3:].float(), depth)
    torch.manual_seed(0)
    out = random_shift(packed, draw_shifts(b, pad, rgb.device))
    assert out.dtype == dtype and out.is_contiguous(memory_format=torch.channels_last)
    seen = set()
    for i in range(b):
        # The centre pixel tells the shift; every pixel must be the input at the clamped offset.
        centre = int(out[i, 3, h // 2, w // 2]) - 100
        dy, dx = centre // w - h // 2, centre % w - w // 2
        assert abs(dy) <= pad and abs(dx) <= pad
        rows = (torch.arange(h) + dy).clamp(0, h - 1)
        cols = (torch.arange(w) + dx).clamp(0, w - 1)
        expected = (rows[:, None] * w + cols[None, :]).float()
        assert torch.equal(out[i, 3].float(), expected + 100)
        for c in range(3):
            assert torch.equal(out[i, c].float(), expected)  # RGB moved with the depth
        seen.add((dy, dx))
    assert len(seen) > 10  # shifts differ between frames


def test_drq_folds_normalisation_into_the_first_conv_for_uint8_and_float_frames():
    policy, batch = policy_and_batch()
    enc = policy.critic.encoder
    obs = {RGB: batch[RGB], DEPTH: batch[DEPTH]}
    folded = enc.conv_features([obs])
    as_floats = enc.conv_features([{k: as_float(v) for k, v in obs.items()}])
    explicit = enc.conv(torch.cat([enc.standardize(k, as_float(v)) for k, v in obs.items()], dim=1))
    assert folded.is_contiguous(memory_format=torch.channels_last)
    torch.testing.assert_close(folded, explicit, atol=1e-4, rtol=1e-4)
    torch.testing.assert_close(as_floats, explicit, atol=1e-4, rtol=1e-4)


def test_shared_encoder_is_trained_by_the_critic_loss_only_and_listed_once():
    policy, batch = policy_and_batch()
    params = policy.get_optim_params()[0]["params"]
    assert len(params) == len({id(p) for p in params})
    encoder_ids = {id(p) for p in policy.critic.encoder.parameters()}
    assert encoder_ids <= {id(p) for p in params}
    _, critic_loss, actor_loss = _losses(policy, batch)
    conv_weight = policy.critic.encoder.conv[0].weight
    (actor_grad,) = torch.autograd.grad(actor_loss, [conv_weight], retain_graph=True, allow_unused=True)
    assert actor_grad is None
    actor_head = policy.actor.net[0].weight
    assert torch.autograd.grad(actor_loss, [actor_head], retain_graph=True)[0].abs().sum() > 0
    assert torch.autograd.grad(critic_loss, [conv_weight])[0].abs().sum() > 0


@pytest.mark.parametrize("image_encoder", ["drq", "paper"])
def test_reusing_o_next_encoding_for_goals_gives_the_same_loss(image_encoder, monkeypatch):
    policy, batch = policy_and_batch(image_encoder=image_encoder, augment_pad=0, batch_size=32)
    # Make some recorded goals equal to o_{t+1} too, so reuse and re-encoding cover the same frames.
    for key in (RGB, DEPTH):
        batch[core.goal_key(key)][:8] = batch[core.NEXT + key][:8]
    reused, stats = policy.forward(batch, generator=torch.Generator().manual_seed(3))
    assert 0.3 < stats["frac_goal_next"] < 0.8
    monkeypatch.setattr(torch.compiler, "is_compiling", lambda: True)  # the path that encodes every goal
    every_goal, stats_all = policy.forward(batch, generator=torch.Generator().manual_seed(3))
    torch.testing.assert_close(reused, every_goal, rtol=1e-5, atol=1e-5)
    assert stats == pytest.approx(stats_all, rel=1e-5, abs=1e-6)


def test_augmentation_changes_what_the_networks_see_never_the_reward():
    policy, batch = policy_and_batch(batch_size=64)
    torch.manual_seed(7)
    loss_a, stats_a = policy.forward(batch, generator=torch.Generator().manual_seed(2))
    torch.manual_seed(8)
    loss_b, stats_b = policy.forward(batch, generator=torch.Generator().manual_seed(2))
    assert loss_a != loss_b  # other shifts, other features
    for key in ("frac_positive", "frac_goal_next", "frac_goal_future", "frac_goal_recorded"):
        assert stats_a[key] == stats_b[key]
    assert stats_a["frac_positive"] == stats_a["frac_goal_next"]  # random frames: only o_{t+1} equals itself
    obs = {RGB: batch[RGB], DEPTH: batch[DEPTH]}
    goal = {RGB: batch[core.goal_key(RGB)], DEPTH: batch[core.goal_key(DEPTH)]}
    assert torch.equal(
        policy.select_action({**obs, **{core.goal_key(k): v for k, v in goal.items()}}),
        policy.actor(obs, goal),
    )


@pytest.mark.parametrize("target_encoder", [False, True])
def test_target_critic_uses_its_own_encoder_only_when_asked(target_encoder):
    policy, batch = policy_and_batch(target_encoder=target_encoder, augment_pad=0)
    before, _ = policy.forward(batch, generator=torch.Generator().manual_seed(4))
    with torch.no_grad():
        policy.target_critic.encoder.conv[0].weight.mul_(3.0)
    after, _ = policy.forward(batch, generator=torch.Generator().manual_seed(4))
    assert (before != after) == target_encoder


def test_target_update_moves_a_shared_encoder_once():
    policy, _ = policy_and_batch()
    online, target = policy.critic.encoder.conv[0].weight, policy.target_critic.encoder.conv[0].weight
    with torch.no_grad():
        online.add_(1.0)
    old_target = target.clone()
    policy.update()
    tau = policy.config.tau
    torch.testing.assert_close(target, tau * old_target + (1 - tau) * online)


def test_bf16_only_where_asked_or_native():
    assert not use_bf16("float32", "cpu")
    assert use_bf16("bfloat16", "cpu")
    assert use_bf16("auto", "cpu") == native_bf16("cpu")
    flags = Path("/proc/cpuinfo").read_text()
    assert native_bf16("cpu") == ("avx512_bf16" in flags or "amx_bf16" in flags)


def test_one_shift_per_transition_is_shared_by_its_observation_next_observation_and_goal(monkeypatch):
    policy, batch = policy_and_batch(batch_size=16)
    seen = []
    original = networks.random_shift

    def spy(frames, shift):
        seen.append(shift.clone())
        return original(frames, shift)

    monkeypatch.setattr(networks, "random_shift", spy)
    policy.forward(batch, generator=torch.Generator().manual_seed(9))
    source = core.relabel_sources(
        batch[core.HAS_FUTURE], policy.config, None, torch.Generator().manual_seed(9)
    ).source
    rest = (source != core.SOURCE_NEXT).nonzero().squeeze(1)
    is_goal = (source == core.SOURCE_NEXT).nonzero().squeeze(1)
    # Pass with gradients: [o_t, the o_{t+1} that are goals, the other goals]; without: the other o_{t+1}.
    shift, shift_rest = seen
    b, n = 16, len(is_goal)
    assert 0 < n < b and shift.shape == (2, 2 * b) and shift.abs().max() <= policy.config.augment_pad
    assert torch.equal(shift[:, b : b + n], shift[:, :b][:, is_goal])
    assert torch.equal(shift[:, b + n :], shift[:, :b][:, rest])
    assert torch.equal(shift_rest, shift[:, :b][:, rest])
    assert len({tuple(c) for c in shift[:, :b].T.tolist()}) > 1  # transitions get different shifts


def test_compiled_image_loss_is_one_graph():
    """Under ``compile_model`` the image loss must trace as one graph: a graph break (such as tracing the CPU
    flags read that picks the conv precision) splits it into pieces that recompile until Dynamo falls back to
    eager. ``fullgraph=True`` raises on any break; the eager backend keeps the check to tracing."""
    policy, batch = policy_and_batch(conv_precision="auto")
    torch.manual_seed(1)  # the global RNG: Dynamo does not trace a torch.Generator argument
    eager, _ = policy.forward(batch)
    policy._loss = torch.compile(policy._loss, backend="eager", fullgraph=True, dynamic=False)
    torch.manual_seed(1)
    traced, _ = policy.forward(batch)
    torch.testing.assert_close(traced, eager)


def test_random_shift_lowers_under_inductor():
    """The machine-word gather is eager-only: Inductor cannot lower a dtype view of gathered words, so a compiled
    learning core (``compile_model``) must take the plain gather and give the same frames."""
    torch._dynamo.reset()
    x = torch.randn(6, 4, 8, 8).to(torch.bfloat16).contiguous(memory_format=torch.channels_last)
    shift = draw_shifts(6, 2, x.device)
    assert torch.equal(torch.compile(random_shift, fullgraph=True)(x, shift), random_shift(x, shift))


@pytest.mark.parametrize("spatial_softmax", [False, True])
def test_projection_runs_in_the_conv_precision_except_after_spatial_softmax(spatial_softmax):
    """With bf16 convs the "drq" projection multiplies bf16 maps (float32 features come out); after the spatial
    softmax the keypoints and everything behind them stay float32."""
    policy, batch = policy_and_batch(conv_precision="bfloat16", spatial_softmax=spatial_softmax)
    linear = policy.critic.encoder.trunk[1]
    seen = []
    linear.register_forward_hook(lambda _m, inputs, out: seen.append((inputs[0].dtype, out.dtype)))
    features = policy.critic.encoder({k: batch[k] for k in (RGB, DEPTH)})
    assert features.dtype == torch.float32
    assert seen == [(torch.float32, torch.float32)] if spatial_softmax else seen == [(torch.bfloat16,) * 2]


@pytest.mark.parametrize("precision, maps_tol, grads_tol", [("float32", 1e-5, 1e-5), ("bfloat16", 2e-2, 0.3)])
def test_drq_conv_pass_matches_its_conv_relu_layers_with_gradients(precision, maps_tol, grads_tol):
    """The "drq" conv pass (normalisation folded into the first conv, each layer relu(conv2d) in the conv
    precision) gives the encoder's float32 Conv2d + ReLU layers on the normalised frames, and their gradients
    for every conv weight and bias, with many outputs zero (so the ReLU's mask matters). In bfloat16 within its
    rounding: maps to 2%, gradients (through four rounded layers) to 30% of their norm (relative norms of the
    difference)."""
    policy, batch = policy_and_batch(conv_precision=precision, batch_size=32)
    enc = policy.critic.encoder
    obs = {RGB: batch[RGB], DEPTH: batch[DEPTH]}
    params = list(enc.conv.parameters())

    def maps_and_grads(maps: torch.Tensor) -> list[torch.Tensor]:
        """The maps (float32) and the conv parameters' gradients of a fixed random weighting of them."""
        upstream = torch.randn(maps.shape, generator=torch.Generator().manual_seed(0))
        return [maps.detach().float(), *torch.autograd.grad((maps.float() * upstream).sum(), params)]

    folded = maps_and_grads(enc.conv_features([obs]))
    assert enc.conv_features([obs]).dtype == (torch.bfloat16 if precision == "bfloat16" else torch.float32)
    layers = maps_and_grads(enc.conv(torch.cat([enc.standardize(k, as_float(v)) for k, v in obs.items()], 1)))
    assert 0.2 < float((layers[0] == 0).float().mean()) < 0.8
    for i, (got, want) in enumerate(zip(folded, layers, strict=True)):
        assert float((got - want).norm() / want.norm()) < (maps_tol if i == 0 else grads_tol)
