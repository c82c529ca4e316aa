"""The stuck-state probe reports which way the actor and the critic's best action move, per axis."""

import torch
from torch import nn

from lerobot_indicator.bench.policy_probe import stuck_state_probe
from lerobot_indicator.bench.updates import STATE_FEATURES, make_policy
from lerobot_indicator.envs.configs import SawyerReachEnvConfig


def test_an_actor_that_steers_to_the_goal_counts_as_toward_and_a_critic_preferring_zero_as_staying():
    """Actor pi(o, g) = tanh(20 tanh(10 (g - o))) moves each axis toward the goal; the critic Q = -|a|^2 (a
    stand-in for a critic head) prefers the zero action everywhere."""
    env = SawyerReachEnvConfig(obs_type="state", episode_length=6)
    policy = make_policy(STATE_FEATURES, horizon=6, hidden_dims=[3])
    eye = torch.eye(3)
    with torch.no_grad():
        first, last = [m for m in policy.actor.net if isinstance(m, nn.Linear)]
        first.weight.copy_(10 * torch.cat([-eye, eye], dim=1))
        first.bias.zero_()
        last.weight.copy_(20 * eye)
        last.bias.zero_()
    # A critic preferring the zero action everywhere: Q(o, g, a) = -|tanh(a)|^2.
    policy.critic.head = lambda features, action, frozen=False: -(torch.tanh(action) ** 2).sum(dim=1)
    report = stuck_state_probe(policy, env, episodes=3)
    assert report["episodes"] == 3 and sum(report["far_states_second_half"]) > 0
    far = [i for i, n in enumerate(report["far_states_second_half"]) if n > 0]
    assert all(report["actor_moves_toward_goal"][i] == 1.0 for i in far), report
    assert all(report["critic_best_stays"][i] == 1.0 for i in far), report
    # Six steps of up to 5 cm toward the goal: the final distance is the start distance minus what it moved.
    assert report["final_distance_mean_m"] < report["start_distance_mean_m"] - 0.1, report
    assert len(report["corr_final_error_vs_goal"]) == 3
