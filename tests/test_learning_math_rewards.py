"""Relabeling draws, rewards (oracle, learned), the filter's options and the logged statistics, against values
worked out here by hand.

Setup as in ``test_learning_math``: state inputs of one dim, hidden_dims=[2], T = 4 (gamma = 3/4, and with
R+ = 1, R- = -1: q_min = -4, q_max = 4, q0 = 3). Relabeling draws ``u`` (then ``v`` for the unbalanced mix)
with ``torch.rand(B, generator=...)``; with the seed below and B = 8 those draws are

    u = [0.3319, 0.9003, 0.1204, 0.0187, 0.1775, 0.6853, 0.7801, 0.7648]
    v = [0.8933, 0.125 (exactly 1/8), 0.3576, 0.1469, 0.0678, 0.5515, 0.1655, 0.5490]

so a probability set to one of the drawn values puts a row exactly on the boundary of ``u < p``, and row 1
with 7 future candidates sits exactly on ``v < 1 / (count + 1)``.
"""

import re

import pytest
import torch
from lerobot.configs import FeatureType
from test_learning_math import (
    ACT,
    GOAL,
    GOALS,
    NXT,
    OBS,
    POSITIVE_ROWS,
    STATE,
    T,
    batch_of,
    close,
    col,
    filter_batch_and_policy,
    linears,
    loss_and_stats,
    make_policy,
    pi_ref,
    q_ref,
    set_policy_weights,
    weights,
)
from torch import Tensor, nn

from benchmarks.speed.updates import make_batch
from benchmarks.speed.updates import make_policy as make_image_policy
from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig
from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

SEED, B = 12846, 8
NEXT, FUTURE, RECORDED = core.SOURCE_NEXT, core.SOURCE_FUTURE, core.SOURCE_RECORDED
BASE_STATS = {
    "critic_loss",
    "actor_loss",
    "q_mean",
    "q_std",
    "q_target_mean",
    "frac_positive",
    "frac_filtered",
    "frac_goal_next",
    "frac_goal_future",
    "frac_goal_recorded",
}


def draws() -> tuple[Tensor, Tensor]:
    """The relabeling draws u, v of SEED (module docstring), as float32 tensors."""
    x = torch.rand(2 * B, generator=torch.Generator().manual_seed(SEED))
    return x[:B], x[B:]


def config(**kwargs) -> IndicatorDDPGConfig:
    return IndicatorDDPGConfig(device="cpu", horizon=T, observation_keys=[STATE], **kwargs)


def mask(*rows: int, n: int = B) -> Tensor:
    """Bool (n,) True on ``rows``."""
    out = torch.zeros(n, dtype=torch.bool)
    out[list(rows)] = True
    return out


def constant_critics(policy: IndicatorDDPGPolicy, q: float = 0.3) -> None:
    """Q(o, g, a) = q for the online critic and Q' = 0 for the target critic: then y = clip(r) row by row."""
    with torch.no_grad():
        for net, value in ((policy.target_critic, 0.0), (policy.critic, q)):
            linears(net)[-1].weight.zero_()
            linears(net)[-1].bias.fill_(value)


# ----------------------------------------------------------------------------------- 1. relabel_sources


def test_drawn_values_are_the_ones_the_expected_sources_below_are_worked_out_from():
    """The hand-made expectations of this section rest on these draws and boundaries."""
    u, v = draws()
    assert u.tolist() == pytest.approx(
        [0.3319, 0.9003, 0.1204, 0.0187, 0.1775, 0.6853, 0.7801, 0.7648], abs=1e-4
    )
    assert v.tolist() == pytest.approx(
        [0.8933, 0.125, 0.3576, 0.1469, 0.0678, 0.5515, 0.1655, 0.5490], abs=1e-4
    )
    assert float(v[1]) == 1 / 8


@pytest.mark.parametrize(
    "fallback, source",
    [
        ("next", [FUTURE, RECORDED, FUTURE, NEXT, NEXT, NEXT, RECORDED, FUTURE]),
        ("recorded", [FUTURE, RECORDED, FUTURE, NEXT, RECORDED, RECORDED, RECORDED, FUTURE]),
    ],
)
def test_balanced_sources_are_next_below_p_next_future_below_p_next_plus_p_future(fallback, source):
    """branch = next where u < p_next, future where p_next <= u < p_next + p_future, else recorded: row 2 has
    u == p_next exactly (future, not next) and row 6 u == p_next + p_future (recorded, not future). Future
    rows without a t' >= t+2 (rows 4, 5) take the fallback; a next or recorded row without one (rows 3, 1)
    keeps its branch. Sources are long indices."""
    u, _ = draws()
    p_next, p_future = float(u[2]), float(u[6]) - float(u[2])
    assert p_next + p_future == float(u[6])
    has_future = ~mask(1, 3, 4, 5)
    cfg = config(p_next=p_next, p_future=p_future, balance_fallback=fallback)
    relabel = core.relabel_sources(has_future, cfg, None, torch.Generator().manual_seed(SEED))
    assert relabel.branch.tolist() == [FUTURE, RECORDED, FUTURE, NEXT, FUTURE, FUTURE, RECORDED, FUTURE]
    assert relabel.source.tolist() == source
    assert relabel.branch.dtype == relabel.source.dtype == torch.long


