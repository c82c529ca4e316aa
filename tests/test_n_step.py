"""n-step TD targets (``--policy.n_step``): hand-computed returns and bootstraps, the buffer's path frames.

Setup as tests/test_learning_math.py: 1-dim state, hidden_dims=[2], T = 4 (gamma = 3/4, q_min = -4,
q_max = 4), recorded goals only (p_next = p_future = 0) so each row's goal is the one written here.
"""

import numpy as np
import pytest
import torch
from test_learning_math import (
    GOAL,
    STATE,
    LossSpy,
    T,
    batch_of,
    close,
    differs,
    linears,
    make_policy,
    pi_ref,
    q_ref,
    set_policy_weights,
    weights,
)

from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfigError
from lerobot_indicator.training.batches import to_transition_batch
from lerobot_indicator.training.replay_buffer import EpisodeReplayBuffer

GAMMA = (T - 1) / T
# Rows (n = 3, so the path holds o_{t+2}, o_{t+3}; steps past o_T hold o_T):
# 0: t = 0, goal = o_{t+2}            -> r = -1, +1, -1; bootstrap o_{t+3}, gamma^3
# 1: t = 2, goal = o_{t+1}            -> r = +1, -1 (o_{t+2} = o_T); bootstrap o_T, gamma^2
# 2: t = 3 (= T-1), goal never seen   -> r = -1; bootstrap o_{t+1} = o_T, gamma
# 3: t = 1, goal = o_{t+3}            -> r = -1, -1, +1; bootstrap o_{t+3}, gamma^3
OBS = [0.1, 0.5, -0.3, 0.2]
NXT = [0.4, 0.9, -0.6, 0.7]
PATH = [[0.8, -0.2], [1.3, 1.3], [-0.6, -0.6], [0.6, -0.9]]
VALID = [[True, True], [True, False], [False, False], [True, True]]
GOALS = [0.8, 0.9, 2.0, -0.9]
ACT = [0.3, -0.6, 0.8, -0.1]
RETURNS = [
    -1 + GAMMA - GAMMA**2,
    1 - GAMMA,
    -1.0,
    -1 - GAMMA + GAMMA**2,
]
STEPS = [3, 2, 1, 3]


def n_step_batch() -> dict[str, torch.Tensor]:
    batch = batch_of(OBS, NXT, GOALS, ACT)
    batch[core.PATH + STATE] = torch.tensor(PATH, dtype=torch.float32)[:, :, None]
    batch[core.PATH_VALID] = torch.tensor(VALID)
    return batch


def test_n_step_target_sums_discounted_indicator_rewards_and_bootstraps_from_the_last_path_frame(monkeypatch):
    """y = clip(sum_{i<=n'} gamma^(i-1) r_{t+i} + gamma^n' Q'(o_{t+n'}, g, pi'(o_{t+n'}, g)), n' = min(n, T-t),
    each r_{t+i} = R+ iff o_{t+i} equals the goal. Bootstrapping from o_{t+1}, a fixed gamma^n or only the
    first reward each gives a clearly different loss."""
    policy = make_policy(p_next=0.0, p_future=0.0, filter=False, n_step=3)
    set_policy_weights(policy)
    with torch.no_grad():
        linears(policy.target_critic)[-1].weight.mul_(0.3)  # keep every y inside (q_min, q_max)
    batch = n_step_batch()
    _, critic_loss, _, _, _, stats = LossSpy(monkeypatch).run(policy, batch)

    o, o1, g, a = batch[STATE], batch[core.NEXT + STATE], batch[GOAL], batch["action"]
    boot = batch[core.PATH + STATE][:, -1]
    tpa, tqc = weights(policy.target_actor), weights(policy.target_critic)
    q = q_ref(weights(policy.critic), o, g, a)

    def y(returns, discount, frame):
        next_q = q_ref(tqc, frame, g, pi_ref(tpa, frame, g))
        return (torch.tensor(returns) + torch.tensor(discount) * next_q).clamp(-4.0, 4.0)

    expected_y = y(RETURNS, [GAMMA**s for s in STEPS], boot)
    assert bool(((expected_y > -4) & (expected_y < 4)).all()), "this test wants y strictly inside the bounds"
    close(critic_loss, ((q - expected_y) ** 2).mean())
    first_rewards = [-1.0, 1.0, -1.0, -1.0]
    for wrong in (
        y(RETURNS, [GAMMA**s for s in STEPS], o1),
        y(RETURNS, [GAMMA**3] * 4, boot),
        y(first_rewards, [GAMMA**s for s in STEPS], boot),
    ):
        assert differs(((q - wrong) ** 2).mean(), critic_loss)
    # The logged reward statistics and the filter use r_{t+1} (the paper's reward), not the n-step return.
    assert stats["frac_positive"] == pytest.approx(0.25)


def test_n_step_filter_tests_the_first_reward():
    """The filter drops R- transitions with Q > q0 by r_{t+1}: row 0 (r_{t+1} = R-, a later R+ in its path)
    is dropped when every Q is above q0, row 1 (r_{t+1} = R+) never is."""
    policy = make_policy(p_next=0.0, p_future=0.0, filter=True, n_step=3)
    set_policy_weights(policy)
    with torch.no_grad():
        linears(policy.critic)[-1].bias.fill_(100.0)  # Q > q0 = 3 on every row
    _, stats = policy.forward(n_step_batch(), generator=torch.Generator().manual_seed(0))
    assert stats["frac_filtered"] == pytest.approx(0.75)  # rows 0, 2, 3


