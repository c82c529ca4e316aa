"""Replay buffer and batch assembly, value by value: lossless packing (bit patterns, not float equality),
the FIFO ring of episode slots, what one sampled row gathers (o_t, o_{t+1}, o_{t'}, the n-step path and its
mask, ground truth) and the learning core's batch built from it. Episodes are hand-built so that every
stored value names its episode and step; the expected values are written out or computed with plain numpy.
"""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest
import torch

from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.training.batches import to_transition_batch
from lerobot_indicator.training.replay_buffer import (
    EpisodeReplayBuffer,
    _PackedArray,
    pack,
    pack_exactly,
    unpack,
)

STATE, GOAL = "observation.state", "observation.goal_state"
IMAGE, GOAL_IMAGE = "observation.images.front", "observation.images.goal_front"
GT_ACH, GT_DES = "gt_achieved_goal", "gt_desired_goal"


def bits(x: np.ndarray) -> np.ndarray:
    """The float32 bit patterns of ``x`` (what "bit for bit" compares: -0.0 != +0.0, NaN payloads)."""
    assert x.dtype == np.float32
    return np.ascontiguousarray(x).view(np.uint32)


def f32(*values: float) -> np.ndarray:
    return np.array(values, np.float32)


# ------------------------------------------------------------------------------------ unpack and packing


def test_unpack_divides_by_a_scale_other_than_one_and_always_gives_float32():
    """uint8 k with scale 255 is the float32 k / 255 (numpy's float32 division, bit for bit); scale 1 keeps
    the stored integer's value; a float32 array comes back as it is."""
    k = np.arange(256, dtype=np.uint8)
    out = unpack(k, 255.0)
    assert out.dtype == np.float32
    assert np.array_equal(bits(out), bits(np.arange(256, dtype=np.float32) / np.float32(255)))
    depth = np.array([0, 7, 65535], np.uint16)
    out = unpack(depth, 1.0)
    assert out.dtype == np.float32 and np.array_equal(out, f32(0, 7, 65535))
    x = f32(-0.0, 0.5, np.nan)
    assert np.array_equal(bits(unpack(x, 1.0)), bits(x))
    assert np.array_equal(unpack(np.array([2], np.uint16), 2.0), f32(1.0))  # any scale other than 1 divides


def test_pack_exactly_accepts_every_k_over_255_and_the_integer_range_ends():
    """Every k/255 (k = 0..255, float32) packs as uint8 k; 0 and 65535 are uint16's ends and pack too."""
    k = np.arange(256)
    packed = pack_exactly(k.astype(np.float32) / np.float32(255), np.dtype(np.uint8), 255.0)
    assert packed is not None and packed.dtype == np.uint8 and np.array_equal(packed, k)
    packed = pack_exactly(f32(0, 1, 65534, 65535), np.dtype(np.uint16), 1.0)
    assert packed is not None and packed.dtype == np.uint16
    assert np.array_equal(packed, [0, 1, 65534, 65535])
    # Not float32 yet (float64, a list): converted first, so the same values pack the same way.
    assert np.array_equal(pack_exactly(np.array([0.0, 1.0]), np.dtype(np.uint8), 255.0), [0, 255])
    assert np.array_equal(pack_exactly([3.0, 4.0], np.dtype(np.uint16), 1.0), [3, 4])
    # An empty array packs (to an empty array of the dtype).
    empty = pack_exactly(np.zeros((0, 2), np.float32), np.dtype(np.uint8), 255.0)
    assert empty is not None and empty.dtype == np.uint8 and empty.shape == (0, 2)


@pytest.mark.parametrize(
    ("value", "dtype", "scale"),
    [
        (f32(256) / np.float32(255), np.uint8, 255.0),  # one step past uint8's top
        (f32(-1) / np.float32(255), np.uint8, 255.0),  # one step below 0
        (f32(65536), np.uint16, 1.0),
        (f32(-1), np.uint16, 1.0),
        (f32(0.5), np.uint16, 1.0),  # not an integer
        (f32(0.1), np.uint8, 255.0),  # not a k / 255
        (f32(0.0, -0.0), np.uint16, 1.0),  # -0.0 would come back as +0.0
        (f32(1e30), np.uint16, 1.0),
        (f32(np.inf), np.uint8, 255.0),
    ],
)
def test_pack_exactly_refuses_what_unpack_would_not_give_back_bit_for_bit(value, dtype, scale):
    """Out of range, off the grid, a negative zero or a NaN: None (out-of-range values are refused before
    the integer cast, so refusing an infinity or a huge value raises no "invalid value in cast" warning)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert pack_exactly(value, np.dtype(dtype), scale) is None


def test_pack_exactly_refuses_nan_before_the_integer_cast():
    """A NaN is refused with the out-of-range values, before the cast (which would warn "invalid value")."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert pack_exactly(f32(1.0, np.nan), np.dtype(np.uint8), 255.0) is None
        assert pack_exactly(f32(np.nan), np.dtype(np.uint16), 1.0) is None