# future_count of each row and whether it has a t' >= t+2 at all (row 2 has not: its count is void).
COUNTS = torch.tensor([1, 7, 3, 6, 5, 1, 1, 1])
HAS_FUTURE = ~mask(2)


def test_unbalanced_branch_is_future_below_p_future_unbalanced_then_next_with_one_over_count_plus_one():
    """balance=False, p_future_unbalanced = u[5]: future branch where u < p (rows 0, 2, 3, 4; row 5 sits on the
    boundary and is recorded). A future-branch row takes o_{t+1} where v < 1/(count+1), count = future_count
    where a t' exists, 0 where not: row 2 (no t', threshold 1) and row 4 (v = 0.068 < 1/6) get o_{t+1}; row 3
    (v = 0.147 > 1/7) keeps its future frame, which a count of 1 (threshold 1/2) would not."""
    u, _ = draws()
    cfg = config(balance=False, p_future_unbalanced=float(u[5]))
    relabel = core.relabel_sources(HAS_FUTURE, cfg, COUNTS, torch.Generator().manual_seed(SEED))
    assert relabel.branch.tolist() == [FUTURE, RECORDED, FUTURE, FUTURE, FUTURE, RECORDED, RECORDED, RECORDED]
    assert relabel.source.tolist() == [FUTURE, RECORDED, NEXT, FUTURE, NEXT, RECORDED, RECORDED, RECORDED]
    assert relabel.branch.dtype == relabel.source.dtype == torch.long


def test_unbalanced_next_needs_v_strictly_below_one_over_count_plus_one():
    """p_future_unbalanced = 1 (every row in the future branch): row 1 has v = 1/8 exactly and 7 candidates, so
    v < 1/(7+1) is false and it keeps the future frame; rows 2, 4, 6 fall below their thresholds."""
    cfg = config(balance=False, p_future_unbalanced=1.0)
    relabel = core.relabel_sources(HAS_FUTURE, cfg, COUNTS, torch.Generator().manual_seed(SEED))
    assert relabel.branch.tolist() == [FUTURE] * B
    assert relabel.source.tolist() == [FUTURE, FUTURE, NEXT, FUTURE, NEXT, FUTURE, NEXT, FUTURE]


def test_unbalanced_without_future_count_counts_one_candidate_where_a_future_exists():
    """future_count=None: threshold 1/2 where has_future, 1 where not: rows 1, 3, 4, 6 (v < 1/2) and row 2
    (no future) get o_{t+1}."""
    cfg = config(balance=False, p_future_unbalanced=1.0)
    relabel = core.relabel_sources(HAS_FUTURE, cfg, None, torch.Generator().manual_seed(SEED))
    assert relabel.source.tolist() == [FUTURE, NEXT, NEXT, NEXT, NEXT, FUTURE, NEXT, FUTURE]


def generator_state_after(n_draws: int) -> Tensor:
    gen = torch.Generator().manual_seed(SEED)
    for _ in range(n_draws):
        torch.rand(B, generator=gen)
    return gen.get_state()


@pytest.mark.parametrize("balance, n_draws", [(True, 1), (False, 2)])
def test_relabeling_a_batch_on_another_device_draws_from_the_callers_generator(balance, n_draws):
    """A batch on another device than the generator (here the meta device) with a future_count on a third
    (the CPU): the draws come from the caller's CPU generator, which advances by exactly the B (balanced) or
    2B (unbalanced) numbers, and the sources come back on the batch's device."""
    gen = torch.Generator().manual_seed(SEED)
    cfg = config(balance=balance)
    relabel = core.relabel_sources(torch.ones(B, dtype=torch.bool, device="meta"), cfg, COUNTS, gen)
    assert relabel.branch.device.type == relabel.source.device.type == "meta"
    assert torch.equal(gen.get_state(), generator_state_after(n_draws))


@pytest.mark.parametrize("balance", [True, False])
def test_without_a_generator_the_draws_use_the_batch_devices_rng(balance):
    """generator=None: on the CPU the draws are torch's global RNG's (the same sources as a generator seeded
    alike); for a batch on another device they are made there, so the CPU RNG is left as it was (the meta
    device, whose draws consume nothing, shows where they were made)."""
    cfg = config(balance=balance)
    with torch.random.fork_rng():
        torch.manual_seed(SEED)
        plain = core.relabel_sources(HAS_FUTURE, cfg, COUNTS)
        seeded = core.relabel_sources(HAS_FUTURE, cfg, COUNTS, torch.Generator().manual_seed(SEED))
        assert torch.equal(plain.source, seeded.source) and torch.equal(plain.branch, seeded.branch)
        before = torch.get_rng_state()
        relabel = core.relabel_sources(torch.ones(B, dtype=torch.bool, device="meta"), cfg, COUNTS)
        assert torch.equal(torch.get_rng_state(), before)
    assert relabel.source.device.type == "meta"


