"""Episode replay buffer: sampling respects episode boundaries and the paper's future-goal rule."""

import numpy as np
import pytest

from lerobot_indicator.training.replay_buffer import EpisodeReplayBuffer

T = 5


def _episode(ep_id: int) -> tuple[dict, np.ndarray, dict]:
    """Each value encodes (episode, step) so a sample can be traced back to where it came from."""
    steps = np.arange(T + 1)
    state = np.stack([np.full(T + 1, ep_id), steps, np.zeros(T + 1)], axis=1).astype(np.float32)
    image = np.zeros((T + 1, 3, 4, 4), np.float32)  # policy layout: CHW floats k/255
    image[:, 0, 0, 0], image[:, 1, 0, 0] = ep_id, steps
    image /= np.float32(255)
    obs = {
        "observation.state": state,
        "observation.goal_state": np.full((1, 3), 100 + ep_id, np.float32),
        "observation.images.front": image,
        "observation.images.goal_front": np.full((1, 3, 4, 4), ep_id, np.float32) / np.float32(255),
    }
    actions = np.stack([np.full(T, ep_id), np.arange(T), np.zeros(T)], axis=1).astype(np.float32)
    gt = {"gt_achieved_goal": state.copy(), "gt_desired_goal": np.full(3, 100 + ep_id, np.float32)}
    return obs, actions, gt


def test_sampling_stays_inside_the_episode_and_follows_the_future_rule():
    buf = EpisodeReplayBuffer(capacity_transitions=10 * T, horizon=T)
    for e in range(7):
        buf.add_episode(*_episode(e))
    b = buf.sample(4096, np.random.default_rng(0))
    ep = b["obs"]["observation.state"][:, 0]
    t = b["obs"]["observation.state"][:, 1]
    assert np.all(b["next_obs"]["observation.state"][:, 0] == ep)
    assert np.all(b["next_obs"]["observation.state"][:, 1] == t + 1)
    assert np.all(b["action"][:, 0] == ep) and np.all(b["action"][:, 1] == t)
    assert np.all(b["obs"]["observation.goal_state"][:, 0] == 100 + ep)
    assert np.all(b["obs"]["observation.images.goal_front"][:, 0, 0, 0] * 255 == ep)
    assert np.all(np.rint(b["obs"]["observation.images.front"][:, 1, 0, 0] * 255) == t)
    fut = b["future_obs"]["observation.state"]
    has = b["has_future"]
    assert np.all(fut[has, 0] == ep[has]), "future goal taken from another episode"
    assert np.all(fut[has, 1] >= t[has] + 2) and np.all(fut[has, 1] <= T)
    assert np.array_equal(has, t + 2 <= T)
    # t' is uniform over {t+2..T}: for t = 0 each of the T-1 choices appears about equally often.
    counts = np.bincount(fut[(t == 0)][:, 1].astype(int), minlength=T + 1)[2:]
    assert counts.min() > 0.6 * counts.mean()
    assert np.array_equal(b["gt_future_achieved"][has], fut[has])


def test_fifo_overwrites_oldest_episode():
    buf = EpisodeReplayBuffer(capacity_transitions=3 * T, horizon=T)
    for e in range(5):
        buf.add_episode(*_episode(e))
    assert len(buf) == 3 * T
    assert sorted(set(buf.obs["observation.state"][:, 0, 0].astype(int))) == [2, 3, 4]


def test_bad_episodes_are_rejected():
    buf = EpisodeReplayBuffer(capacity_transitions=4 * T, horizon=T)
    obs, actions, gt = _episode(0)
    with pytest.raises(ValueError, match="actions"):
        buf.add_episode(obs, actions[:-1], gt)
    buf.add_episode(obs, actions, gt)
    with pytest.raises(ValueError, match="keys"):
        buf.add_episode({k: v for k, v in obs.items() if k != "observation.images.front"}, actions, gt)
    with pytest.raises(RuntimeError, match="empty"):
        EpisodeReplayBuffer(4 * T, T).sample(1, np.random.default_rng())