def test_n_step_one_path_step_per_extra_step_with_oracle_rewards(monkeypatch):
    """Oracle rewards along the path come from the path frames' ground truth: a row whose o_{t+2} is within
    epsilon of the goal gets R+ at i = 2."""
    policy = make_policy(
        p_next=0.0, p_future=0.0, filter=False, n_step=2, reward="oracle", oracle_epsilon=0.05
    )
    set_policy_weights(policy)
    batch = batch_of([0.0, 0.0], [0.1, 0.2], [0.5, 0.5], [0.1, 0.1])
    batch[core.PATH + STATE] = torch.tensor([[[0.3]], [[0.9]]])
    batch[core.PATH_VALID] = torch.tensor([[True], [True]])
    batch[core.GT_NEXT_ACHIEVED] = torch.tensor([[0.1], [0.2]])
    batch[core.GT_FUTURE_ACHIEVED] = torch.tensor([[4.0], [4.0]])
    batch[core.GT_DESIRED] = torch.tensor([[0.5], [0.5]])
    batch[core.GT_PATH_ACHIEVED] = torch.tensor([[[0.52]], [[0.9]]])  # row 0 arrives at step 2
    _, critic_loss, _, _, _, _ = LossSpy(monkeypatch).run(policy, batch)
    g, boot = batch[GOAL], batch[core.PATH + STATE][:, -1]
    tpa, tqc = weights(policy.target_actor), weights(policy.target_critic)
    next_q = q_ref(tqc, boot, g, pi_ref(tpa, boot, g))
    y = (torch.tensor([-1 + GAMMA, -1 - GAMMA]) + GAMMA**2 * next_q).clamp(-4.0, 4.0)
    q = q_ref(weights(policy.critic), batch[STATE], g, batch["action"])
    close(critic_loss, ((q - y) ** 2).mean())


def test_replay_path_frames_are_the_next_n_minus_one_clamped_at_the_episode_end():
    """``sample(n_step=n)``: path_obs[:, j] = o_{min(t+2+j, T)}, path_valid = t+2+j <= T, ground truth
    alike, for every t including T-1 (no valid step); the path's last entry is the bootstrap frame."""
    buffer = EpisodeReplayBuffer(100 * T, T)
    frames = np.arange(T + 1, dtype=np.float32)[:, None]
    for e in range(3):
        buffer.add_episode(
            {STATE: frames + 10 * e, GOAL: np.full((1, 1), -1.0, np.float32)},
            np.zeros((T, 1), np.float32),
            {"gt_achieved_goal": frames + 10 * e, "gt_desired_goal": np.zeros(1, np.float32)},
        )
    sample = buffer.sample(400, np.random.default_rng(0), n_step=3)
    t, ep = sample["t"], sample["episode"]
    assert set(t.tolist()) == set(range(T))
    expected = np.minimum(t[:, None] + [2, 3], T) + 10 * ep[:, None]
    np.testing.assert_array_equal(sample["path_obs"][STATE][..., 0], expected)
    np.testing.assert_array_equal(sample["gt_path_achieved"][..., 0], expected)
    np.testing.assert_array_equal(sample["path_valid"], t[:, None] + [2, 3] <= T)
    batch = to_transition_batch(sample, [STATE], T, "cpu")
    assert batch[core.PATH + STATE].shape == (400, 2, 1) and batch[core.PATH_VALID].dtype == torch.bool
    assert "path_obs" not in buffer.sample(4, np.random.default_rng(0))  # n_step=1: nothing extra


def test_n_step_fields_are_checked_and_lerobot_train_batches_refuse_it():
    with pytest.raises(IndicatorDDPGConfigError, match="n_step must be >= 1"):
        make_policy(n_step=0)
    policy = make_policy(n_step=3)
    frames = torch.zeros(2, 2 + len(policy.config.future_offsets), 1)
    batch = {STATE: frames, GOAL: frames, "action": torch.zeros(2, 1)}
    with pytest.raises(ValueError, match="n_step=3: a lerobot-train sample"):
        core.dataset_batch_to_transitions(batch, policy.config)


def test_inverse_dynamics_with_n_step_still_predicts_a_t_from_o_t_and_o_next():
    """With n-step targets the bootstrap frame is o_{t+n}, but the inverse-dynamics loss must still see
    (o_t, o_{t+1}): the same weights and frames give the same loss as with one-step targets."""
    from test_visual_encoder import DEPTH, RGB, policy_and_batch

    losses = {}
    for n in (1, 3):
        policy, batch = policy_and_batch(
            batch_size=8, augment_pad=0, inverse_dynamics=1.0, n_step=n, conv_precision="float32"
        )
        for k in (RGB, DEPTH):
            far = torch.roll(batch[core.NEXT + k], 1, dims=0)  # o_{t+2}, o_{t+3}: other frames than o_{t+1}
            batch[core.PATH + k] = torch.stack([far, torch.roll(far, 1, dims=0)], dim=1)
        batch[core.PATH_VALID] = torch.ones(8, 2, dtype=torch.bool)
        _, stats = policy.forward(batch, generator=torch.Generator().manual_seed(0))
        losses[n] = stats["inverse_dynamics_loss"]
    assert losses[3] == pytest.approx(losses[1], rel=1e-5)