# --------------------------------------------------------------------------- 2. rows_equal, masked_mean


@pytest.mark.parametrize("order", ["int-first", "float-first"])
def test_rows_equal_promotes_before_comparing_bits(order):
    """An int32 1 and a float32 1.0 are the same value (True in either order, their bit patterns differ); a
    float32 0.5 equals the float64 0.5, while float32(0.1) is not float64 0.1."""
    ints, floats = torch.tensor([[1, 2], [1, 3]], dtype=torch.int32), torch.tensor([[1.0, 2.0], [1.0, 2.0]])
    a, b = (ints, floats) if order == "int-first" else (floats, ints)
    assert core.rows_equal(a, b).tolist() == [True, False]
    half32, half64 = torch.tensor([[0.5], [0.1]]), torch.tensor([[0.5], [0.1]], dtype=torch.float64)
    a, b = (half32, half64) if order == "int-first" else (half64, half32)
    assert core.rows_equal(a, b).tolist() == [True, False]


def test_masked_mean_divides_by_the_number_of_masked_rows():
    """sum(x * mask) / max(sum(mask), 1): a single masked row gives its own value, no row gives 0."""
    x = torch.tensor([2.0, 4.0, 8.0])
    assert core.masked_mean(x, torch.tensor([0.0, 1.0, 0.0])).item() == 4.0
    assert core.masked_mean(x, torch.tensor([1.0, 1.0, 0.0])).item() == 3.0
    assert core.masked_mean(x, torch.zeros(3)).item() == 0.0


def test_stats_to_floats_gives_python_floats_by_name():
    out = core.stats_to_floats({"a": torch.tensor(1.5), "b": torch.tensor(-2), "c": torch.tensor(True)})
    assert out == {"a": 1.5, "b": -2.0, "c": 1.0} and all(type(v) is float for v in out.values())


# --------------------------------------------------------------------------------- 3. filter_calibrated


def calibrated(reward, q, fraction: float, valid=None) -> Tensor:
    reward, q = torch.tensor(reward), torch.tensor(q)
    valid = torch.ones(len(reward), dtype=torch.bool) if valid is None else torch.tensor(valid)
    out = core.filter_calibrated(reward, q, valid, q0=2.0, r_pos=1.0, fraction=fraction)
    assert out.dtype == torch.bool and out.dim() == 0
    return out


def test_calibrated_counts_positives_with_q_strictly_above_q0_against_the_fraction():
    """Four valid R+ rows, Q = 3, 2 (= q0: not above), 2.5, 1: two above q0; the R- row at Q = 5 does not
    count. 2 >= 0.5 * 4 (the boundary holds), 2 < 0.75 * 4."""
    reward, q = [1.0, 1.0, 1.0, 1.0, -1.0, -1.0], [3.0, 2.0, 2.5, 1.0, 5.0, 0.0]
    assert bool(calibrated(reward, q, 0.5))
    assert not bool(calibrated(reward, q, 0.75))


def test_calibrated_counts_only_valid_r_plus_rows_as_positives():
    """One R+ row above q0 among R- rows below: 1 of 1 positives (True, also for a single positive); an R+ row
    marked invalid is no positive."""
    assert bool(calibrated([1.0, -1.0, -1.0, -1.0], [3.0, 0.0, 0.0, 0.0], 0.9))
    assert bool(calibrated([1.0, 1.0], [3.0, 0.0], 0.9, valid=[True, False]))
    assert not bool(calibrated([1.0, 1.0], [3.0, 0.0], 0.9))


def test_calibrated_is_false_without_any_positive():
    """No valid R+ row is no evidence: False even where every Q is above q0."""
    assert not bool(calibrated([-1.0, -1.0], [5.0, 5.0], 0.5))
    assert not bool(calibrated([1.0, -1.0], [5.0, 5.0], 0.5, valid=[False, True]))


# ------------------------------------------------------------------------------- 4. reward_statistics AUC


def auc_inputs(rows: list[tuple[bool, float, bool]]):
    """(ground-truth success, reward, valid) per row -> reward_statistics' arguments; the ground truth is 1-d,
    0.1 from the goal for a success and 2 for a failure (epsilon 0.5); every row kept."""
    success, reward, valid = (torch.tensor(c) for c in zip(*rows, strict=True))
    goal = torch.zeros(len(rows), 1)
    achieved = torch.where(success, 0.1, 2.0)[:, None]
    return reward.float(), achieved, goal, torch.ones(len(rows), dtype=torch.bool), valid


