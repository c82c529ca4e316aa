"""The learning core on hand-made batches: relabeling, indicator reward, filtering, targets, gradients."""

import pytest
import torch
from lerobot.configs import FeatureType, PolicyFeature

from lerobot_indicator.keys import goal_key
from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy.configuration_indicator_ddpg import (
    IndicatorDDPGConfig,
    IndicatorDDPGConfigError,
)
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

STATE, GOAL = "observation.state", "observation.goal_state"


def state_config(**kwargs) -> IndicatorDDPGConfig:
    cfg = IndicatorDDPGConfig(
        device="cpu", hidden_dims=[32, 32, 32], **{"horizon": 25, "observation_keys": [STATE], **kwargs}
    )
    cfg.input_features = {
        STATE: PolicyFeature(FeatureType.STATE, (3,)),
        GOAL: PolicyFeature(FeatureType.STATE, (3,)),
    }
    cfg.output_features = {"action": PolicyFeature(FeatureType.ACTION, (3,))}
    return cfg


def transition_batch(batch_size: int, generator: torch.Generator, has_future: bool = True) -> dict:
    """Random continuous states: o_{t+1} equals only itself, so the reward is R+ exactly for next-goals."""
    obs = torch.randn(batch_size, 3, generator=generator)
    nxt = torch.randn(batch_size, 3, generator=generator)
    return {
        STATE: obs,
        core.NEXT + STATE: nxt,
        core.FUTURE + STATE: torch.randn(batch_size, 3, generator=generator),
        GOAL: torch.randn(batch_size, 3, generator=generator),
        "action": torch.rand(batch_size, 3, generator=generator) * 2 - 1,
        core.HAS_FUTURE: torch.full((batch_size,), has_future),
    }


def fractions(source: torch.Tensor) -> list[float]:
    return [
        (source == s).float().mean().item()
        for s in (core.SOURCE_NEXT, core.SOURCE_FUTURE, core.SOURCE_RECORDED)
    ]


def test_balanced_relabel_fractions():
    gen = torch.Generator().manual_seed(0)
    relabel = core.relabel_sources(torch.ones(100_000, dtype=torch.bool), state_config(), generator=gen)
    assert fractions(relabel.branch) == pytest.approx([0.45, 0.45, 0.1], abs=0.01)
    assert torch.equal(relabel.branch, relabel.source)


def test_unbalanced_relabel_fractions_and_her_future():
    gen = torch.Generator().manual_seed(0)
    n = 100_000
    cfg = state_config(balance=False)
    relabel = core.relabel_sources(torch.ones(n, dtype=torch.bool), cfg, torch.full((n,), 3), gen)
    assert fractions(relabel.branch) == pytest.approx([0.0, 0.9, 0.1], abs=0.01)
    # Future over {t+1} + 3 candidates: o_{t+1} with probability 1/4 of the future branch.
    assert fractions(relabel.source) == pytest.approx([0.9 / 4, 0.9 * 3 / 4, 0.1], abs=0.01)


def test_relabel_is_reproducible_with_a_generator():
    has_future = torch.ones(1000, dtype=torch.bool)
    a = core.relabel_sources(has_future, state_config(), generator=torch.Generator().manual_seed(3)).source
    b = core.relabel_sources(has_future, state_config(), generator=torch.Generator().manual_seed(3)).source
    c = core.relabel_sources(has_future, state_config(), generator=torch.Generator().manual_seed(4)).source
    assert torch.equal(a, b) and not torch.equal(a, c)


def test_no_future_falls_back_to_recorded_goal_when_asked_and_next_when_unbalanced():
    n = 10_000
    no_future = torch.zeros(n, dtype=torch.bool)
    cfg = state_config(balance_fallback="recorded")
    balanced = core.relabel_sources(no_future, cfg, generator=torch.Generator().manual_seed(0))
    assert not (balanced.source == core.SOURCE_FUTURE).any()
    assert fractions(balanced.source) == pytest.approx([0.45, 0.0, 0.55], abs=0.02)
    unbalanced = core.relabel_sources(no_future, state_config(balance=False), generator=torch.Generator())
    assert fractions(unbalanced.source) == pytest.approx([0.9, 0.0, 0.1], abs=0.02)