def test_pack_picks_the_smallest_exact_packing_else_float32():
    """k/255 -> (uint8 k, 255); integers 0..65535 not all k/255 -> (uint16, 1); anything else -> float32
    with scale 1, the same bits, also when the input was float64."""
    stored, scale = pack(f32(0, 1, 128) / np.float32(255))
    assert stored.dtype == np.uint8 and scale == 255.0 and np.array_equal(stored, [0, 1, 128])
    stored, scale = pack(f32(0, 2, 300, 65535))
    assert stored.dtype == np.uint16 and scale == 1.0 and np.array_equal(stored, [0, 2, 300, 65535])
    for value in (f32(0.25, -0.0, 70000), f32(1.0, np.nan)):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            stored, scale = pack(value)
        assert stored.dtype == np.float32 and scale == 1.0 and np.array_equal(bits(stored), bits(value))
    stored, scale = pack(np.array([0.1, 2.0]))  # float64 in: float32 out
    assert stored.dtype == np.float32 and scale == 1.0 and np.array_equal(stored, f32(0.1, 2.0))
    for value in (f32(0, 1) / np.float32(255), f32(5, 6), f32(0.3, -0.0)):
        assert np.array_equal(bits(unpack(*pack(value))), bits(value))


def test_packed_array_starts_in_the_first_values_packing_and_widens_without_losing_rows():
    """The dtype comes from ``first``: uint8 for k/255, uint16 for integers, float32 otherwise; a later row
    that does not fit widens the whole array to float32 with every earlier row's value kept."""
    rgb = _PackedArray((3, 2), f32(0, 1) / np.float32(255))
    assert (rgb.dtype, rgb.scale, rgb.data.dtype, rgb.data.shape) == (np.uint8, 255.0, np.uint8, (3, 2))
    assert np.array_equal(rgb.data, np.zeros((3, 2)))
    rgb[0] = f32(3, 4) / np.float32(255)
    assert np.array_equal(rgb.data[0], [3, 4]) and rgb.dtype == np.uint8
    assert np.array_equal(bits(rgb[0]), bits(f32(3, 4) / np.float32(255)))
    rgb[1] = f32(0.5, -0.0)  # not k/255: widen
    assert (rgb.dtype, rgb.scale, rgb.data.dtype) == (np.float32, 1.0, np.float32)
    assert np.array_equal(bits(rgb[0]), bits(f32(3, 4) / np.float32(255)))
    assert np.array_equal(bits(rgb[1]), bits(f32(0.5, -0.0)))
    assert np.array_equal(bits(rgb[2]), bits(f32(0, 0)))
    rgb[2] = f32(7, 8) / np.float32(255)  # once float32, any value is stored as it is
    expected = np.stack([f32(3, 4) / np.float32(255), f32(0.5, -0.0), f32(7, 8) / np.float32(255)])
    assert np.array_equal(bits(rgb[:]), bits(expected))

    depth = _PackedArray((2, 1), f32(300))
    assert (depth.dtype, depth.scale, depth.data.dtype) == (np.uint16, 1.0, np.uint16)
    depth[1] = f32(65535)
    assert np.array_equal(depth[:], f32(0, 65535)[:, None])
    other = _PackedArray((2, 1), f32(0.5))
    assert (other.dtype, other.scale, other.data.dtype) == (np.float32, 1.0, np.float32)