def auc(rows, reward: str = "ae") -> dict[str, Tensor]:
    cfg = config(reward=reward, filter=False, oracle_epsilon=0.5)
    return core.reward_statistics(*auc_inputs(rows), cfg)


def test_reward_auc_counts_pairs_ranked_right_and_ties_half_over_valid_pairs():
    """Valid successes r = 0.8, 0.5, 0.6 and failures r = 0.5, 0.2, 0.9: of the 9 pairs 0.8 beats 2, 0.5 beats
    1 and ties 1, 0.6 beats 2: AUC = (2 + 1.5 + 2) / 9. Invalid rows (a success at r = 0, a failure at r = 1)
    are in no pair."""
    rows = [
        (True, 0.8, True),
        (True, 0.5, True),
        (True, 0.6, True),
        (False, 0.5, True),
        (False, 0.2, True),
        (False, 0.9, True),
        (True, 0.0, False),
        (False, 1.0, False),
    ]
    stats = auc(rows)
    assert stats["reward_auc"].item() == pytest.approx(5.5 / 9)


def test_reward_auc_of_a_single_pair_and_of_none():
    """One pair ranked right gives 1, ranked wrong 0, tied 1/2; no pair (only successes, or the only failure
    invalid) gives 1/2."""
    assert auc([(True, 0.7, True), (False, 0.2, True)])["reward_auc"].item() == 1.0
    assert auc([(True, 0.2, True), (False, 0.7, True)])["reward_auc"].item() == 0.0
    assert auc([(True, 0.4, True), (False, 0.4, True)])["reward_auc"].item() == 0.5
    assert auc([(True, 0.7, True), (True, 0.2, True)])["reward_auc"].item() == 0.5
    assert auc([(True, 0.7, True), (False, 0.9, False)])["reward_auc"].item() == 0.5


def test_reward_auc_is_logged_for_learned_rewards_only():
    rows = [(True, 1.0, True), (False, -1.0, True)]
    assert "reward_auc" in auc(rows, "vae")
    assert "reward_auc" not in auc(rows, "indicator") and "reward_auc" not in auc(rows, "oracle")


# -------------------------------------------------------------------- 5. dataset_batch_to_transitions


def dataset_batch(n: int, device: str = "cpu") -> dict[str, Tensor]:
    """A lerobot-train batch of frames [o_t, o_{t+1}, 2 future offsets]; row i has i % 3 valid futures."""
    frames = torch.arange(4, dtype=torch.float32).repeat(n, 1)[:, :, None]
    valid_futures = torch.arange(n) % 3
    is_pad = torch.zeros(n, 4, dtype=torch.bool)
    is_pad[:, 2] = valid_futures < 1
    is_pad[:, 3] = valid_futures < 2
    batch = {STATE: frames, f"{STATE}_is_pad": is_pad, GOAL: frames + 10, "action": torch.zeros(n, 1)}
    return {k: v.to(device) for k, v in batch.items()}


@pytest.mark.parametrize("n_step", [2, 3])
def test_dataset_batches_refuse_n_step_targets_and_say_why(n_step):
    """A lerobot-train sample has no frames between o_{t+1} and the future ones: n_step > 1 is refused with the
    reason and the way out."""
    cfg = config(future_offsets=[2, 3], n_step=n_step)
    message = (
        f"n_step={n_step}: a lerobot-train sample holds o_t, o_{{t+1}} and future frames, not the frames in "
        "between that an n-step target compares with the goal; train with n_step=1 here, or with "
        "lerobot-indicator-train (--dataset.* seeds its episode buffer)"
    )
    with pytest.raises(ValueError, match=re.escape(message) + "$"):
        core.dataset_batch_to_transitions(dataset_batch(3), cfg)


# ------------------------------------------------------------------------------- 6. the loss's stats