def test_packing_is_lossless_and_compact():
    buf = EpisodeReplayBuffer(capacity_transitions=4 * T, horizon=T)
    obs, actions, gt = _episode(1)
    depth_mm = np.arange((T + 1) * 16, dtype=np.float32).reshape(T + 1, 1, 4, 4) + 250
    buf.add_episode({**obs, "observation.images.front_depth": depth_mm}, actions, gt)
    assert buf.obs["observation.images.front"].dtype == np.uint8
    assert buf.obs["observation.images.front_depth"].dtype == np.uint16
    assert np.array_equal(buf.obs["observation.images.front"][0], obs["observation.images.front"])
    assert np.array_equal(buf.obs["observation.images.front_depth"][0], depth_mm)
    # A later episode that does not pack exactly widens the key instead of losing bits.
    obs2, actions2, gt2 = _episode(2)
    obs2["observation.state"] = obs2["observation.state"] + np.float32(0.123)
    buf.add_episode({**obs2, "observation.images.front_depth": depth_mm}, actions2, gt2)
    assert buf.obs["observation.state"].dtype == np.float32
    assert np.array_equal(buf.obs["observation.state"][1], obs2["observation.state"])
    assert np.array_equal(buf.obs["observation.state"][0], obs["observation.state"])


def _frames_and_goal(e: int, key: str) -> np.ndarray:
    obs = _episode(e)[0]
    head, _, name = key.rpartition(".")
    return np.concatenate([obs[key], obs[f"{head}.goal_{name}"]])


def test_observation_stats_cover_frames_and_goals_of_the_stored_episodes():
    """Per dimension / per channel mean and std over each stored episode's T + 1 frames and its goal (the
    goal counts: it shares the observation's normalisation); evicted episodes drop out."""
    buf = EpisodeReplayBuffer(capacity_transitions=4 * T, horizon=T)
    for e in range(3):
        buf.add_episode(*_episode(e))
    stats = buf.observation_stats()
    state = np.concatenate([_frames_and_goal(e, "observation.state") for e in range(3)])
    np.testing.assert_allclose(stats["observation.state"]["mean"], state.mean(0), rtol=1e-6)
    np.testing.assert_allclose(stats["observation.state"]["std"], state.std(0), rtol=1e-6)
    image = np.concatenate([_frames_and_goal(e, "observation.images.front") for e in range(3)])
    assert stats["observation.images.front"]["mean"].shape == (3, 1, 1)
    assert {a.dtype for s in stats.values() for a in s.values()} == {np.dtype(np.float32)}  # LeRobot's stats
    np.testing.assert_allclose(
        stats["observation.images.front"]["mean"][:, 0, 0], image.mean((0, 2, 3)), rtol=1e-6
    )
    np.testing.assert_allclose(
        stats["observation.images.front"]["std"][:, 0, 0], image.std((0, 2, 3)), rtol=1e-5
    )
    assert "observation.goal_state" not in stats  # goals are normalised with their observation's stats

    for e in range(3, 6):  # capacity 4: episodes 0 and 1 are evicted
        buf.add_episode(*_episode(e))
    state = np.concatenate([_frames_and_goal(e, "observation.state") for e in range(2, 6)])
    np.testing.assert_allclose(buf.observation_stats()["observation.state"]["mean"], state.mean(0), rtol=1e-6)


def test_packing_keeps_the_sign_of_zero_bit_for_bit():
    """An integer-valued float state with -0.0 must not be packed into an integer dtype (it would return +0.0)."""
    T = 2
    buf = EpisodeReplayBuffer(4 * T, T)
    state = np.array([[0.0, 1.0], [-0.0, 2.0], [3.0, 0.0]], np.float32)
    buf.add_episode(
        {"observation.state": state, "observation.goal_state": state[:1]}, np.zeros((T, 1), np.float32)
    )
    stored = buf.obs["observation.state"][0]
    assert np.array_equal(stored.view(np.uint32), state.view(np.uint32))
