"""NaN / Inf never trains silently and is never saved: datasets, batches, losses and checkpoints."""

import numpy as np
import pytest
import torch

from benchmarks.speed.updates import STATE_FEATURES, make_batch, make_policy
from lerobot_indicator.finite import NonFiniteError, check_episode, check_module

STATE = "observation.state"


def test_a_dataset_episode_names_key_episode_and_frame():
    obs = {STATE: np.zeros((6, 3), np.float32), "action": np.zeros((6, 3), np.float32)}
    check_episode(obs, 4, "dataset u/d")  # finite: no error
    obs[STATE][3, 1] = np.inf
    with pytest.raises(NonFiniteError, match=r"dataset u/d: observation.state is inf at episode 4, frame 3"):
        check_episode(obs, 4, "dataset u/d")


def test_a_batch_names_the_key_and_for_dataset_batches_episode_and_index():
    policy = make_policy(STATE_FEATURES, hidden_dims=[8])
    batch = make_batch(STATE_FEATURES, 4)
    batch[STATE][2, 0] = float("nan")
    with pytest.raises(
        NonFiniteError, match=r"observation.state is nan in the training batch \(batch row 2\)"
    ):
        policy.forward(batch)
    batch["episode_index"], batch["index"] = torch.tensor([0, 0, 7, 7]), torch.tensor([1, 2, 93, 94])
    with pytest.raises(NonFiniteError, match=r"\(episode 7, dataset index 93\)"):
        policy.forward(batch)


def test_a_non_finite_loss_stops_before_backward_and_no_checkpoint_takes_it():
    policy = make_policy(STATE_FEATURES, hidden_dims=[8])
    batch = make_batch(STATE_FEATURES, 4)
    with torch.no_grad():
        policy.critic.net[0].weight[0, 0] = float("nan")
    with pytest.raises(NonFiniteError, match="the loss is nan"):
        policy.forward(batch)
    with pytest.raises(NonFiniteError, match=r"checkpoint: critic.net.0.weight holds NaN/Inf"):
        check_module(policy, "checkpoint")