def test_loss_stats_are_means_over_valid_rows_of_q_target_reward_and_filter():
    """The filter batch of test_learning_math (Q > q0 + 1.5 on rows 0-3, < q0 - 1.5 on rows 4-7; R+ on rows 2,
    3, 6, 7) with rows 0 and 6 invalid: the filter drops rows 0, 1; keep = valid and not dropped = rows 2, 3, 4,
    5, 7. Over the 6 valid rows: q_mean, q_std (population), q_target_mean, frac_positive = 3/6,
    frac_filtered = 1/6 (row 1), all goals recorded; the losses are means over the kept rows. No other stat
    is logged without ground truth, a reward model, inverse dynamics or a calibrated filter."""
    policy, batch = filter_batch_and_policy(1.0, -1.0)
    batch[core.NEXT_VALID] = ~mask(0, 6)
    loss, stats = loss_and_stats(policy, batch)
    assert set(stats) == BASE_STATS
    o, o1, g, a = batch[STATE], batch[core.NEXT + STATE], batch[GOAL], batch["action"]
    pa, qc, tpa, tqc = (
        weights(m) for m in (policy.actor, policy.critic, policy.target_actor, policy.target_critic)
    )
    valid, keep = ~mask(0, 6), mask(2, 3, 4, 5, 7)
    q = q_ref(qc, o, g, a)
    r = torch.where(mask(2, 3, 6, 7), 1.0, -1.0)
    y = (r + 0.75 * q_ref(tqc, o1, g, pi_ref(tpa, o1, g))).clamp(-4.0, 4.0)
    pi = pi_ref(pa, o, g)
    critic_loss = ((q - y) ** 2)[keep].mean()
    actor_loss = (-q_ref(qc, o, g, pi) + (pi**2).mean(dim=1))[keep].mean()
    close(stats["critic_loss"], critic_loss)
    close(stats["actor_loss"], actor_loss)
    close(loss, critic_loss + actor_loss)
    close(stats["q_mean"], q[valid].mean())
    close(stats["q_std"], q[valid].std(unbiased=False))
    close(stats["q_target_mean"], y[valid].mean())
    assert stats["frac_positive"].item() == pytest.approx(3 / 6)
    assert stats["frac_filtered"].item() == pytest.approx(1 / 6)
    assert [stats[f"frac_goal_{s}"].item() for s in ("next", "future", "recorded")] == [0.0, 0.0, 1.0]


def test_loss_goal_fractions_are_over_valid_rows():
    """Balanced relabeling (0.45 / 0.45 / 0.1) with the draws u of the module docstring: sources next, recorded,
    next, next, next, future, future, future. With rows 0 and 5 invalid: 3/6 next, 2/6 future, 1/6
    recorded."""
    policy = make_policy(filter=False)
    set_policy_weights(policy)
    batch = batch_of(OBS + [0.1, 0.2], NXT + [0.3, 0.4], GOALS + [0.5, 0.6], ACT + [0.0, 0.5])
    batch[core.NEXT_VALID] = ~mask(0, 5)
    _, stats = loss_and_stats(policy, batch, seed=SEED)
    got = [stats[f"frac_goal_{s}"].item() for s in ("next", "future", "recorded")]
    assert got == pytest.approx([3 / 6, 2 / 6, 1 / 6])


# ---------------------------------------------------------------------------- 7. the filter's options


def test_filter_q_target_drops_r_minus_rows_where_the_target_critic_is_above_q0():
    """filter_q="target": the target critic is the online one mirrored in o (Q' > q0 + 1.5 for o = -0.5), so
    the R- rows it drops are rows 4, 5, not the rows 0, 1 the online critic would; y still comes from the
    target critic on o_{t+1}."""
    policy, batch = filter_batch_and_policy(1.0, -1.0)
    policy.config.filter_q = "target"
    with torch.no_grad():
        for online, target in zip(linears(policy.critic), linears(policy.target_critic), strict=True):
            target.weight.copy_(online.weight)
            target.bias.copy_(online.bias)
        linears(policy.target_critic)[0].weight[0, 0] = -3.0
    loss, stats = loss_and_stats(policy, batch)
    o, o1, g, a = batch[STATE], batch[core.NEXT + STATE], batch[GOAL], batch["action"]
    pa, qc, tpa, tqc = (
        weights(m) for m in (policy.actor, policy.critic, policy.target_actor, policy.target_critic)
    )
    q_target = q_ref(tqc, o, g, a)
    q0 = policy.config.q0
    assert bool((q_target[4:6] > q0 + 1.5).all() and (q_target[:2] < q0 - 1.5).all())
    keep = ~mask(4, 5)
    r = torch.where(mask(2, 3, 6, 7), 1.0, -1.0)
    y = (r + 0.75 * q_ref(tqc, o1, g, pi_ref(tpa, o1, g))).clamp(-4.0, 4.0)
    close(stats["critic_loss"], ((q_ref(qc, o, g, a) - y) ** 2)[keep].mean())
    assert stats["frac_filtered"].item() == pytest.approx(2 / 8)


