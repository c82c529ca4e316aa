"""The reward filter's options beside the paper's rule: its Q from the target critic, and a calibrated start."""

import re

import pytest
import torch
from test_indicator_core import state_config, transition_batch

from benchmarks.speed.updates import make_batch, make_policy, rgbd_features
from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfigError
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy


def test_calibrated_needs_the_fraction_of_valid_positives_above_q0():
    reward = torch.tensor([1.0, 1.0, 1.0, -1.0, -1.0])
    q = torch.tensor([3.0, 2.5, 1.0, 2.9, 0.0])
    valid = torch.ones(5, dtype=torch.bool)

    def calibrated(fraction: float, valid: torch.Tensor = valid, reward: torch.Tensor = reward) -> bool:
        return bool(core.filter_calibrated(reward, q, valid, q0=2.0, r_pos=1.0, fraction=fraction))

    assert not calibrated(0.9)  # 2 of 3 positives above q0; the negative above q0 does not count
    assert calibrated(2 / 3) and calibrated(0.6)
    assert calibrated(0.9, valid=torch.tensor([True, True, False, True, True]))  # the low one is invalid
    assert not calibrated(0.1, reward=-torch.ones(5))  # no positive: no evidence, no filtering


def _spy_filter_q(monkeypatch) -> list[torch.Tensor]:
    seen = []
    original = core.filter_keep

    def spy(reward, q, q0, r_neg):
        seen.append(q.clone())
        return original(reward, q, q0, r_neg)

    monkeypatch.setattr(core, "filter_keep", spy)
    return seen


def _perturb(module: torch.nn.Module) -> None:
    gen = torch.Generator().manual_seed(9)
    with torch.no_grad():
        for p in module.parameters():
            p.add_(0.1 * torch.randn(p.shape, generator=gen))


ARMS = {
    "state": {},
    "drq": {"image_encoder": "drq"},
    "drq_target_encoder": {"image_encoder": "drq", "target_encoder": True},
    "paper": {"image_encoder": "paper"},
}


@pytest.mark.parametrize("arm", sorted(ARMS))
@pytest.mark.parametrize("filter_q", ["online", "target"])
def test_filter_q_is_the_chosen_critic_on_o_t_and_the_relabeled_goal(arm, filter_q, monkeypatch):
    torch.manual_seed(0)
    if arm == "state":
        policy = IndicatorDDPGPolicy(state_config(filter_q=filter_q))
        batch = transition_batch(16, torch.Generator().manual_seed(1))
    else:
        features = rgbd_features(24)
        config = {"hidden_dims": [8, 8, 8], "conv_precision": "float32", "augment_pad": 0, **ARMS[arm]}
        policy = make_policy(features, filter_q=filter_q, **config)
        batch = make_batch(features, 16)
    _perturb(policy.target_critic)  # targets differ from the online networks (and their encoders)
    cfg = policy.config
    seen = _spy_filter_q(monkeypatch)
    policy.forward(batch, generator=torch.Generator().manual_seed(2))

    source = core.relabel_sources(batch[core.HAS_FUTURE], cfg, None, torch.Generator().manual_seed(2)).source
    keys = cfg.observation_keys
    obs, goal = {k: batch[k] for k in keys}, core.select_goals(batch, keys, source)
    with torch.no_grad():
        if filter_q == "online":
            expected = policy.critic(obs, goal, batch["action"])
        elif cfg.shared_encoder and not cfg.target_encoder:
            # The shared design's targets read the online encoder's features (DrQ-v2); only the head differs.
            expected = policy.target_critic.head(policy.critic.encode(obs, goal), batch["action"])
        else:
            expected = policy.target_critic(obs, goal, batch["action"])
    torch.testing.assert_close(seen[0], expected, rtol=1e-4, atol=1e-4)


def test_calibrated_filter_acts_only_in_batches_whose_positives_have_high_q(monkeypatch):
    cfg = state_config(filter_start="calibrated", filter_calibration=0.9)
    policy = IndicatorDDPGPolicy(cfg)
    batch = transition_batch(256, torch.Generator().manual_seed(1))
    # With random continuous states R+ exactly where the goal is o_{t+1}: the relabeled positives.
    source = core.relabel_sources(batch[core.HAS_FUTURE], cfg, None, torch.Generator().manual_seed(2)).source
    positive = source == core.SOURCE_NEXT
    head = policy.critic.head

    def forward_with_q(q_pos: float, q_neg: float) -> dict[str, float]:
        q = torch.where(positive, q_pos, q_neg)
        monkeypatch.setattr(policy.critic, "head", lambda f, a, frozen=False: head(f, a, frozen) * 0 + q)
        return policy.forward(batch, generator=torch.Generator().manual_seed(2))[1]

    above, below = cfg.q0 + 1.0, cfg.q0 - 1.0
    stats = forward_with_q(q_pos=below, q_neg=above)  # uncalibrated: high Q on negatives is not trusted
    assert stats["filter_active"] == 0.0 and stats["frac_filtered"] == 0.0
    stats = forward_with_q(q_pos=above, q_neg=above)  # calibrated: every negative above q0 is dropped
    assert stats["filter_active"] == 1.0
    assert stats["frac_filtered"] == pytest.approx(1.0 - positive.float().mean().item())
    cfg.filter_start = "always"  # the paper's rule filters regardless
    stats = forward_with_q(q_pos=below, q_neg=above)
    assert stats["frac_filtered"] == pytest.approx(1.0 - positive.float().mean().item())
    assert "filter_active" not in stats


@pytest.mark.parametrize(
    ("option", "message"),
    [
        ({"filter_q": "ema"}, "filter_q must be one of ('online', 'target'), got 'ema'"),
        ({"filter_start": "later"}, "filter_start must be one of ('always', 'calibrated'), got 'later'"),
        ({"filter_calibration": 0.0}, "filter_calibration must be in (0, 1], got 0.0"),
    ],
)
def test_bad_filter_options_name_the_field(option, message):
    with pytest.raises(IndicatorDDPGConfigError, match=re.escape(message)):
        state_config(**option)
