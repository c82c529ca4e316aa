"""Our state-based goal envs as the ``Dict(observation, achieved_goal, desired_goal)`` GoalEnv that
Stable-Baselines3's ``HerReplayBuffer`` (and gymnasium-robotics' Fetch tasks) expect.

Used by ``benchmarks/experiments/run_vs_sb3.py`` to run SB3 DDPG/TD3 + HER on the very same simulator. SB3 relabels goals
itself and asks the env for rewards through a *vectorised* ``compute_reward(achieved, desired, info)``; this
one is the ground-truth sparse reward the env's ``step`` returns and our ``reward=oracle`` baseline uses:
+1 when ``||achieved - desired|| <= epsilon``, else -1 (SB3 uses the reward as given, so keeping the env's
+1/-1 makes SB3's targets live on the same scale as ours; the more common Fetch form 0/-1 differs by a
constant shift of the return).

Ground truth only: this adapter gives the learner the achieved/desired *state*, i.e. more information than
the indicator reward, which only compares raw observations.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

OBSERVATION, ACHIEVED, DESIRED = "observation", "achieved_goal", "desired_goal"


def sparse_goal_reward(achieved: np.ndarray, desired: np.ndarray, epsilon: float) -> np.ndarray:
    """+1 where ``||achieved - desired|| <= epsilon`` over the last axis, else -1 (float32, batch shape)."""
    achieved, desired = np.asarray(achieved), np.asarray(desired)
    if achieved.shape != desired.shape:
        raise ValueError(f"achieved {achieved.shape} and desired {desired.shape} goals differ in shape")
    distance = np.linalg.norm(achieved - desired, axis=-1)
    return np.where(distance <= epsilon, 1.0, -1.0).astype(np.float32)


class GoalEnvAdapter(gym.Wrapper):
    """Wrap an env whose obs dict has ``agent_pos`` and ``goal_state`` (``obs_type=state``).

    observation = achieved_goal = ``agent_pos`` (the gripper xyz is both the state and what is achieved),
    desired_goal = ``goal_state``. Reward, ``info`` and time-limit truncation pass through unchanged.
    """

    def __init__(self, env: gym.Env):
        super().__init__(env)
        spaces = env.observation_space
        if not isinstance(spaces, gym.spaces.Dict) or not {"agent_pos", "goal_state"} <= set(spaces):
            raise ValueError(
                f"GoalEnvAdapter needs an obs dict with 'agent_pos' and 'goal_state' (obs_type=state), got "
                f"{spaces}"
            )
        if set(spaces) != {"agent_pos", "goal_state"}:
            raise ValueError(f"GoalEnvAdapter wraps state observations only, got keys {sorted(spaces)}")
        self.epsilon = float(env.unwrapped.epsilon)
        pos, goal = spaces["agent_pos"], spaces["goal_state"]
        self.observation_space = gym.spaces.Dict({OBSERVATION: pos, ACHIEVED: pos, DESIRED: goal})

    @staticmethod
    def _goal_obs(obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {OBSERVATION: obs["agent_pos"], ACHIEVED: obs["agent_pos"].copy(), DESIRED: obs["goal_state"]}

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        return self._goal_obs(obs), info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._goal_obs(obs), reward, terminated, truncated, info

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        """Vectorised over leading axes (SB3 passes (B, 3) goals and a list of info dicts, unused)."""
        return sparse_goal_reward(achieved_goal, desired_goal, self.epsilon)


def make_goal_env(env_id: str = "lerobot_indicator/SawyerReach-v0", **kwargs) -> GoalEnvAdapter:
    """``gym.make(env_id, obs_type="state", **kwargs)`` (with its TimeLimit) wrapped as a GoalEnv."""
    import lerobot_indicator  # noqa: F401  (registers the gymnasium ids)

    kwargs.setdefault("obs_type", "state")
    kwargs.setdefault("render_mode", None)
    return GoalEnvAdapter(gym.make(env_id, **kwargs))