@pytest.mark.parametrize(
    "fraction, invalid, active",
    [(0.5, [], True), (0.6, [], False), (0.6, [6], True)],
    ids=["half-needed", "more-needed", "low-positive-invalid"],
)
def test_calibrated_filter_drops_only_once_enough_valid_positives_are_above_q0(fraction, invalid, active):
    """filter_start="calibrated" on the filter batch: of the R+ rows 2, 3, 6, 7 the first two have Q > q0, so
    the filter acts (drops rows 0, 1) for filter_calibration 0.5, not for 0.6, and again for 0.6 once the
    low-Q positive row 6 is invalid (2 of 3). filter_active logs the decision; the critic loss averages the
    kept valid rows."""
    policy, batch = filter_batch_and_policy(1.0, -1.0)
    policy.config.filter_start, policy.config.filter_calibration = "calibrated", fraction
    valid = ~mask(*invalid)
    batch[core.NEXT_VALID] = valid
    _, stats = loss_and_stats(policy, batch)
    assert set(stats) == BASE_STATS | {"filter_active"}
    assert stats["filter_active"].item() == float(active)
    keep = valid & (~mask(0, 1) if active else torch.ones(B, dtype=torch.bool))
    assert stats["frac_filtered"].item() == pytest.approx(2 / int(valid.sum()) if active else 0.0)
    o, o1, g, a = batch[STATE], batch[core.NEXT + STATE], batch[GOAL], batch["action"]
    qc, tpa, tqc = (weights(m) for m in (policy.critic, policy.target_actor, policy.target_critic))
    r = torch.where(mask(2, 3, 6, 7), 1.0, -1.0)
    y = (r + 0.75 * q_ref(tqc, o1, g, pi_ref(tpa, o1, g))).clamp(-4.0, 4.0)
    close(stats["critic_loss"], ((q_ref(qc, o, g, a) - y) ** 2)[keep].mean())


# ------------------------------------------------------------------------------- 8. the oracle reward

# Ground truth of o_{t+1} and of the recorded goal, 1-d; epsilon 0.5. Rows 1 and 3 have o_{t+1} == g bit for
# bit (what the indicator would reward), but the oracle looks at the ground truth only.
GT_NEXT = [0.0, 0.0, 1.0, 2.0, 0.3]
GT_GOAL = [0.4, 0.6, 1.0, -2.0, 0.8]  # distances 0.4, 0.6, 0, 4, 0.5 (= epsilon): success, no, yes, no, yes
ORACLE_SUCCESS = [True, False, True, False, True]


def oracle_batch() -> dict[str, Tensor]:
    batch = batch_of([0.1] * 5, [0.2, 0.7, 0.3, 0.9, 0.4], [0.5, 0.7, 0.6, 0.9, 0.8], [0.0] * 5)
    batch[core.GT_NEXT_ACHIEVED] = col(GT_NEXT)
    batch[core.GT_FUTURE_ACHIEVED] = col([9.0] * 5)
    batch[core.GT_DESIRED] = col(GT_GOAL)
    return batch


def oracle_policy(**overrides):
    """reward="oracle" with R+ = 2, R- = -0.5, epsilon 0.5, the recorded goal, no filter, Q = 0.3, Q' = 0."""
    policy = make_policy(
        reward="oracle",
        oracle_epsilon=0.5,
        positive_reward=2.0,
        negative_reward=-0.5,
        p_next=0.0,
        p_future=0.0,
        filter=False,
        **overrides,
    )
    set_policy_weights(policy)
    constant_critics(policy)
    return policy


def test_oracle_reward_is_r_plus_where_the_ground_truth_is_within_epsilon_of_the_goal():
    """reward="oracle" (R+ = 2, R- = -0.5): r = R+ where ||s_{t+1} - s_g|| <= epsilon, whatever the frames;
    with Q = 0.3 and Q' = 0, critic_loss = mean (0.3 - r)^2 and 3 of 5 rows are positive."""
    _, stats = loss_and_stats(oracle_policy(), oracle_batch())
    r = torch.where(torch.tensor(ORACLE_SUCCESS), 2.0, -0.5)
    close(stats["critic_loss"], ((0.3 - r) ** 2).mean())
    assert stats["frac_positive"].item() == pytest.approx(3 / 5)
    assert stats["reward_accuracy"].item() == 1.0


@pytest.mark.parametrize(
    ("fn_rate", "fp_rate", "expected_positive", "fn_seen", "fp_seen"),
    [(1.0, 0.0, [False] * 5, 1.0, 0.0), (0.0, 1.0, [True] * 5, 0.0, 1.0)],
)
def test_oracle_reward_flipped_at_rate_one_turns_every_true_positive_or_negative(
    fn_rate, fp_rate, expected_positive, fn_seen, fp_seen
):
    """The section-4 noisy oracle on the same batch: p_FN = 1 gives R- on all 5 rows (3 true positives
    flipped, the 2 negatives kept), p_FP = 1 gives R+ on all; the logged rates see the flips."""
    policy = oracle_policy(reward_false_negative_rate=fn_rate, reward_false_positive_rate=fp_rate)
    _, stats = loss_and_stats(policy, oracle_batch())
    r = torch.where(torch.tensor(expected_positive), 2.0, -0.5)
    close(stats["critic_loss"], ((0.3 - r) ** 2).mean())
    assert stats["false_negative_rate"].item() == fn_seen
    assert stats["false_positive_rate"].item() == fp_seen
    assert stats["reward_accuracy"].item() == pytest.approx(
        2 / 5 if fn_rate else 3 / 5
    )  # right only on the unflipped class


