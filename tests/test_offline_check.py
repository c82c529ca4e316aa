"""The offline check (lerobot_indicator/training/offline_check.py): hand-made critics and actors give the numbers
they must, and both trainers' paths (lerobot-indicator-train's metrics, the lerobot-indicator-offline-check
CLI) run it on held-out episodes of a dataset without goal columns."""

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from lerobot_indicator.training import offline_check
from lerobot_indicator.training.offline_check import check_episodes, spearman, value_ranking

STATE, CONTEXT = "observation.state", "observation.environment_state"
BIN = Path(sys.executable).parent


def episode(length: int, seed: int = 0) -> dict[str, torch.Tensor]:
    """Frames o_0..o_L whose state is the step index t, a context input, and random actions in [-1, 1]."""
    rng = np.random.default_rng(seed)
    t = torch.arange(length + 1, dtype=torch.float32)
    return {
        STATE: t[:, None].repeat(1, 2),
        CONTEXT: -t[:, None],
        "action": torch.as_tensor(rng.uniform(-1, 1, (length + 1, 2)), dtype=torch.float32),
    }


def steps_away(obs, goal, action):
    """A critic whose Q is exactly -k for the goal o_{t+k} (the state holds t)."""
    return -(goal[STATE][:, 0] - obs[STATE][:, 0])


EPISODES = [episode(20, 0), episode(50, 1), episode(7, 2)]


def check(critic, actor=None, **kwargs):
    actor = actor or (lambda obs, goal: torch.zeros(obs[STATE].shape[0], 2))
    return check_episodes(EPISODES, [STATE], critic, actor, context_keys=[CONTEXT], **kwargs)


def test_a_critic_that_is_minus_k_orders_goals_perfectly():
    result = check(steps_away)
    assert result["q_rank_corr"] == pytest.approx(1.0)
    assert result["q_rank_corr_per_episode"] == pytest.approx([1.0, 1.0, 1.0])
    assert result["q_rank_undefined_frac"] == 0
    # Mean Q per offset is -k itself.
    assert result["q_by_offset"] == pytest.approx([-k for k in result["offsets"]])
    # Starts with fewer than MIN_OFFSETS valid offsets are skipped: an episode of 7 steps has offsets 1,2,3,4,6
    # -> starts t with t + 3 <= 7.
    short = check_episodes([episode(7)], [STATE], steps_away, lambda o, g: torch.zeros(len(o[STATE]), 2))
    assert short["q_rank_starts"] == 5


def test_a_reversed_critic_gives_minus_one_and_a_constant_one_is_undefined():
    assert check(lambda o, g, a: -steps_away(o, g, a))["q_rank_corr"] == pytest.approx(-1.0)
    constant = check(lambda o, g, a: torch.full((o[STATE].shape[0],), 3.0))
    assert math.isnan(constant["q_rank_corr"]) and constant["q_rank_undefined_frac"] == 1.0
    assert all(math.isnan(c) for c in constant["q_rank_corr_per_episode"])
    json.dumps(constant)  # NaN is written as JSON's NaN, not an error
    # Constant on some starts only: those are left out of the mean, the rest count.
    q = torch.tensor([[-1.0, -2.0, -3.0], [5.0, 5.0, 5.0], [-3.0, -2.0, -1.0]])
    corr, undefined, used = value_ranking(q, [1, 2, 3])
    assert corr == pytest.approx(0.0) and undefined == 1 and used == 3
    # A critic that ignores the goal orders nothing on average: near zero on random values.
    rng = torch.Generator().manual_seed(0)
    noise = check(lambda o, g, a: torch.rand(o[STATE].shape[0], generator=rng))
    assert abs(noise["q_rank_corr"]) < 0.15


def test_spearman_with_ties_by_hand_and_nan_when_constant():
    """x = [10, 20, 10] ranks [1.5, 3, 1.5], y = [1, 3, 2] ranks [1, 3, 2]; centred (-0.5, 1, -0.5) and
    (-1, 1, 0): 1.5 / sqrt(1.5 * 2) = 0.866."""
    assert spearman(torch.tensor([10.0, 20.0, 10.0]), torch.tensor([1.0, 3.0, 2.0])) == pytest.approx(
        1.5 / math.sqrt(3.0)
    )
    assert math.isnan(spearman(torch.ones(4), torch.arange(4.0)))