def test_unpack_and_pack_keep_nan_payloads_bit_for_bit():
    """A signalling NaN with a payload survives pack + unpack unchanged (a float division, even by 1, would
    quiet it: 0x7f800001 -> 0x7fc00001), and so does a quiet NaN with the sign bit set."""
    value = np.array([0x7F800001, 0xFFC00005, 0x3F800000], np.uint32).view(np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        stored, scale = pack(value)
    assert stored.dtype == np.float32 and scale == 1.0
    assert np.array_equal(unpack(stored, scale).view(np.uint32), [0x7F800001, 0xFFC00005, 0x3F800000])


# ------------------------------------------------------------------------------------ coded episodes

H = 3  # horizon of the coded episodes


def coded_episode(
    e: int, horizon: int = H
) -> tuple[dict[str, np.ndarray], np.ndarray, dict[str, np.ndarray]]:
    """Episode ``e``: state o_t = (e, t) (integers: packs as uint16), image o_t with pixel (c, 0, 0) =
    ((e, t)[c] + 1) / 255 and 0 elsewhere (packs as uint8), goals (100 + e, 1) and (50 + e) / 255, action
    a_t = (e, t + 0.5), ground truth achieved (e, -t) and desired (100 + e, -1)."""
    steps = np.arange(horizon + 1, dtype=np.float32)
    state = np.stack([np.full(horizon + 1, e, np.float32), steps], axis=1)
    image = np.zeros((horizon + 1, 2, 2, 2), np.float32)
    image[:, 0, 0, 0], image[:, 1, 0, 0] = e + 1, steps + 1
    obs = {
        STATE: state,
        GOAL: f32(100 + e, 1)[None],
        IMAGE: image / np.float32(255),
        GOAL_IMAGE: np.full((1, 2, 2, 2), 50 + e, np.float32) / np.float32(255),
    }
    actions = np.stack([np.full(horizon, e, np.float32), steps[:-1] + 0.5], axis=1)
    gt = {GT_ACH: np.stack([state[:, 0], -steps], axis=1), GT_DES: f32(100 + e, -1)}
    return obs, actions, gt


def coded_buffer(episodes: range, capacity: int, ground_truth: bool = True) -> EpisodeReplayBuffer:
    buf = EpisodeReplayBuffer(capacity * H, H)
    for e in episodes:
        obs, actions, gt = coded_episode(e)
        buf.add_episode(obs, actions, gt if ground_truth else None)
    return buf


def image_code(frames: np.ndarray) -> np.ndarray:
    """(e, t) from coded image frames (float k/255 or packed uint8 k)."""
    k = frames[..., :, 0, 0] if frames.dtype == np.uint8 else np.rint(frames[..., :, 0, 0] * 255)
    return k.astype(np.int64) - 1


# ------------------------------------------------------------------------------------------- sampling


@pytest.mark.parametrize("packed", [False, True])
def test_every_sampled_field_is_the_frame_its_indices_name(packed: bool):
    """Row i of a sample is episode ep_i, step t_i, future step t'_i: o_t, o_{t+1}, o_{t'} of that episode,
    a_t, the episode's goals and ground truth, with t' in {t+2..T} (both of t = 0's choices occur; o_T and
    has_future False for t = T-1). Unpacked: float32 values; packed: the stored uint8 / uint16 integers. No n-step fields
    unless asked for."""
    buf = coded_buffer(range(3), capacity=3)
    n = 600
    b = buf.sample(n, np.random.default_rng(5), packed=packed)
    assert set(b) == {
        "obs",
        "next_obs",
        "future_obs",
        "action",
        "has_future",
        "episode",
        "t",
        "future_t",
        "gt_next_achieved",
        "gt_future_achieved",
        "gt_desired",
    }
    ep, t, ft = b["episode"], b["t"], b["future_t"]
    assert set(ep.tolist()) == {0, 1, 2} and set(t.tolist()) == {0, 1, 2}
    assert np.array_equal(b["has_future"], t <= H - 2)
    has = b["has_future"]
    assert np.all((ft[has] >= t[has] + 2) & (ft[has] <= H)) and np.all(ft[~has] == H)
    assert set(ft[t == 0].tolist()) == {2, 3}
    state_dtype, image_dtype = (np.uint16, np.uint8) if packed else (np.float32, np.float32)
    for name, step in (("obs", t), ("next_obs", t + 1), ("future_obs", ft)):
        frames = b[name]
        assert set(frames) == ({STATE, IMAGE, GOAL, GOAL_IMAGE} if name == "obs" else {STATE, IMAGE})
        assert frames[STATE].dtype == state_dtype and frames[IMAGE].dtype == image_dtype, name
        assert np.array_equal(frames[STATE], np.stack([ep, step], axis=1)), name
        assert frames[IMAGE].shape == (n, 2, 2, 2)
        assert np.array_equal(image_code(frames[IMAGE]), np.stack([ep, step], axis=1)), name
    assert b["obs"][GOAL].dtype == state_dtype and b["obs"][GOAL_IMAGE].dtype == image_dtype
    assert np.array_equal(b["obs"][GOAL], np.stack([100 + ep, np.ones(n)], axis=1))
    goal_k = b["obs"][GOAL_IMAGE] if packed else np.rint(b["obs"][GOAL_IMAGE] * 255)
    assert b["obs"][GOAL_IMAGE].shape == (n, 2, 2, 2) and np.array_equal(
        goal_k, np.broadcast_to(50 + ep[:, None, None, None], (n, 2, 2, 2))
    )
    assert b["action"].dtype == np.float32 and np.array_equal(b["action"], np.stack([ep, t + 0.5], axis=1))
    assert np.array_equal(b["gt_next_achieved"], np.stack([ep, -(t + 1)], axis=1))
    assert np.array_equal(b["gt_future_achieved"], np.stack([ep, -ft], axis=1))
    assert np.array_equal(b["gt_desired"], np.stack([100 + ep, -np.ones(n)], axis=1))


def test_sampling_an_empty_buffer_raises():
    with pytest.raises(RuntimeError, match="^cannot sample from an empty replay buffer$"):
        EpisodeReplayBuffer(2 * H, H).sample(1, np.random.default_rng(0))


@pytest.mark.parametrize("n_step", [2, 3, 5])
@pytest.mark.parametrize("packed", [False, True])
def test_n_step_path_is_o_t_plus_2_to_o_t_plus_n_clipped_at_the_last_frame_with_its_mask(
    n_step: int, packed: bool
):
    """path_obs[:, j] = o_{min(t+2+j, T)} of the row's episode (j = 0..n-2), path_valid[:, j] = t+2+j <= T,
    gt_path_achieved the achieved goal at the same clipped steps; the other fields as without n-step."""
    buf = coded_buffer(range(2), capacity=2)
    n = 300
    b = buf.sample(n, np.random.default_rng(n_step), packed=packed, n_step=n_step)
    ep, t = b["episode"], b["t"]
    steps = t[:, None] + 2 + np.arange(n_step - 1)[None]  # (n, n-1)
    clipped = np.minimum(steps, H)
    assert b["path_valid"].dtype == np.bool_ and b["path_valid"].shape == (n, n_step - 1)
    assert np.array_equal(b["path_valid"], steps <= H)
    assert b["path_valid"].any() and not b["path_valid"].all()
    ep2 = np.broadcast_to(ep[:, None], clipped.shape)
    assert set(b["path_obs"]) == {STATE, IMAGE}
    state = b["path_obs"][STATE]
    assert state.dtype == (np.uint16 if packed else np.float32) and state.shape == (n, n_step - 1, 2)
    assert np.array_equal(state, np.stack([ep2, clipped], axis=-1))
    image = b["path_obs"][IMAGE]
    assert image.dtype == (np.uint8 if packed else np.float32) and image.shape == (n, n_step - 1, 2, 2, 2)
    assert np.array_equal(image_code(image), np.stack([ep2, clipped], axis=-1))
    assert np.array_equal(b["gt_path_achieved"], np.stack([ep2, -clipped], axis=-1))
    assert np.array_equal(b["next_obs"][STATE], np.stack([ep, t + 1], axis=1))


def test_n_step_without_ground_truth_has_no_ground_truth_fields():
    buf = coded_buffer(range(2), capacity=2, ground_truth=False)
    b = buf.sample(16, np.random.default_rng(0), n_step=3)
    assert set(b) == {
        "obs",
        "next_obs",
        "future_obs",
        "action",
        "has_future",
        "episode",
        "t",
        "future_t",
        "path_obs",
        "path_valid",
    }
    assert np.array_equal(b["path_obs"][STATE][:, :, 1], np.minimum(b["t"][:, None] + [2, 3], H))


# ------------------------------------------------------------------------- construction and the FIFO ring


def test_a_new_buffer_holds_whole_episodes_of_the_capacity_and_is_empty():
    """Capacity in episodes is capacity_transitions // horizon (7 // 3 = 2); one episode is the least; a
    horizon of 1 is allowed."""
    buf = EpisodeReplayBuffer(7, 3)
    assert (buf.horizon, buf.capacity, len(buf), buf.num_episodes, buf.next_slot) == (3, 2, 0, 0, 0)
    assert buf.total_episodes_added == 0 and buf.keys == [] and buf.moments == {}
    assert buf.actions is None and buf.gt_achieved is None and buf.gt_desired is None
    assert EpisodeReplayBuffer(3, 3).capacity == 1
    assert EpisodeReplayBuffer(1, 1).capacity == 1 and EpisodeReplayBuffer(5, 1).capacity == 5


def test_a_buffer_without_room_for_one_episode_or_without_steps_is_refused():
    with pytest.raises(ValueError, match=r"^horizon must be >= 1, got 0$"):
        EpisodeReplayBuffer(4, 0)
    with pytest.raises(ValueError, match=r"^capacity \(2 transitions\) must hold at least one episode of 3$"):
        EpisodeReplayBuffer(2, 3)


def test_the_first_episode_allocates_every_array_at_its_shape_and_dtype():
    """Per non-goal key (capacity, T + 1, ...) in its packing, per goal key (capacity, ...), actions
    (capacity, T, action_dim) float32, ground truth (capacity, T + 1, g) and (capacity, g) float32, moments
    (capacity, 3, dim or channels) float64; unused slots are zero."""
    buf = coded_buffer(range(1), capacity=4)
    assert buf.keys == sorted([STATE, GOAL, IMAGE, GOAL_IMAGE])
    assert set(buf.obs) == {STATE, IMAGE} and set(buf.goals) == {GOAL, GOAL_IMAGE}
    shapes = {k: (a.data.shape, a.data.dtype) for k, a in {**buf.obs, **buf.goals}.items()}
    assert shapes == {
        STATE: ((4, H + 1, 2), np.uint16),
        IMAGE: ((4, H + 1, 2, 2, 2), np.uint8),
        GOAL: ((4, 2), np.uint16),
        GOAL_IMAGE: ((4, 2, 2, 2), np.uint8),
    }
    assert buf.actions.shape == (4, H, 2) and buf.actions.dtype == np.float32
    assert buf.gt_achieved.shape == (4, H + 1, 2) and buf.gt_achieved.dtype == np.float32
    assert buf.gt_desired.shape == (4, 2) and buf.gt_desired.dtype == np.float32
    assert {k: (m.shape, m.dtype) for k, m in buf.moments.items()} == {
        STATE: ((4, 3, 2), np.float64),
        IMAGE: ((4, 3, 2), np.float64),
    }
    for array in (buf.obs[STATE].data, buf.goals[GOAL].data, buf.actions, buf.gt_achieved, buf.gt_desired):
        assert not array[1:].any()
    assert not buf.moments[STATE][1:].any()


def test_shapes_follow_the_episode_not_fixed_sizes():
    """A 5-dim state, 3-dim actions, 4-dim ground truth and a 1-step horizon: every array takes its size
    from the episode given."""
    buf = EpisodeReplayBuffer(2, 1)
    obs = {STATE: np.arange(10, dtype=np.float32).reshape(2, 5), GOAL: np.full((1, 5), 0.5, np.float32)}
    gt = {GT_ACH: np.ones((2, 4), np.float32), GT_DES: np.zeros(4, np.float32)}
    buf.add_episode(obs, np.ones((1, 3), np.float32), gt)
    assert buf.obs[STATE].data.shape == (2, 2, 5) and buf.goals[GOAL].data.shape == (2, 5)
    assert buf.goals[GOAL].dtype == np.float32  # 0.5 is neither k/255 nor an integer
    assert buf.actions.shape == (2, 1, 3) and buf.moments[STATE].shape == (2, 3, 5)
    assert buf.gt_achieved.shape == (2, 2, 4) and buf.gt_desired.shape == (2, 4)


def test_a_goals_packing_is_chosen_from_its_first_step_only():
    """A goal key may come with several (identical or not) steps; only step 0 is stored, counted in the
    moments and decides the packing: a later step that is not k/255 is ignored."""
    buf = EpisodeReplayBuffer(2 * H, H)
    obs, actions, _ = coded_episode(0)
    obs[GOAL_IMAGE] = np.concatenate([obs[GOAL_IMAGE], np.full((1, 2, 2, 2), 0.3, np.float32)])
    buf.add_episode(obs, actions)
    assert buf.goals[GOAL_IMAGE].dtype == np.uint8
    assert np.array_equal(buf.goals[GOAL_IMAGE].data[0], np.full((2, 2, 2), 50))
    # The image's moments count its 4 frames and the goal once: 5 x 4 pixels per channel, channel 0 summing
    # 4 frame pixels of 1/255 and 4 goal pixels of 50/255 (the ignored goal step would add 4 x 0.3).
    assert np.array_equal(buf.moments[IMAGE][0, 0], [20, 20])
    k = np.float64(np.float32(1) / np.float32(255)), np.float64(np.float32(50) / np.float32(255))
    np.testing.assert_allclose(buf.moments[IMAGE][0, 1, 0], 4 * k[0] + 4 * k[1], rtol=1e-12)


def test_ring_overwrites_the_oldest_slot_and_counts_what_it_holds():
    """Capacity 3: episodes 0, 1, 2 fill slots 0, 1, 2; episode 3 replaces 0 in slot 0, episode 4 replaces 1
    in slot 1. next_slot, num_episodes (at most the capacity), len (transitions) and total_episodes_added
    follow after every episode."""
    buf = EpisodeReplayBuffer(3 * H + 2, H)
    seen = []
    for e in range(5):
        obs, actions, gt = coded_episode(e)
        buf.add_episode(obs, actions, gt)
        seen.append((buf.next_slot, buf.num_episodes, len(buf), buf.total_episodes_added))
    assert seen == [(1, 1, 3, 1), (2, 2, 6, 2), (0, 3, 9, 3), (1, 3, 9, 4), (2, 3, 9, 5)]
    slots = [3, 4, 2]
    assert np.array_equal(buf.obs[STATE][:, 0, 0], f32(*slots))
    assert np.array_equal(image_code(buf.obs[IMAGE][:, 0])[:, 0], slots)
    assert np.array_equal(buf.goals[GOAL][:, 0], f32(*[100 + e for e in slots]))
    assert np.array_equal(buf.actions[:, 0, 0], f32(*slots))
    assert np.array_equal(buf.gt_achieved[:, 0, 0], f32(*slots))
    assert np.array_equal(buf.gt_desired[:, 0], f32(*[100 + e for e in slots]))
    for slot, e in enumerate(slots):
        obs, actions, gt = coded_episode(e)
        assert np.array_equal(buf.obs[STATE][slot], obs[STATE])
        assert np.array_equal(bits(buf.obs[IMAGE][slot]), bits(obs[IMAGE]))
        assert np.array_equal(bits(buf.goals[GOAL_IMAGE][slot]), bits(obs[GOAL_IMAGE][0]))
        assert np.array_equal(buf.actions[slot], actions)
        assert np.array_equal(buf.gt_achieved[slot], gt[GT_ACH])
    assert set(buf.sample(200, np.random.default_rng(0))["obs"][STATE][:, 0].tolist()) == {2.0, 3.0, 4.0}


def test_start_at_continues_the_ring_as_if_that_many_episodes_had_been_added():
    """start_at(n): the next episode goes to slot n % capacity, the buffer counts min(n, capacity) episodes
    and total_episodes_added continues from n."""
    buf = EpisodeReplayBuffer(3 * H, H)
    buf.start_at(7)
    assert (buf.next_slot, buf.num_episodes, buf.total_episodes_added, len(buf)) == (1, 3, 7, 9)
    obs, actions, gt = coded_episode(9)
    buf.add_episode(obs, actions, gt)
    assert (buf.next_slot, buf.num_episodes, buf.total_episodes_added) == (2, 3, 8)
    assert np.array_equal(buf.obs[STATE][1], obs[STATE]) and not buf.obs[STATE].data[[0, 2]].any()
    small = EpisodeReplayBuffer(3 * H, H)
    small.start_at(2)
    assert (small.next_slot, small.num_episodes, small.total_episodes_added) == (2, 2, 2)
    small.start_at(0)
    assert (small.next_slot, small.num_episodes, small.total_episodes_added) == (0, 0, 0)


# ------------------------------------------------------------------------------ what add_episode refuses


def test_add_episode_refuses_wrong_lengths_keys_and_mixed_ground_truth_with_messages():
    buf = EpisodeReplayBuffer(2 * H, H)
    obs, actions, gt = coded_episode(0)
    with pytest.raises(
        ValueError, match=r"^episode actions have shape \(1, 2\), expected \(T, action_dim\) with T = 3$"
    ):
        buf.add_episode(obs, actions[:1], gt)  # (1, 2): the count is the leading axis
    with pytest.raises(ValueError, match=r"^episode actions have shape \(3,\), expected"):
        buf.add_episode(obs, actions[:, 0], gt)  # 1-D: would broadcast into every row of a (T, T) slot
    flat = {**gt, GT_ACH: gt[GT_ACH][:, 0]}
    with pytest.raises(
        ValueError, match=r"^gt_achieved_goal has shape \(4,\), expected \(T \+ 1, goal_dim\)$"
    ):
        buf.add_episode(obs, actions, flat)
    short = {**obs, STATE: obs[STATE][:H]}
    with pytest.raises(
        ValueError, match=r"^observation 'observation.state' has 3 steps, expected T \+ 1 = 4$"
    ):
        buf.add_episode(short, actions, gt)
    assert buf.actions is None  # nothing was allocated by a refused episode
    buf.add_episode(obs, actions, gt)
    partial = {k: v for k, v in obs.items() if k != GOAL}
    expected = re.escape(f"episode keys {sorted(partial)} differ from the buffer's {sorted(obs)}")
    with pytest.raises(ValueError, match=f"^{expected}$"):
        buf.add_episode(partial, actions, gt)
    message = r"^either every episode in a buffer carries ground truth or none does$"
    with pytest.raises(ValueError, match=message):
        buf.add_episode(obs, actions)
    no_gt = EpisodeReplayBuffer(2 * H, H)
    no_gt.add_episode(obs, actions)
    with pytest.raises(ValueError, match=message):
        no_gt.add_episode(obs, actions, gt)
    assert (buf.num_episodes, no_gt.num_episodes) == (1, 1)  # the refused episodes were not stored


# ------------------------------------------------------------------------------ moments and statistics


def test_moments_are_count_sum_and_sum_of_squares_of_the_frames_and_goal_per_dimension_or_channel():
    """Slot moments of a state: over its T + 1 frames and its goal, per dimension; of an image: per channel
    over the frames' and goal's pixels; of a key without a goal: over its frames only. Float64 sums of the
    float32 values, written out by hand for the coded episode."""
    buf = EpisodeReplayBuffer(2 * H, H)
    obs, actions, gt = coded_episode(2)
    obs["observation.environment_state"] = f32(1, 2, 3, 4)[:, None] * f32(1, -1)[None]  # (T + 1, 2), no goal
    buf.add_episode(obs, actions, gt)
    state = buf.moments[STATE][0]
    # dim 0: 2, 2, 2, 2 and the goal's 102; dim 1: 0, 1, 2, 3 and the goal's 1
    assert np.array_equal(
        state, [[5, 5], [4 * 2 + 102, 0 + 1 + 2 + 3 + 1], [4 * 4 + 102**2, 0 + 1 + 4 + 9 + 1]]
    )
    image = buf.moments[IMAGE][0]
    # per channel: 4 frames of 4 pixels and the goal's 4 pixels = 20 values; frame pixel (0, 0) of channel 0
    # is 3/255, of channel 1 (t + 1)/255; every goal pixel (50 + 2)/255.
    v = lambda i: np.float64(np.float32(i) / np.float32(255))  # noqa: E731  the float32 value i/255
    expected_sum = [4 * v(3) + 4 * v(52), v(1) + v(2) + v(3) + v(4) + 4 * v(52)]
    expected_sq = [
        4 * v(3) ** 2 + 4 * v(52) ** 2,
        v(1) ** 2 + v(2) ** 2 + v(3) ** 2 + v(4) ** 2 + 4 * v(52) ** 2,
    ]
    np.testing.assert_allclose(image, [[20, 20], expected_sum, expected_sq], rtol=1e-12)
    env = buf.moments["observation.environment_state"][0]
    assert np.array_equal(env, [[4, 4], [10, -10], [30, 30]])


def test_observation_stats_are_over_the_stored_slots_only_shaped_per_dimension_or_channel():
    """Mean and std from the slots' moments: the ring keeps the newest 2 of 3 episodes, so stats are over
    episodes 1 and 2 only; a state gives (dim,), an image (C, 1, 1), all float32."""
    buf = coded_buffer(range(3), capacity=2)
    stats = buf.observation_stats()
    assert set(stats) == {STATE, IMAGE}
    frames = np.concatenate(
        [np.concatenate([coded_episode(e)[0][STATE], coded_episode(e)[0][GOAL]]) for e in (1, 2)]
    )
    assert stats[STATE]["mean"].shape == (2,) and stats[STATE]["mean"].dtype == np.float32
    np.testing.assert_allclose(stats[STATE]["mean"], frames.astype(np.float64).mean(0), rtol=1e-6)
    np.testing.assert_allclose(stats[STATE]["std"], frames.astype(np.float64).std(0), rtol=1e-6)
    assert stats[IMAGE]["mean"].shape == (2, 1, 1) and stats[IMAGE]["std"].dtype == np.float32
    # Every value equal: std exactly 0, never NaN, also where rounding makes E[x^2] - E[x]^2 negative (it
    # does for 11 one-step episodes, 3 values each, of this float32 value, summed per slot as the buffer does).
    v = np.float32(255.49251)
    per_slot = np.array([3 * np.float64(v), 3 * np.square(np.float64(v))])
    total, total_sq = np.sum([per_slot] * 11, axis=0)
    assert total_sq / 33 - np.square(total / 33) < 0
    constant = EpisodeReplayBuffer(11, 1)
    for _ in range(11):
        obs = {STATE: np.full((2, 1), v, np.float32), GOAL: np.full((1, 1), v, np.float32)}
        constant.add_episode(obs, np.zeros((1, 1), np.float32))
    const_stats = constant.observation_stats()[STATE]
    assert const_stats["std"].tolist() == [0.0] and const_stats["mean"].tolist() == [v]


# ---------------------------------------------------------------------------------------- batch assembly


@pytest.mark.parametrize("n_step", [1, 3])
def test_transition_batch_has_exactly_the_core_keys_with_the_sampled_frames(n_step: int):
    """Keys: action, future.valid, future.count, per compared key o_t / next. / future. (and path. with
    path.valid when n-step), the recorded goals, ground truth; frames packed as uint8 stay uint8 (their k),
    uint16 become float32 values; every gathered frame is the coded (episode, step) of its row."""
    buf = coded_buffer(range(3), capacity=3)
    n = 64
    sample = buf.sample(n, np.random.default_rng(11), packed=True, n_step=n_step)
    batch = to_transition_batch(sample, [STATE, IMAGE], H, "cpu")
    expected_keys = {
        core.ACTION,
        core.HAS_FUTURE,
        core.FUTURE_COUNT,
        STATE,
        IMAGE,
        GOAL,
        GOAL_IMAGE,
        core.NEXT + STATE,
        core.NEXT + IMAGE,
        core.FUTURE + STATE,
        core.FUTURE + IMAGE,
        core.GT_NEXT_ACHIEVED,
        core.GT_FUTURE_ACHIEVED,
        core.GT_DESIRED,
    }
    if n_step > 1:
        expected_keys |= {core.PATH + STATE, core.PATH + IMAGE, core.PATH_VALID, core.GT_PATH_ACHIEVED}
    assert set(batch) == expected_keys
    ep, t, ft = (torch.from_numpy(sample[k]) for k in ("episode", "t", "future_t"))
    assert batch[core.FUTURE_COUNT].dtype == torch.int64
    assert torch.equal(batch[core.FUTURE_COUNT], torch.tensor([2, 1, 0])[t])  # |{t+2..3}|
    assert batch[core.HAS_FUTURE].dtype == torch.bool
    assert torch.equal(batch[core.HAS_FUTURE], t < H - 1)
    assert batch[core.ACTION].dtype == torch.float32
    assert torch.equal(batch[core.ACTION], torch.stack([ep, t], 1).float() + torch.tensor([0.0, 0.5]))
    for key, step in ((STATE, t), (core.NEXT + STATE, t + 1), (core.FUTURE + STATE, ft)):
        assert batch[key].dtype == torch.float32, key
        assert torch.equal(batch[key], torch.stack([ep, step], 1).float()), key
    for key, step in ((IMAGE, t), (core.NEXT + IMAGE, t + 1), (core.FUTURE + IMAGE, ft)):
        assert batch[key].dtype == torch.uint8 and batch[key].shape == (n, 2, 2, 2), key
        assert torch.equal(batch[key][:, :, 0, 0].long() - 1, torch.stack([ep, step], 1)), key
    assert batch[GOAL].dtype == torch.float32
    assert torch.equal(batch[GOAL], torch.stack([100 + ep, torch.ones_like(ep)], 1).float())
    assert batch[GOAL_IMAGE].dtype == torch.uint8
    assert torch.equal(batch[GOAL_IMAGE].long(), (50 + ep)[:, None, None, None].expand(n, 2, 2, 2))
    assert torch.equal(batch[core.GT_NEXT_ACHIEVED], torch.stack([ep, -(t + 1)], 1).float())
    assert torch.equal(batch[core.GT_FUTURE_ACHIEVED], torch.stack([ep, -ft], 1).float())
    assert torch.equal(batch[core.GT_DESIRED], torch.stack([100 + ep, -torch.ones_like(ep)], 1).float())
    if n_step > 1:
        steps = t[:, None] + torch.tensor([2, 3])
        clipped, ep2 = steps.clamp_max(H), ep[:, None].expand(n, 2)
        assert batch[core.PATH_VALID].dtype == torch.bool
        assert torch.equal(batch[core.PATH_VALID], steps <= H)
        assert batch[core.PATH + STATE].dtype == torch.float32
        assert torch.equal(batch[core.PATH + STATE], torch.stack([ep2, clipped], -1).float())
        path_image = batch[core.PATH + IMAGE]
        assert path_image.dtype == torch.uint8 and path_image.shape == (n, 2, 2, 2, 2)
        assert torch.equal(path_image[..., 0, 0].long() - 1, torch.stack([ep2, clipped], -1))
        assert torch.equal(batch[core.GT_PATH_ACHIEVED], torch.stack([ep2, -clipped], -1).float())


def test_a_widened_goal_turns_its_observations_path_frames_into_float_values_too():
    """The goal image widened to float32 (a later goal was not k/255) while the image itself is still uint8:
    o_t, next, future and the path frames of that key all become float32 k/255, so all of them compare
    with the goal as values; the state group, packed alike, keeps its own dtypes."""
    buf = EpisodeReplayBuffer(2 * H, H)
    for e in range(2):
        obs, actions, gt = coded_episode(e)
        if e == 1:
            obs[GOAL_IMAGE] = obs[GOAL_IMAGE] + np.float32(0.001)
        buf.add_episode(obs, actions, gt)
    assert buf.obs[IMAGE].dtype == np.uint8 and buf.goals[GOAL_IMAGE].dtype == np.float32
    sample = buf.sample(32, np.random.default_rng(2), packed=True, n_step=3)
    batch = to_transition_batch(sample, [STATE, IMAGE], H, "cpu")
    ep, t = (torch.from_numpy(sample[k]) for k in ("episode", "t"))
    for key in (IMAGE, core.NEXT + IMAGE, core.FUTURE + IMAGE, core.PATH + IMAGE, GOAL_IMAGE):
        assert batch[key].dtype == torch.float32, key
    clipped = (t[:, None] + torch.tensor([2, 3])).clamp_max(H)
    expected = (torch.stack([ep[:, None].expand(32, 2), clipped], -1) + 1).float() / 255
    assert torch.equal(batch[core.PATH + IMAGE][..., 0, 0], expected)
    assert torch.equal(batch[IMAGE][:, :, 0, 0], (torch.stack([ep, t], 1) + 1).float() / 255)
    assert batch[STATE].dtype == batch[core.PATH + STATE].dtype == batch[GOAL].dtype == torch.float32


def test_transition_batch_of_unpacked_samples_keeps_float32_and_goes_to_the_device():
    """Unpacked samples are float32 already and stay so; every tensor lands on the requested device."""
    sample = coded_buffer(range(2), capacity=2).sample(8, np.random.default_rng(0), n_step=2)
    batch = to_transition_batch(sample, [STATE, IMAGE], H, torch.device("meta"))
    assert {v.device.type for v in batch.values()} == {"meta"}
    assert batch[core.PATH + IMAGE].dtype == batch[IMAGE].dtype == torch.float32
    assert batch[core.PATH_VALID].dtype == torch.bool and batch[core.PATH_VALID].shape == (8, 1)