def test_balance_fallback_next_uses_o_next_only_where_no_future_exists():
    n = 10_000
    has_future = torch.arange(n) % 2 == 0
    assert state_config().balance_fallback == "next"
    relabel = core.relabel_sources(has_future, state_config(), generator=torch.Generator().manual_seed(0))
    cfg = state_config(balance_fallback="recorded")
    recorded = core.relabel_sources(has_future, cfg, generator=torch.Generator().manual_seed(0))
    assert torch.equal(relabel.branch, recorded.branch)  # same draws, only the fallback differs
    assert fractions(relabel.source[~has_future]) == pytest.approx([0.9, 0.0, 0.1], abs=0.02)
    assert torch.equal(relabel.source[has_future], recorded.source[has_future])
    with pytest.raises(IndicatorDDPGConfigError, match="balance_fallback"):
        state_config(balance_fallback="future")


def test_select_goals_takes_each_source():
    gen = torch.Generator().manual_seed(0)
    batch = transition_batch(3, gen)
    goals = core.select_goals(batch, [STATE], torch.tensor([0, 1, 2]))[STATE]
    assert torch.equal(goals[0], batch[core.NEXT + STATE][0])
    assert torch.equal(goals[1], batch[core.FUTURE + STATE][1])
    assert torch.equal(goals[2], batch[GOAL][2])


@pytest.mark.parametrize("dtype, shape", [(torch.uint8, (3, 5, 7)), (torch.float32, (1, 4, 4))])
def test_select_goals_copies_image_rows_bit_for_bit(dtype, shape):
    """Frames are selected as machine words (105 bytes: bytes; 64 bytes: int64 words): every row is its
    source's row, bit patterns (-0.0, NaN payloads) included."""
    gen = torch.Generator().manual_seed(0)
    b = 7
    rows = [torch.randint(0, 256, (b, *shape), generator=gen).to(dtype) for _ in range(3)]
    if dtype == torch.float32:
        rows[1][2, 0, 1, 1] = -0.0
        rows[2][3].view(torch.int32)[0, 0, 0] = 0x7FC00123  # a NaN with a payload
    key = "observation.images.front"
    batch = {core.NEXT + key: rows[0], core.FUTURE + key: rows[1], goal_key(key): rows[2]}
    source = torch.tensor([0, 1, 2, 2, 1, 0, 1])
    picked = core.select_goals(batch, [key], source)[key]
    assert picked.dtype == dtype and picked.shape == (b, *shape)
    for i, s in enumerate(source.tolist()):
        assert torch.equal(picked[i].view(torch.uint8), rows[s][i].view(torch.uint8))


@pytest.mark.parametrize("path", ["words", "words, 2-d rows", "compiling", "1-d rows", "two dtypes"])
def test_pick_takes_each_source_on_the_word_path_and_the_plain_one(path, monkeypatch):
    """Rows of one dtype with 2+ dims are selected as machine words; under torch.compile (Inductor cannot
    lower the word view), for 1-d rows and for rows of different dtypes the plain ``where`` selects them.
    Both give row i of next / future / recorded as source[i] says."""
    b = 6
    shape = {"1-d rows": (b,), "words, 2-d rows": (b, 4)}.get(path, (b, 2, 3))
    value = torch.arange(b).view((b,) + (1,) * (len(shape) - 1)).expand(shape)
    nxt, future, recorded = (value + offset for offset in (10, 100, 200))
    dtypes = (torch.float32, torch.float32, torch.float64) if path == "two dtypes" else (torch.uint8,) * 3
    nxt, future, recorded = (t.to(dtype) for t, dtype in zip((nxt, future, recorded), dtypes, strict=True))
    words = []
    if path.startswith("words"):
        monkeypatch.setattr(core, "row_words", lambda x, f=core.row_words: words.append(x) or f(x))
    else:  # the plain path never views rows as words
        monkeypatch.setattr(
            core, "row_words", lambda x: pytest.fail("rows viewed as words off the word path")
        )
    if path == "compiling":
        monkeypatch.setattr(torch.compiler, "is_compiling", lambda: True)
    source = torch.tensor([0, 1, 2, 2, 1, 0])
    picked = core._pick(source, nxt, future, recorded)
    assert len(words) == (3 if path.startswith("words") else 0)
    assert picked.shape == shape and picked.dtype == torch.promote_types(dtypes[0], dtypes[2])
    expected = [10, 101, 202, 203, 104, 15]
    assert [int(x) for x in picked.reshape(b, -1)[:, -1]] == expected
    assert torch.equal(
        picked, picked.reshape(b, -1)[:, :1].reshape((b,) + (1,) * (len(shape) - 1)).expand(shape)
    )


