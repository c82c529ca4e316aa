"""The online trainer's batch assembly: every replay-sample field lands under its core key, as it was sampled,
on the requested device, with packed frames converted only where the networks could not take them."""

import numpy as np
import torch

from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.training.batches import to_transition_batch
from lerobot_indicator.training.replay_buffer import EpisodeReplayBuffer

T = 4
IMAGE, GOAL_IMAGE = "observation.images.front", "observation.images.goal_front"
DEPTH, GOAL_DEPTH = "observation.images.front_depth", "observation.images.goal_front_depth"


def episode(e: int) -> tuple[dict, np.ndarray, dict]:
    """RGB k/255 (packs as uint8) and integer depth (packs as uint16) whose pixel (0, 0) codes (e, t)."""
    image = np.zeros((T + 1, 3, 2, 2), np.float32)
    image[:, 0, 0, 0], image[:, 1, 0, 0] = e, np.arange(T + 1)
    depth = np.zeros((T + 1, 1, 2, 2), np.float32) + 300 + 10 * e + np.arange(T + 1)[:, None, None, None]
    obs = {
        IMAGE: image / np.float32(255),
        GOAL_IMAGE: np.full((1, 3, 2, 2), 7 + e, np.float32) / np.float32(255),
        DEPTH: depth,
        GOAL_DEPTH: np.full((1, 1, 2, 2), 1000 + e, np.float32),
    }
    actions = np.stack([np.full(T, e), np.arange(T)], axis=1).astype(np.float32) / 8
    achieved = np.stack([np.full(T + 1, e), np.arange(T + 1)], axis=1).astype(np.float32)
    gt = {"gt_achieved_goal": achieved, "gt_desired_goal": np.array([50.0 + e, -1.0], np.float32)}
    return obs, actions, gt


def packed_sample(n: int = 64, seed: int = 0) -> dict:
    buf = EpisodeReplayBuffer(3 * T, T)
    for e in range(3):
        buf.add_episode(*episode(e))
    return buf.sample(n, np.random.default_rng(seed), packed=True)


def test_every_field_lands_under_its_core_key_with_the_sampled_values():
    sample = packed_sample()
    batch = to_transition_batch(sample, [IMAGE, DEPTH], T, torch.device("cpu"))
    assert torch.equal(batch[core.ACTION], torch.from_numpy(sample["action"]))
    assert torch.equal(batch[core.HAS_FUTURE], torch.from_numpy(sample["has_future"]))
    assert torch.equal(batch[core.FUTURE_COUNT], torch.from_numpy(np.maximum(T - sample["t"] - 1, 0)))
    for key in (IMAGE, DEPTH):
        assert torch.equal(batch[key].float(), torch.from_numpy(sample["obs"][key]).float())
        assert torch.equal(batch[core.NEXT + key].float(), torch.from_numpy(sample["next_obs"][key]).float())
        assert torch.equal(
            batch[core.FUTURE + key].float(), torch.from_numpy(sample["future_obs"][key]).float()
        )
    for goal in (GOAL_IMAGE, GOAL_DEPTH):
        assert torch.equal(batch[goal].float(), torch.from_numpy(sample["obs"][goal]).float())
    # Ground truth: of o_{t+1}, of o_{t'} and the episode's desired goal, each by its own sampled index.
    ep, t, future_t = (torch.from_numpy(sample[k]).float() for k in ("episode", "t", "future_t"))
    assert torch.equal(batch[core.GT_NEXT_ACHIEVED], torch.stack([ep, t + 1], dim=1))
    assert torch.equal(batch[core.GT_FUTURE_ACHIEVED], torch.stack([ep, future_t], dim=1))
    assert torch.equal(batch[core.GT_DESIRED], torch.stack([50 + ep, -torch.ones_like(ep)], dim=1))


def test_packed_rgb_stays_uint8_and_packed_depth_becomes_its_float_value():
    sample = packed_sample()
    assert sample["obs"][IMAGE].dtype == np.uint8 and sample["obs"][DEPTH].dtype == np.uint16
    batch = to_transition_batch(sample, [IMAGE, DEPTH], T, torch.device("cpu"))
    for key in (IMAGE, core.NEXT + IMAGE, core.FUTURE + IMAGE, GOAL_IMAGE):
        assert batch[key].dtype == torch.uint8, key
    for key in (DEPTH, core.NEXT + DEPTH, core.FUTURE + DEPTH, GOAL_DEPTH):
        assert batch[key].dtype == torch.float32, key
    assert torch.equal(batch[GOAL_DEPTH][:, 0, 0, 0], 1000 + torch.from_numpy(sample["episode"]).float())


def test_a_key_packed_unlike_its_goal_is_compared_as_float_values():
    """RGB widened to float32 (a later episode did not pack) while its goal is still uint8: all four frames
    of the group become their float32 values, the goal's k as k/255."""
    buf = EpisodeReplayBuffer(2 * T, T)
    buf.add_episode(*episode(0))
    obs, actions, gt = episode(1)
    buf.add_episode({**obs, IMAGE: obs[IMAGE] + np.float32(0.001)}, actions, gt)
    sample = buf.sample(32, np.random.default_rng(0), packed=True)
    assert sample["obs"][IMAGE].dtype == np.float32 and sample["obs"][GOAL_IMAGE].dtype == np.uint8
    batch = to_transition_batch(sample, [IMAGE, DEPTH], T, torch.device("cpu"))
    for key in (IMAGE, core.NEXT + IMAGE, core.FUTURE + IMAGE, GOAL_IMAGE):
        assert batch[key].dtype == torch.float32, key
    expected_goal = (7 + torch.from_numpy(sample["episode"]).float()) / 255
    assert torch.equal(batch[GOAL_IMAGE][:, 0, 0, 0], expected_goal)


def test_tensors_go_to_the_requested_device():
    batch = to_transition_batch(packed_sample(8), [IMAGE, DEPTH], T, torch.device("meta"))
    assert {k: v.device.type for k, v in batch.items()} == {k: "meta" for k in batch}