def test_a_perfect_actor_has_zero_action_error_and_the_baselines_are_exact():
    for ep in EPISODES:

        def recorded_action(obs, goal, ep=ep):  # the state holds t: answer a_t, whatever the goal
            return ep["action"][obs[STATE][:, 0].long()]

        one = check_episodes([ep], [STATE], steps_away, recorded_action, near_offsets=[1, 2, 3])
        assert one["action_error"] == 0.0
        assert sorted(one["action_error_by_offset"]) == ["1", "2", "3"]
        assert all(v["action_error"] == 0.0 for v in one["action_error_by_offset"].values())
        assert one["action_error_random"] > 0.4 and one["action_error_mean_action"] > 0.2
    # Baselines on hand-made actions: a in {0, 1, -1, 0.5}: E|u - a| = (1 + a^2) / 2 for u ~ U[-1, 1].
    recorded = torch.tensor([[0.0, 1.0], [-1.0, 0.5]])
    errors = offline_check.action_errors(recorded, recorded, recorded.mean(0))
    assert errors["action_error"] == 0.0
    assert errors["action_error_random"] == pytest.approx(np.mean([0.5, 1.0, 1.0, 0.625]))
    assert errors["action_error_zero"] == pytest.approx(np.mean([0.0, 1.0, 1.0, 0.5]))
    assert errors["action_error_mean_action"] == pytest.approx(np.mean([0.5, 0.25, 0.5, 0.25]))
    # The random baseline's formula against sampling.
    u = torch.rand(200_000, 1, generator=torch.Generator().manual_seed(0)) * 2 - 1
    assert (u - 0.5).abs().mean().item() == pytest.approx(0.625, abs=3e-3)


def test_offsets_must_be_positive():
    with pytest.raises(ValueError, match="offsets must be >= 1"):
        check(steps_away, offsets=[0, 1, 2])


# ---------------- the trainers: lerobot-indicator-train's metrics and the CLI ----------------


def env() -> dict[str, str]:
    return {**os.environ, "HF_HUB_OFFLINE": "1", "CUDA_VISIBLE_DEVICES": "", "MUJOCO_GL": "egl"}


def state_dataset(root: Path, episodes: int, horizon: int) -> Path:
    """A goal-free recording with the sawyer_reach state task's key, made with LeRobot's own API."""
    from lerobot.datasets import LeRobotDataset

    features = {
        STATE: {"dtype": "float32", "shape": (3,), "names": ["x", "y", "z"]},
        "action": {"dtype": "float32", "shape": (3,), "names": ["dx", "dy", "dz"]},
    }
    ds = LeRobotDataset.create("local/reach_no_goal", fps=30, features=features, root=root, use_videos=False)
    rng = np.random.default_rng(0)
    for _ in range(episodes):
        for _ in range(horizon + 1):
            ds.add_frame({STATE: rng.uniform(-0.2, 0.2, 3).astype(np.float32), "task": "reach",
                          "action": rng.uniform(-1, 1, 3).astype(np.float32)})  # fmt: skip
        ds.save_episode()
    ds.finalize()
    return root


def test_online_trainer_logs_the_check_on_held_out_episodes_and_the_cli_writes_json_and_png(tmp_path):
    root = state_dataset(tmp_path / "d", episodes=4, horizon=5)
    out = tmp_path / "run"
    cmd = [
        str(BIN / "lerobot-indicator-train"), "--env.type=sawyer_reach", "--env.obs_type=state",
        "--env.episode_length=5", "--policy.type=indicator_ddpg", "--policy.push_to_hub=false",
        "--policy.device=cpu", "--policy.hidden_dims=[16,16,16]", "--dataset.repo_id=local/reach_no_goal",
        f"--dataset.root={root}", "--dataset.episodes=[0,1,2]", "--online.episodes_per_cycle=0",
        "--online.n_envs=1", "--online.use_async_envs=false", "--online.updates_per_cycle=2",
        "--online.batch_size=8", "--online.eval_episodes=1", "--steps=2", f"--output_dir={out}",
    ]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env())
    assert proc.returncode == 0, proc.stderr[-4000:]
    assert "offline check on 1 held-out episodes" in proc.stdout + proc.stderr
    row = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()][-1]
    assert row["offline_held_out"] == 1.0
    for key in ("offline_q_rank_corr", "offline_action_error", "offline_action_error_mean_action"):
        assert key in row
    assert np.isfinite(row["offline_action_error"])

    checkpoint = out / "checkpoints" / "last" / "pretrained_model"
    cli = [
        str(BIN / "lerobot-indicator-offline-check"), f"--policy.path={checkpoint}",
        "--dataset.repo_id=local/reach_no_goal", f"--dataset.root={root}", "--episodes=[3]",
        f"--output_dir={tmp_path / 'check'}",
    ]  # fmt: skip
    proc = subprocess.run(cli, capture_output=True, text=True, timeout=300, env=env())
    assert proc.returncode == 0, proc.stderr[-4000:]
    result = json.loads((tmp_path / "check" / offline_check.RESULT_FILE).read_text())
    assert result["episodes"] == 1 and result["dataset_episodes"] == [3]
    assert result["action_error"] == pytest.approx(row["offline_action_error"], rel=1e-6)
    assert (tmp_path / "check" / offline_check.FIGURE_FILE).stat().st_size > 0