def test_noisy_oracle_flips_are_drawn_from_the_loss_generator():
    """p_FN = p_FP = 0.5: which rows flip depends on the generator passed to the loss alone (a run's seed),
    never on torch's global random state."""
    policy = oracle_policy(reward_false_negative_rate=0.5, reward_false_positive_rate=0.5)

    def flips(seed: int, global_seed: int) -> tuple[float, float]:
        torch.manual_seed(global_seed)
        _, stats = loss_and_stats(policy, oracle_batch(), seed=seed)
        return stats["critic_loss"].item(), stats["frac_positive"].item()

    assert len({flips(7, g) for g in range(4)}) == 1
    assert len({flips(seed, 0) for seed in range(8)}) > 1  # the draws do move with the seed


def test_flip_rewards_flips_each_class_at_its_own_rate_and_nothing_at_zero():
    success = torch.arange(200_000) % 4 == 0  # 50,000 true positives, 150,000 true negatives
    assert core.flip_rewards(success, 0.0, 0.0) is success
    g = torch.Generator().manual_seed(3)
    noisy = core.flip_rewards(success, 0.3, 0.05, g)
    assert (~noisy[success]).float().mean().item() == pytest.approx(0.3, abs=0.006)
    assert noisy[~success].float().mean().item() == pytest.approx(0.05, abs=0.002)
    u = torch.rand(success.shape, generator=torch.Generator().manual_seed(3))
    assert torch.equal(noisy, torch.where(success, u >= 0.3, u < 0.05))


def test_flip_rewards_keeps_a_draw_equal_to_the_fn_rate_and_flips_only_draws_below_the_fp_rate():
    # The draws the generator will give, taken as the rates: a positive is kept when u >= p_FN (so at u = p_FN
    # it is kept) and a negative turned positive when u < p_FP (so at u = p_FP it is not).
    u = torch.rand(2, generator=torch.Generator().manual_seed(5))
    out = core.flip_rewards(
        torch.tensor([True, False]), float(u[0]), float(u[1]), torch.Generator().manual_seed(5)
    )
    assert out.tolist() == [True, False]


def test_flip_rewards_draws_on_the_generator_device_and_answers_on_the_batch_device():
    """A CPU generator with a batch on another device (a CUDA batch in training; "meta" on CPU-only CI): the
    draws come from the generator on its own device whatever the default device, the result is on the batch's."""
    success = torch.tensor([True, False, True, False], device="meta")
    g, reference = torch.Generator().manual_seed(3), torch.Generator().manual_seed(3)
    with torch.device("meta"):
        out = core.flip_rewards(success, 0.3, 0.1, g)
    assert out.device.type == "meta" and out.shape == (4,) and out.dtype == torch.bool
    torch.rand(4, generator=reference)
    assert torch.equal(g.get_state(), reference.get_state())  # 4 draws taken from the CPU generator
    # No generator: torch's default one, on the batch's device.
    assert core.flip_rewards(torch.tensor([True, False]), 0.0, 1.0).tolist() == [True, True]


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"reward_false_negative_rate": 0.1}, "reward_false_negative_rate=0.1 flips the ground-truth reward"),
        ({"reward": "oracle", "reward_false_positive_rate": 1.5}, "must be in [0, 1], got 1.5"),
    ],
)
def test_reward_noise_needs_the_oracle_and_a_probability(overrides, message):
    with pytest.raises(Exception, match=re.escape(message)):
        IndicatorDDPGConfig(**overrides)


GT_MESSAGE = (
    "reward='oracle' needs ground truth in the batch: next.observation.gt_achieved_goal, "
    "future.observation.gt_achieved_goal, observation.gt_desired_goal"
)


@pytest.mark.parametrize("present", [[], [core.GT_NEXT_ACHIEVED], [core.GT_NEXT_ACHIEVED, core.GT_DESIRED]])
def test_oracle_reward_without_the_ground_truth_names_the_keys_it_needs(present):
    """Missing ground truth of the goal (one of the three keys absent), with or without o_{t+1}'s."""
    policy = make_policy(reward="oracle", p_next=0.0, p_future=0.0, filter=False)
    ground_truth = {core.GT_NEXT_ACHIEVED, core.GT_FUTURE_ACHIEVED, core.GT_DESIRED}
    batch = {k: v for k, v in oracle_batch().items() if k not in ground_truth or k in present}
    with pytest.raises(ValueError, match=re.escape(GT_MESSAGE) + "$"):
        loss_and_stats(policy, batch)


def test_oracle_n_step_error_names_the_path_ground_truth_too():
    policy = make_policy(reward="oracle", p_next=0.0, p_future=0.0, filter=False, n_step=2)
    batch = batch_of([0.1] * 3, [0.2] * 3, [0.3] * 3, [0.0] * 3)
    with pytest.raises(ValueError, match=re.escape(GT_MESSAGE + ", path.observation.gt_achieved_goal") + "$"):
        loss_and_stats(policy, batch)


