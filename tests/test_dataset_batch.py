"""``lerobot-train`` batch assembly (``dataset_batch_to_transitions``): shape errors, batches without padding
flags, ground truth, the recorded goal's frame, the generator and the device."""

import pytest
import torch

from lerobot_indicator.keys import OBS_GT_ACHIEVED_GOAL, OBS_GT_DESIRED_GOAL
from lerobot_indicator.policy import indicator_core as core
from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig

STATE, GOAL = "observation.state", "observation.goal_state"
OFFSETS = [2, 3]
N_FRAMES = 2 + len(OFFSETS)


def config() -> IndicatorDDPGConfig:
    # n_step=1: what the policy resolves to for lerobot-train samples, which hold no frames in between.
    return IndicatorDDPGConfig(
        device="cpu", horizon=4, observation_keys=[STATE], future_offsets=OFFSETS, n_step=1
    )


def frames(n: int, device: str = "cpu") -> dict[str, torch.Tensor]:
    """Row i, frame j holds the state (i, j) and the goal (100 + i, j): every output names its source."""
    rows = torch.arange(n, dtype=torch.float32)[:, None].expand(n, N_FRAMES)
    cols = torch.arange(N_FRAMES, dtype=torch.float32)[None].expand(n, N_FRAMES)
    return {
        STATE: torch.stack([rows, cols], dim=2).to(device),
        GOAL: torch.stack([100 + rows, cols], dim=2).to(device),
        "action": torch.zeros(n, 1, device=device),
    }


def test_a_batch_without_frame_axis_fails_naming_the_key_and_shape():
    batch = frames(3)
    for bad in (batch[STATE][:, 0, 0], batch[STATE][:, :3]):
        with pytest.raises(
            ValueError, match=rf"'{STATE}' has shape \({bad.shape[0]},.*expected \(B, {N_FRAMES}"
        ) as err:
            core.dataset_batch_to_transitions({**batch, STATE: bad}, config())
        # Both frame counts a lerobot-train sample may hold: with or without the episode's last frame.
        assert str(err.value).endswith(f", or (B, {N_FRAMES + 1}, ...) with the episode's last frame")


def test_one_number_per_frame_is_accepted():
    batch = frames(3)
    out = core.dataset_batch_to_transitions({**batch, STATE: batch[STATE][..., 1]}, config())
    assert torch.equal(out[STATE], torch.zeros(3)) and torch.equal(out[core.NEXT + STATE], torch.ones(3))


def test_no_padding_flags_means_every_frame_is_real():
    n = 400
    out = core.dataset_batch_to_transitions(frames(n), config(), torch.Generator().manual_seed(0))
    assert out[core.FUTURE_COUNT].tolist() == [len(OFFSETS)] * n
    assert out[core.HAS_FUTURE].dtype == torch.bool and bool(out[core.HAS_FUTURE].all())
    assert out[core.NEXT_VALID].dtype == torch.bool and bool(out[core.NEXT_VALID].all())
    assert torch.equal(out[STATE][:, 1], torch.zeros(n)) and torch.equal(
        out[core.NEXT + STATE][:, 1], torch.ones(n)
    )
    picked = out[core.FUTURE + STATE]
    assert torch.equal(picked[:, 0], torch.arange(n, dtype=torch.float32)), "future frame from another row"
    assert set(picked[:, 1].tolist()) == {2.0, 3.0}


def test_recorded_goal_is_the_goal_of_o_t():
    out = core.dataset_batch_to_transitions(frames(5), config())
    assert torch.equal(out[GOAL][:, 1], torch.zeros(5))  # frame 0's goal, not o_{t+1}'s


def test_ground_truth_of_next_future_and_goal_frames():
    n = 64
    batch = frames(n)
    batch[OBS_GT_ACHIEVED_GOAL] = batch[STATE] * 2
    batch[OBS_GT_DESIRED_GOAL] = batch[GOAL] * 2
    out = core.dataset_batch_to_transitions(batch, config(), torch.Generator().manual_seed(1))
    assert torch.equal(out[core.GT_NEXT_ACHIEVED], batch[STATE][:, 1] * 2)
    assert torch.equal(out[core.GT_FUTURE_ACHIEVED], out[core.FUTURE + STATE] * 2)
    assert torch.equal(out[core.GT_DESIRED], batch[GOAL][:, 0] * 2)
    for only in (OBS_GT_ACHIEVED_GOAL, OBS_GT_DESIRED_GOAL):  # both or none: half the ground truth is unused
        out = core.dataset_batch_to_transitions({**frames(n), only: batch[only]}, config())
        assert not {core.GT_NEXT_ACHIEVED, core.GT_FUTURE_ACHIEVED, core.GT_DESIRED} & set(out), only


def test_the_generator_alone_decides_the_future_frame():
    picks = []
    for global_seed in (1, 2):
        torch.manual_seed(global_seed)
        out = core.dataset_batch_to_transitions(frames(256), config(), torch.Generator().manual_seed(7))
        picks.append(out[core.FUTURE + STATE][:, 1])
    assert torch.equal(picks[0], picks[1])
    assert set(picks[0].tolist()) == {2.0, 3.0}


def test_outputs_stay_on_the_batch_device():
    out = core.dataset_batch_to_transitions(frames(4, device="meta"), config())
    assert {k: v.device.type for k, v in out.items()} == {k: "meta" for k in out}