def test_row_words_are_the_widest_words_that_tile_a_whole_row():
    """A row of 2x3 bytes is 3 int16 words (not the 3-byte width of its last dims); 12 float32 bytes: 3 int32."""
    words = core.row_words(torch.zeros(2, 2, 3, dtype=torch.uint8))
    assert words.dtype == torch.int16 and words.shape == (2, 3)
    words = core.row_words(torch.zeros(2, 3, dtype=torch.float32))
    assert words.dtype == torch.int32 and words.shape == (2, 3)
    words = core.row_words(torch.zeros(4, 2, 4, 4, dtype=torch.uint8))
    assert words.dtype == torch.int64 and words.shape == (4, 4)


def test_indicator_reward_exact_equality_on_every_key():
    img = torch.randint(0, 256, (4, 3, 8, 8)).float() / 255
    depth = torch.rand(4, 1, 8, 8) * 1000
    goal_img, goal_depth = img.clone(), depth.clone()
    goal_img[1, 2, 5, 5] += 1 / 255  # one pixel, one channel, one intensity level
    goal_depth[2, 0, 0, 0] = torch.nextafter(goal_depth[2, 0, 0, 0], torch.tensor(2000.0))  # one ulp
    goal_img[3, 0, 0, 0] = -0.0 if img[3, 0, 0, 0] == 0 else -img[3, 0, 0, 0]
    next_obs = {"observation.images.front": img, "observation.images.front_depth": depth}
    goal = {"observation.images.front": goal_img, "observation.images.front_depth": goal_depth}
    reward = core.indicator_reward(next_obs, goal, 1.0, -1.0)
    assert reward.tolist() == [1.0, -1.0, -1.0, -1.0]


def test_oracle_success_uses_epsilon():
    achieved = torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    goal = torch.tensor([[0.0, 0.0, 0.099], [0.0, 0.101, 0.0]])
    assert core.ground_truth_success(achieved, goal, 0.1).tolist() == [True, False]


def test_gamma_q0_and_bounds_from_horizon():
    cfg = state_config(horizon=25)
    assert cfg.gamma == pytest.approx(24 / 25)
    # 0.5 [R- + gamma R+/(1-gamma) + R+/(1-gamma)] = 0.5 [-1 + 24 + 25]
    assert cfg.q0 == pytest.approx(24.0)
    assert (cfg.q_min, cfg.q_max) == pytest.approx((-25.0, 25.0))
    cfg3 = state_config(horizon=3)
    assert cfg3.q0 == pytest.approx(0.5 * (-1 + (2 / 3) / (1 / 3) + 1 / (1 / 3)))
    # The threshold sits strictly between the two Q* bounds of section 5.3.
    assert -1 + cfg.gamma / (1 - cfg.gamma) < cfg.q0 < 1 / (1 - cfg.gamma)


def test_filter_drops_exactly_negative_rewards_above_q0():
    reward = torch.tensor([-1.0, -1.0, -1.0, 1.0, 1.0])
    q = torch.tensor([30.0, 24.0, 10.0, 30.0, -5.0])
    assert core.filter_keep(reward, q, q0=24.0, r_neg=-1.0).tolist() == [False, True, True, True, True]