# ------------------------------------------------------------------------------ 9. learned rewards


class StubReward(nn.Module):
    """A reward model with a known reward r = 1 / (1 + (o' - g)^2) and loss 0.5 mean(o^2) (one parameter)."""

    def __init__(self):
        super().__init__()
        self.scale = nn.Parameter(torch.tensor(0.5))

    def reward_to(self, goal: dict[str, Tensor]):
        return lambda frames: 1 / (1 + (frames[STATE] - goal[STATE]).square().sum(dim=1))

    def loss(self, frames: dict[str, Tensor]) -> tuple[Tensor, dict[str, Tensor]]:
        value = self.scale * frames[STATE].square().mean()
        return value, {"reward_model_reconstruction": value.detach()}


def learned_policy(reward: str = "ae") -> IndicatorDDPGPolicy:
    """A state policy whose config asks for a learned reward (its own networks; the model is passed in)."""
    policy = make_policy(p_next=0.0, p_future=0.0, filter=False)
    policy.config.reward = reward
    set_policy_weights(policy)
    constant_critics(policy)
    return policy


def test_learned_reward_comes_from_the_model_on_next_obs_and_goal_and_its_loss_is_added():
    """reward="ae" with a model: r = model.reward(o_{t+1}, g) (y = r with Q' = 0, inside [0, T]); the total
    loss adds model.loss(o_t) to critic + actor; the model's stats and reward_mean (over valid rows) are
    logged, and with ground truth the ranking AUC too."""
    policy = learned_policy()
    batch = batch_of(OBS, NXT, GOALS, ACT)
    valid = ~mask(1, n=len(OBS))
    batch[core.NEXT_VALID] = valid
    batch[core.GT_NEXT_ACHIEVED] = col(NXT)
    batch[core.GT_FUTURE_ACHIEVED] = col([9.0] * len(OBS))
    batch[core.GT_DESIRED] = col(GOALS)
    loss, stats = loss_and_stats(policy, batch, reward_model=StubReward())
    o, o1, g = batch[STATE], batch[core.NEXT + STATE], batch[GOAL]
    r = 1 / (1 + (o1 - g).squeeze(1) ** 2)
    close(stats["critic_loss"], ((0.3 - r) ** 2)[valid].mean())
    pi = pi_ref(weights(policy.actor), o, g)
    actor_loss = (-0.3 + (pi**2).mean(dim=1))[valid].mean()
    close(stats["actor_loss"], actor_loss)
    model_loss = 0.5 * (o**2).mean()
    close(loss, stats["critic_loss"] + actor_loss + model_loss)
    close(stats["reward_model_reconstruction"], model_loss)
    close(stats["reward_mean"], r[valid].mean())
    assert set(stats) >= BASE_STATS | {"reward_model_reconstruction", "reward_mean", "reward_auc"}
    assert (r == 1.0).tolist() == POSITIVE_ROWS  # the model's best reward exactly where o_{t+1} == g


@pytest.mark.parametrize("reward", ["ae", "vae"])
def test_learned_reward_without_a_model_is_refused(reward):
    policy = learned_policy(reward)
    with pytest.raises(
        ValueError, match=re.escape(f"reward={reward!r} needs the policy's reward_model") + "$"
    ):
        loss_and_stats(policy, batch_of(OBS, NXT, GOALS, ACT))


# ------------------------------------------------------------------- 10. inverse dynamics in the stats


@pytest.mark.parametrize("weight", [0.0, 0.5])
def test_inverse_dynamics_loss_is_logged_and_added_with_its_weight(weight):
    """inverse_dynamics = w > 0 adds w * mean_i mean_a (tanh(g(enc(o_t), enc(o_{t+1}))) - a_t)^2 to the loss
    and logs the mean; with w = 0 there is no such network and no such stat."""
    cam = "observation.images.cam"
    features = {cam: (FeatureType.VISUAL, (2, 8, 8))}
    torch.manual_seed(0)
    policy = make_image_policy(
        features,
        horizon=T,
        hidden_dims=[4],
        conv_channels=[2],
        conv_strides=[2],
        feature_dim=4,
        augment_pad=0,
        conv_precision="float32",
        inverse_dynamics=weight,
        filter=False,
    )
    batch = make_batch(features, 4)
    loss, stats = loss_and_stats(policy, batch)
    if weight == 0.0:
        assert set(stats) == BASE_STATS
        return
    assert set(stats) == BASE_STATS | {"inverse_dynamics_loss"}
    with torch.no_grad():
        transition = policy.critic.encode({cam: batch[cam]}, {cam: batch[core.NEXT + cam]})
        expected = ((torch.tanh(policy.critic.inverse(transition)) - batch["action"]) ** 2).mean()
    close(stats["inverse_dynamics_loss"], expected)
    close(loss, stats["critic_loss"] + stats["actor_loss"] + weight * expected)
