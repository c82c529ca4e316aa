"""The pusher-cue probe measures how far each push of a policy ends from the goal image's resting pusher."""

import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
pytest.importorskip("robosuite")
pytest.importorskip("mujoco")

import gymnasium as gym  # noqa: E402
import torch  # noqa: E402
from lerobot.configs import FeatureType  # noqa: E402

from benchmarks.probes.pusher_cue import pusher_cue_probe, summarise  # noqa: E402
from benchmarks.speed.updates import make_policy  # noqa: E402
from lerobot_indicator.envs import ROPE_PUSH_ID  # noqa: E402
from lerobot_indicator.envs import rope_cache as rc  # noqa: E402
from lerobot_indicator.envs.configs import RopePushEnvConfig  # noqa: E402
from lerobot_indicator.keys import EVAL_SEED_OFFSET, GT_DISTANCE  # noqa: E402


class ConstantActor(torch.nn.Module):
    def __init__(self, action: torch.Tensor):
        super().__init__()
        self.action = action

    def forward(self, obs: dict, goal: dict) -> torch.Tensor:
        return self.action


def test_summary_of_hand_made_misses():
    """Two episodes of two pushes: last-push misses 0.04 and 0.06 m (mean 0.05; one within 5 cm), chance
    0.4 and 0.3 (mean 0.35), and the lower miss with the higher rope distance (Spearman -1)."""
    r = summarise(np.array([[0.2, 0.04], [0.1, 0.06]]), np.array([0.4, 0.3]), np.array([0.5, 0.3]))
    assert r["episodes"] == 2
    assert r["push_end_to_goal_pusher_m_per_step"] == pytest.approx([0.15, 0.05])
    assert r["last_push_end_to_goal_pusher_m"] == pytest.approx(0.05)
    assert r["random_push_end_to_goal_pusher_m"] == pytest.approx(0.35)
    assert r["last_push_within_5cm_of_goal_pusher"] == 0.5
    assert r["spearman_last_push_miss_vs_final_distance"] == pytest.approx(-1.0)
    assert r["final_distance_mean"] == pytest.approx(0.4)


def test_a_constant_push_is_measured_against_each_evaluation_goals_last_hidden_push(tmp_path):
    """An actor that always pushes the same way: every push ends at the same table point, so each episode's
    miss is that point's distance to where its goal's last hidden push ended, read here from an env reset
    with the same evaluation seed; the rope distance is what the same pushes leave in that env."""
    cache = rc.generate_cache(tmp_path / "cache.npz", n=2, seed=3, workers=0, chunk_size=1, progress=False)
    cfg = RopePushEnvConfig(obs_type="state", cache_path=str(cache), pusher_rest="push_end")
    policy = make_policy({"observation.state": (FeatureType.STATE, (45,))}, horizon=3)
    push = torch.tensor([[0.2, -0.5, -0.1, 0.3]])
    policy.actor = ConstantActor(push)
    report = pusher_cue_probe(policy, cfg, episodes=3, random_pushes=50)

    env = gym.make(ROPE_PUSH_ID, **cfg.gym_kwargs).unwrapped
    misses, distances = [], []
    for episode in range(3):
        env.reset(seed=EVAL_SEED_OFFSET + episode)
        goal_rest = env.sim.action_to_points(env.goal_push_actions[-1])[1]
        misses.append(np.linalg.norm(env.sim.action_to_points(push[0].numpy())[1] - goal_rest))
        for _ in range(3):
            *_, info = env.step(push[0].numpy())
        distances.append(info[GT_DISTANCE])
    env.close()
    assert len(set(np.round(misses, 6))) > 1  # the evaluation goals differ in where their pusher rests
    assert report["push_end_to_goal_pusher_m_per_step"] == pytest.approx([np.mean(misses)] * 3)
    assert report["last_push_end_to_goal_pusher_m"] == pytest.approx(np.mean(misses))
    assert report["final_distance_mean"] == pytest.approx(np.mean(distances), abs=1e-5)
    assert 0.05 < report["random_push_end_to_goal_pusher_m"] < 1.0


def test_an_env_without_pushes_is_refused_by_name():
    from lerobot_indicator.envs.configs import SawyerReachEnvConfig

    policy = make_policy({"observation.state": (FeatureType.STATE, (3,))}, horizon=3)
    with pytest.raises(ValueError, match="needs --env.type=rope_push, got --env.type=sawyer_reach"):
        pusher_cue_probe(policy, SawyerReachEnvConfig(obs_type="state"))
