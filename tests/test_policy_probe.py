"""The stuck-state probe reports which way the actor and the critic's best action move, per axis."""

import torch
from torch import nn

from benchmarks.probes.policy_probe import stuck_state_probe
from benchmarks.speed.updates import STATE_FEATURES, make_policy
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


def test_critic_saturation_reads_a_saturated_layer_and_a_constant_q():
    """hidden_dims=[3, 2]: with the second layer's bias at +100 both its units sit at tanh(100) = 1 for every
    input (saturated fraction 1, std 0) and Q = w . 1 + b is the same for every row and action; with a zero
    bias that layer follows the input and Q varies."""
    from benchmarks.probes.policy_probe import critic_saturation, env_frames

    env = SawyerReachEnvConfig(obs_type="state", episode_length=4)
    policy = make_policy(STATE_FEATURES, horizon=4, hidden_dims=[3, 2])
    obs, goal = env_frames(policy, env, episodes=2, steps=3)
    assert len(obs["observation.state"]) == 6
    actions = torch.linspace(-1, 1, 18).reshape(6, 3)
    first, second, last = [m for m in policy.critic.net if isinstance(m, nn.Linear)]
    with torch.no_grad():
        first.weight.fill_(0.3)
        second.weight.fill_(0.5)
        second.bias.fill_(100.0)
        last.weight.copy_(torch.tensor([[2.0, 3.0]]))
        last.bias.fill_(-1.0)
    r = critic_saturation(policy.critic, obs, goal, actions)
    assert [h["saturated_fraction"] for h in r["hidden_layers"]] == [
        r["hidden_layers"][0]["saturated_fraction"],
        1.0,
    ]
    assert r["hidden_layers"][1]["unit_std"] == 0.0
    assert r["q_mean"] == 4.0 and r["q_std_over_batch"] == 0.0 and r["q_std_over_actions"] == 0.0
    with torch.no_grad():
        second.bias.zero_()
    r = critic_saturation(policy.critic, obs, goal, actions)
    assert r["hidden_layers"][1]["saturated_fraction"] < 1.0 and r["q_std_over_batch"] > 1e-3
    assert r["q_std_over_actions"] > 1e-3 and r["frames"] == 6