def test_loss_filters_only_negative_high_q_transitions():
    torch.manual_seed(0)
    cfg = state_config()
    policy = IndicatorDDPGPolicy(cfg)
    batch = transition_batch(512, torch.Generator().manual_seed(1))
    # Force every Q above q0: only transitions with R- may be filtered, all of them are.
    torch.nn.init.constant_(policy.critic.net[-1].bias, cfg.q0 + 100)
    _, stats = policy.forward(batch, generator=torch.Generator().manual_seed(2))
    assert stats["frac_filtered"] == pytest.approx(1 - stats["frac_positive"])
    assert stats["frac_positive"] == pytest.approx(stats["frac_goal_next"])
    torch.nn.init.constant_(policy.critic.net[-1].bias, cfg.q_min)
    _, stats = policy.forward(batch, generator=torch.Generator().manual_seed(2))
    assert stats["frac_filtered"] == 0.0
    cfg.filter = False
    torch.nn.init.constant_(policy.critic.net[-1].bias, cfg.q0 + 100)
    _, stats = policy.forward(batch, generator=torch.Generator().manual_seed(2))
    assert stats["frac_filtered"] == 0.0


def test_target_update_arithmetic():
    policy = IndicatorDDPGPolicy(state_config())
    online = [p.detach().clone() for p in policy.critic.parameters()]
    target = [p.detach().clone() + 1.0 for p in policy.target_critic.parameters()]
    with torch.no_grad():
        for p, t in zip(policy.target_critic.parameters(), target, strict=True):
            p.copy_(t)
    policy.update()
    for p, o, t in zip(policy.target_critic.parameters(), online, target, strict=True):
        torch.testing.assert_close(p, 0.98 * t + 0.02 * o)


def test_critic_target_is_clipped_and_initial_q_is_low():
    cfg = state_config()
    policy = IndicatorDDPGPolicy(cfg)
    batch = transition_batch(64, torch.Generator().manual_seed(0))
    _, stats = policy.forward(batch)
    assert stats["q_mean"] == pytest.approx(cfg.q_min, abs=2.0)
    torch.nn.init.constant_(policy.target_critic.net[-1].bias, 1e3)
    _, stats = policy.forward(batch)
    assert stats["q_target_mean"] == pytest.approx(cfg.q_max)


def _losses(policy: IndicatorDDPGPolicy, batch: dict) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Total loss and its critic / actor parts (spied from the core's two masked means, in call order)."""
    original, calls = core.masked_mean, []

    def spy(x, mask):
        calls.append(original(x, mask))
        return calls[-1]

    core.masked_mean = spy
    try:
        total, _ = policy.forward(batch, generator=torch.Generator().manual_seed(5))
    finally:
        core.masked_mean = original
    return total, calls[0], calls[1]


def test_gradients_are_isolated_in_the_combined_loss():
    torch.manual_seed(0)
    policy = IndicatorDDPGPolicy(state_config(filter=False))
    batch = transition_batch(32, torch.Generator().manual_seed(0))

    def grads(part: int) -> dict[str, torch.Tensor | None]:
        policy.zero_grad(set_to_none=True)
        _losses(policy, batch)[part].backward()
        return {n: None if p.grad is None else p.grad.clone() for n, p in policy.named_parameters()}

    total, critic_only, actor_only = grads(0), grads(1), grads(2)
    for name, g in total.items():
        if name.startswith("critic."):
            assert actor_only[name] is None, f"actor loss reached {name}"
            torch.testing.assert_close(g, critic_only[name])
        elif name.startswith("actor."):
            assert critic_only[name] is None, f"critic loss reached {name}"
            torch.testing.assert_close(g, actor_only[name])
        else:
            assert name.startswith("target_") and g is None, name
    assert torch.count_nonzero(total["actor.net.0.weight"]) > 0
    assert torch.count_nonzero(total["critic.net.0.weight"]) > 0
