"""The critic-fit diagnostic replays a run's saved episode chunks with either input and fits the critic."""

import numpy as np

from benchmarks.probes.critic_fit import fit_critic


def fake_run(tmp_path, episodes: int = 8, horizon: int = 5, size: int = 24):
    rng = np.random.default_rng(0)
    pos = np.cumsum(rng.uniform(-0.05, 0.05, (episodes, horizon + 1, 3)), axis=1).astype(np.float32)
    chunk = {
        "obs/observation.images.front": rng.integers(0, 256, (episodes, horizon + 1, 3, size, size)).astype(
            np.float32
        )
        / 255,
        "obs/observation.images.front_depth": rng.integers(
            500, 900, (episodes, horizon + 1, 1, size, size)
        ).astype(np.float32),
        "obs/observation.images.goal_front": np.repeat(
            rng.integers(0, 256, (episodes, 1, 3, size, size)), horizon + 1, 1
        ).astype(np.float32)
        / 255,
        "obs/observation.images.goal_front_depth": np.full(
            (episodes, horizon + 1, 1, size, size), 700, np.float32
        ),
        "actions": (np.diff(pos, axis=1) / 0.05).astype(np.float32),
        "gt_achieved": pos,
        "gt_desired": pos[:, -1],
    }
    (tmp_path / "replay").mkdir()
    np.savez(tmp_path / "replay" / "cycle_0000000.npz", **chunk)
    return tmp_path


def test_state_critic_fits_and_the_image_path_reads_the_same_episodes(tmp_path):
    run = fake_run(tmp_path)
    state = fit_critic(run, "state", 300, 24, horizon=5, batch_size=32, every=100, hidden_dims=[32, 32, 32])
    losses = [c["critic_loss"] for c in state["curve"]]
    assert state["episodes"] == 8 and len(losses) == 3
    assert losses[-1] < 0.6 * losses[0], losses  # the reward is learnable from the true positions
    images = fit_critic(run, "rgbd", 20, 24, horizon=5, batch_size=16, every=10, hidden_dims=[8, 8, 8])
    assert images["episodes"] == 8 and len(images["curve"]) == 2


def test_localization_probe_reports_a_test_error_curve(tmp_path):
    from benchmarks.probes.critic_fit import localization_probe

    run = fake_run(tmp_path, episodes=30)
    probe = localization_probe(run, 20, 24, horizon=5, batch_size=16, every=10, hidden_dims=[8])
    assert probe["frames"] == 30 * 6 and [c["updates"] for c in probe["curve"]] == [10, 20]
    assert all(c["test_error_mean_m"] > 0 for c in probe["curve"])


def test_feature_probe_finds_a_linear_position_and_none_in_noise(tmp_path):
    """The probe regresses the run's own encoder features: exact where the position is a linear function of
    them, no better than the spread where it is unrelated noise."""
    import torch

    from benchmarks.probes.critic_fit import feature_probe
    from benchmarks.speed.updates import make_policy, rgbd_features

    episodes, horizon, size = 30, 5, 24
    run = fake_run(tmp_path, episodes=episodes, horizon=horizon, size=size)
    policy = make_policy(rgbd_features(size), horizon=horizon, hidden_dims=[8])
    policy.save_pretrained(run / "checkpoints" / "last" / "pretrained_model")
    path = run / "replay" / "cycle_0000000.npz"
    chunk = dict(np.load(path))
    frames = {k[4:]: torch.from_numpy(v.reshape(-1, *v.shape[2:])) for k, v in chunk.items() if "images" in k}
    with torch.no_grad():
        obs = policy.critic.encoder({k: v for k, v in frames.items() if "goal" not in k}).double().numpy()
    w = np.random.default_rng(1).normal(size=(obs.shape[1], 3)) * 0.05
    chunk["gt_achieved"] = (obs @ w).reshape(episodes, horizon + 1, 3).astype(np.float32)
    np.savez(path, **chunk)
    linear = feature_probe(run, horizon=horizon)
    assert linear["episodes"] == episodes and linear["feature_dim"] == obs.shape[1]
    assert linear["ee_error_mean_m"] < 0.02 * linear["ee_spread_m"], linear

    chunk["gt_achieved"] = np.random.default_rng(2).normal(size=chunk["gt_achieved"].shape).astype(np.float32)
    np.savez(path, **chunk)
    noise = feature_probe(run, horizon=horizon)
    assert noise["ee_error_mean_m"] > 0.8 * noise["ee_spread_m"], noise
