"""Recorder: tiny episodes of every task, reloaded offline and checked feature by feature."""

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from huggingface_hub import constants as hf_constants
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from lerobot_indicator.data import action_sources, recorder
from lerobot_indicator.data.checkpoint import JOURNAL_DIR
from lerobot_indicator.data.recorder import RecordConfig, make_single_env, record
from lerobot_indicator.data.storage import DepthRangeError, check_depth_range
from lerobot_indicator.envs import RopePushEnvConfig, SawyerReachEnvConfig
from lerobot_indicator.keys import ACTION_IS_PAD, goal_key

REPO = Path(__file__).resolve().parents[1]
T = 3  # steps per tiny episode
F = T + 1  # frames per episode: o_0..o_T (the last frame holds only the final observation)
TASK_CONFIGS = {"sawyer_reach": SawyerReachEnvConfig, "rope_push": RopePushEnvConfig}
# Task-specific features beyond the shared ones (goal-key rule: observation.x -> observation.goal_x).
EXTRA_FEATURES = {
    "sawyer_reach": {},
    "rope_push": {"observation.rope_xy": ("float32", (30,)), "observation.goal_rope_xy": ("float32", (30,))},
}
GT_DIM = {"sawyer_reach": 3, "rope_push": 30}
POLICY = {"sawyer_reach": "noisy_scripted", "rope_push": "scripted"}


@pytest.fixture(autouse=True)
def _egl(monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))


def env_cfg(task: str = "sawyer_reach", obs_type: str = "rgbd"):
    return TASK_CONFIGS[task](obs_type=obs_type, episode_length=T)


def record_tiny(root: Path, obs_type="rgbd", task="sawyer_reach", **kwargs) -> LeRobotDataset:
    cfg = RecordConfig(
        env=env_cfg(task, obs_type),
        repo_id=f"test/{task}_{obs_type}",
        root=root,
        num_episodes=kwargs.pop("num_episodes", 2),
        **kwargs,
    )
    return record(cfg)


def resume_cfg(root: Path, env=None, repo_id: str = "test/sawyer_reach_state", **kwargs) -> RecordConfig:
    """Settings that continue the dataset at ``root`` with one more episode (state reach by default)."""
    env = env or env_cfg(obs_type="state")
    return RecordConfig(env=env, repo_id=repo_id, root=root, num_episodes=1, resume=True, **kwargs)


def load_offline(root: Path, repo_id: str, monkeypatch, **kwargs) -> LeRobotDataset:
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setattr(hf_constants, "HF_HUB_OFFLINE", True)
    return LeRobotDataset(repo_id, root=root, video_backend="pyav", **kwargs)


def committed_episodes(root: Path) -> int:
    """The episode count ``root``'s info.json commits (0 while there is none or it is being replaced)."""
    try:
        return json.loads((root / "meta" / "info.json").read_text())["total_episodes"]
    except (FileNotFoundError, json.JSONDecodeError):
        return 0


def tree_digest(root: Path) -> dict[str, str]:
    return {
        p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


@pytest.mark.parametrize("task", sorted(TASK_CONFIGS))
@pytest.mark.parametrize("obs_type", ["state", "rgbd"])
def test_recorded_features_reload_offline(tmp_path, monkeypatch, task, obs_type):
    record_tiny(tmp_path / "ds", obs_type, task, policy=POLICY[task])
    ds = load_offline(tmp_path / "ds", f"test/{task}_{obs_type}", monkeypatch)
    assert (ds.num_episodes, len(ds)) == (2, 2 * F)
    cfg = env_cfg(task, obs_type)
    cam, gt_dim = cfg.camera, GT_DIM[task]
    expected = {
        "observation.state": ("float32", (cfg.state_dim,)),
        "observation.goal_state": ("float32", (cfg.state_dim,)),
        "observation.gt_achieved_goal": ("float32", (gt_dim,)),
        "observation.gt_desired_goal": ("float32", (gt_dim,)),
        "observation.gt_distance": ("float32", (1,)),
        "action": ("float32", (cfg.action_dim,)),
        "next.reward": ("float32", (1,)),
        "next.done": ("bool", (1,)),
        ACTION_IS_PAD: ("bool", (1,)),
        **EXTRA_FEATURES[task],
    }
    if obs_type == "rgbd":
        for name in ("front", "goal_front"):
            expected[f"observation.images.{name}"] = ("image", (cam.height, cam.width, 3))
            expected[f"observation.images.{name}_depth"] = ("image", (cam.height, cam.width, 1))
    user_features = {
        k: v
        for k, v in ds.meta.features.items()
        if k not in ("timestamp", "frame_index", "episode_index", "index", "task_index")
    }
    assert {k: (v["dtype"], tuple(v["shape"])) for k, v in user_features.items()} == expected
    for key in ("observation.images.front_depth", "observation.images.goal_front_depth"):
        if obs_type == "rgbd":
            assert ds.meta.features[key]["info"]["is_depth_map"] is True
            assert key in ds.meta.depth_keys

    items = [ds[i] for i in range(len(ds))]
    compared = recorder.default_reward_keys(ds.meta.features)
    assert sorted(compared) == sorted(
        ["observation.images.front", "observation.images.front_depth"]
        if obs_type == "rgbd"
        else [k for k in ("observation.state", "observation.rope_xy") if k in ds.meta.features]
    )
    for i, item in enumerate(items):
        t = item["frame_index"].item()
        assert item["next.done"].item() is (t >= T - 1)
        assert item[ACTION_IS_PAD].item() is (t == T)
        if t < T:  # R+ iff o_{t+1} equals the goal on every compared key, bit for bit
            hit = all(torch.equal(items[i + 1][k], item[goal_key(k)]) for k in compared)
            assert item["next.reward"].item() == (1.0 if hit else -1.0)
        else:  # the final-observation frame: no transition; its action is padding, a copy of a_{T-1}
            assert item["next.reward"].item() == 0.0 and torch.equal(item["action"], items[i - 1]["action"])
        assert torch.all(item["action"].abs() <= 1.0)
        dist = torch.linalg.norm(item["observation.gt_achieved_goal"] - item["observation.gt_desired_goal"])
        assert item["observation.gt_distance"].item() == pytest.approx(dist.item(), abs=1e-5)
        assert item["task"] == ds.meta.tasks.index[0] and item["task"]
        if obs_type == "rgbd":
            rgb, depth = item["observation.images.front"], item["observation.images.front_depth"]
            assert rgb.dtype == torch.float32 and rgb.shape == (3, cam.height, cam.width)
            assert rgb.min() >= 0.0 and rgb.max() <= 1.0 and rgb.std() > 0
            assert depth.dtype == torch.float32 and depth.shape == (1, cam.height, cam.width)
            assert depth.min() >= 0.0 and depth.max() <= cam.depth_max_m * 1000.0  # millimetres
        if task == "rope_push":
            assert torch.equal(item["observation.rope_xy"], item["observation.gt_achieved_goal"])
            assert torch.equal(item["observation.goal_rope_xy"], item["observation.gt_desired_goal"])
            continue
        assert torch.equal(item["observation.goal_state"], item["observation.gt_desired_goal"])
        assert torch.equal(item["observation.state"], item["observation.gt_achieved_goal"])
        if t < T - 1:  # the scripted expert moves the gripper toward the goal
            nxt = items[i + 1]
            assert nxt["observation.gt_distance"] < item["observation.gt_distance"]
            if obs_type == "rgbd":
                assert not torch.equal(nxt["observation.images.front"], item["observation.images.front"])


def test_goal_and_depth_match_the_env_bit_for_bit(tmp_path, monkeypatch):
    """Lossless storage: goal images equal the rendered goal; depth round-trips with 0 mm error."""
    record_tiny(tmp_path / "ds", "rgbd", policy="random", seed=7)
    ds = load_offline(tmp_path / "ds", "test/sawyer_reach_rgbd", monkeypatch)
    vec = make_single_env(env_cfg())
    try:
        for episode in range(2):
            obs, _ = vec.reset(seed=7 + episode)  # the recorder seeds episode e with seed + e
            first = ds[episode * F]
            assert first["episode_index"].item() == episode
            for name, env_img in obs["pixels"].items():
                # What lerobot-eval's preprocess_observation makes of the env image, bit for bit.
                eval_batch = torch.from_numpy(env_img[0]).permute(2, 0, 1).to(torch.float32) / 255
                assert torch.equal(first[f"observation.images.{name}"], eval_batch)
            for name in ("front_depth", "goal_front_depth"):
                stored_mm = first[f"observation.images.{name}"][0].numpy()
                np.testing.assert_array_equal(stored_mm, obs[name][0, ..., 0].astype(np.float32))
    finally:
        vec.close()
    goal = ds[0]["observation.images.goal_front"]
    assert all(torch.equal(ds[t]["observation.images.goal_front"], goal) for t in range(F))


def test_video_storage_is_bit_exact_rgb_and_depth(tmp_path, monkeypatch):
    """--use_videos=true: lossless HEVC (planar RGB; depth as 1 mm linear codes), so the decoded frames are
    the env's own, as the indicator's bit-for-bit comparison needs (docs/dataset_format.md)."""
    record_tiny(tmp_path / "ds", "rgbd", policy="random", use_videos=True, num_episodes=1)
    ds = load_offline(tmp_path / "ds", "test/sawyer_reach_rgbd", monkeypatch)
    assert ds.meta.features["observation.images.front_depth"]["dtype"] == "video"
    assert ds.meta.features["observation.images.front"]["dtype"] == "video"
    vec = make_single_env(env_cfg())
    try:
        obs, _ = vec.reset(seed=0)
    finally:
        vec.close()
    true_mm = obs["front_depth"][0, ..., 0].astype(np.float32)
    assert (true_mm > 0).mean() > 0.5
    np.testing.assert_array_equal(ds[0]["observation.images.front_depth"][0].numpy(), true_mm)
    np.testing.assert_array_equal(
        ds[0]["observation.images.goal_front_depth"][0].numpy(), obs["goal_front_depth"][0, ..., 0]
    )
    rgb = (ds[0]["observation.images.front"].permute(1, 2, 0) * 255).round().to(torch.uint8).numpy()
    np.testing.assert_array_equal(rgb, obs["pixels"]["front"][0])


def test_video_storage_refuses_depth_it_would_clip():
    with pytest.raises(
        DepthRangeError, match=r"observation.images.front_depth: .* up to 4095 mm .* got 5000 mm"
    ):
        check_depth_range("observation.images.front_depth", np.array([[0, 5000]], dtype=np.uint16))
    check_depth_range("observation.images.front_depth", np.array([[0, 4095]], dtype=np.uint16))


def test_indicator_reward_marks_an_exact_goal_hit(tmp_path, monkeypatch):
    """R+ exactly when o_{t+1} equals the goal bit for bit; a 20 um drift is already R-.

    The env starts at its goal; its first step is made to report the start observation again (a
    perfect "stay"), later steps are real (a zero action lets the arm drift by micrometres).
    """
    real_make = recorder.make_single_env

    def env_starting_at_goal(cfg):
        vec = real_make(cfg)
        env = vec.envs[0]  # the recorder steps the single env itself (EpisodeStepper)
        real_reset, real_step, first = env.reset, env.step, {}

        def reset(seed=None, options=None):
            point = np.random.default_rng(seed).uniform(cfg.end_effector.low, cfg.end_effector.high).tolist()
            first["out"], first["t"] = (
                real_reset(seed=seed, options={"goal_pos": point, "start_pos": point}),
                0,
            )
            return first["out"]

        def step(action):
            obs, *rest = real_step(action)
            first["t"] += 1
            return (first["out"][0] if first["t"] == 1 else obs, *rest)

        env.reset, env.step = reset, step
        return vec

    class ZeroAction:
        def reset(self, seed=None):
            pass

        def __call__(self, observation, info):
            return np.zeros((1, 3), np.float32)

    monkeypatch.setattr(recorder, "make_single_env", env_starting_at_goal)
    monkeypatch.setattr(recorder, "make_action_source", lambda *a, **k: ZeroAction())
    record_tiny(tmp_path / "ds", "rgbd", num_episodes=1)
    ds = load_offline(tmp_path / "ds", "test/sawyer_reach_rgbd", monkeypatch)
    goal = ds[0]["observation.images.goal_front"]
    assert torch.equal(ds[0]["observation.images.front"], goal)  # started at the goal, bit for bit
    rewards = [ds[t]["next.reward"].item() for t in range(T)]
    for t in range(T):  # frame t's reward is about o_{t+1}, the next frame's observation
        assert rewards[t] == (1.0 if torch.equal(ds[t + 1]["observation.images.front"], goal) else -1.0)
    assert rewards[0] == 1.0 and rewards[-1] == -1.0


def test_interrupt_keeps_saved_episodes(tmp_path, monkeypatch):
    """An exception (or Ctrl-C) mid-episode keeps every saved episode readable; the partial one is dropped."""
    real = action_sources.make_action_source
    calls = {"n": 0}

    def interrupting(*args, **kwargs):
        source = real(*args, **kwargs)

        def act(observation, info):
            calls["n"] += 1
            if calls["n"] == T + 2:  # second step of the second episode
                raise KeyboardInterrupt
            return source(observation, info)

        act.reset = source.reset
        return act

    monkeypatch.setattr(recorder, "make_action_source", interrupting)
    with pytest.raises(KeyboardInterrupt):
        record_tiny(tmp_path / "ds", "rgbd", num_episodes=3, policy="random")
    assert not (tmp_path / "ds" / JOURNAL_DIR).exists()
    ds = load_offline(tmp_path / "ds", "test/sawyer_reach_rgbd", monkeypatch)
    assert (ds.num_episodes, len(ds)) == (1, F)
    assert ds[T - 1]["next.done"].item() and ds[T]["next.done"].item()
    assert not list((tmp_path / "ds" / "images").rglob("*.png"))  # no leftovers of the dropped episode


def test_killed_recording_is_readable_as_it_is_and_resumes(tmp_path, monkeypatch):
    """SIGKILL at a random moment: every committed episode loads without any recovery step; --resume
    keeps them all and appends."""
    root = tmp_path / "ds"
    cmd = [
        sys.executable,
        str(REPO / "scripts" / "record.py"),
        "--env.type=sawyer_reach",
        "--env.obs_type=state",
        f"--env.episode_length={T}",
        "--policy=random",
        "--num_episodes=10000",
        "--repo_id=test/killed",
        f"--root={root}",
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            if committed_episodes(root) >= 2:
                break
            assert proc.poll() is None, "recorder exited early"
            time.sleep(0.05)
        else:
            pytest.fail("recorder never committed 2 episodes")
        time.sleep(0.3)  # let it get on with more episodes
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()

    ds = load_offline(root, "test/killed", monkeypatch)
    kept = ds.num_episodes
    assert kept >= 2 and len(ds) == kept * F
    before = [ds[i]["action"] for i in range(len(ds))]
    assert sorted({int(e) for e in ds.hf_dataset["episode_index"][: len(ds)]}) == list(range(kept))

    monkeypatch.setenv("HF_HUB_OFFLINE", "0")
    record(resume_cfg(root, repo_id="test/killed", policy="random"))
    ds = load_offline(root, "test/killed", monkeypatch)
    assert ds.num_episodes >= kept + 1 and len(ds) == ds.num_episodes * F  # + a commit the kill cut short
    assert all(torch.equal(ds[i]["action"], a) for i, a in enumerate(before))
    assert sorted({int(e) for e in ds.hf_dataset["episode_index"]}) == list(range(ds.num_episodes))
    assert not (root / JOURNAL_DIR).exists()


@pytest.mark.parametrize("policy", ["random", "noisy_scripted"])
def test_resumed_recording_equals_an_uninterrupted_one(tmp_path, monkeypatch, policy):
    """Episode e's env seed and action noise depend on e only: 4 episodes in one run == 2 + 2 resumed."""
    record_tiny(tmp_path / "one", "state", policy=policy, num_episodes=4, seed=3)
    record_tiny(tmp_path / "two", "state", policy=policy, num_episodes=2, seed=3)
    record_tiny(tmp_path / "two", "state", policy=policy, num_episodes=2, seed=3, resume=True)
    one = load_offline(tmp_path / "one", "test/sawyer_reach_state", monkeypatch)
    two = load_offline(tmp_path / "two", "test/sawyer_reach_state", monkeypatch)
    assert one.num_episodes == two.num_episodes == 4
    for episode in range(4):
        frames = range(episode * F, (episode + 1) * F)
        a = torch.stack([one[i]["action"] for i in frames])
        b = torch.stack([two[i]["action"] for i in frames])
        assert torch.equal(a, b), f"episode {episode}: actions differ"
        assert torch.equal(one[episode * F]["observation.state"], two[episode * F]["observation.state"])
    # and the noise differs between episodes (a resumed run does not replay episodes 0, 1)
    assert not torch.equal(one[0]["action"], one[2 * F]["action"])


def test_resume_with_other_env_settings_is_an_error(tmp_path):
    """A resumed recording may not mix horizons (or any other stored setting): the error names the
    field, the dataset's value and the given one, and nothing is written."""
    root = tmp_path / "ds"
    record_tiny(root, "state", num_episodes=1)
    digest = tree_digest(root)
    with pytest.raises(ValueError) as err:
        record(resume_cfg(root, SawyerReachEnvConfig(obs_type="state", episode_length=T + 2)))
    message = str(err.value)
    assert f"env.episode_length: dataset {T}, given {T + 2}" in message and "\n" not in message
    assert tree_digest(root) == digest
    with pytest.raises(ValueError, match="r_neg: dataset -1.0, given -2.0"):
        record(resume_cfg(root, r_neg=-2.0))
    assert tree_digest(root) == digest


@pytest.mark.parametrize("use_videos", [False, True])
def test_corrupt_frame_fails_with_one_line(tmp_path, monkeypatch, capsys, use_videos):
    """An image frame that does not read back stops the recording with one line naming the episode,
    the frame and the file; the episodes before it stay saved, the broken one is not."""
    from lerobot.datasets import dataset_writer

    real_write = dataset_writer.write_image

    def write_image(image, fpath, compress_level=1):
        real_write(image, fpath, compress_level)
        path = Path(fpath)
        if path.parent.name == "episode-000001" and path.name.startswith("frame-000002"):
            path.write_bytes(path.read_bytes()[:40])  # truncated, as by a full disk

    monkeypatch.setattr(dataset_writer, "write_image", write_image)
    root = tmp_path / "ds"
    with pytest.raises(SystemExit) as exit_info:
        _cli(
            monkeypatch,
            "--env.type=sawyer_reach",
            "--env.obs_type=rgb",
            f"--env.episode_length={T}",
            "--env.camera.width=32",
            "--env.camera.height=32",
            "--policy=random",
            "--num_episodes=3",
            "--image_writer_threads=0",
            f"--use_videos={str(use_videos).lower()}",
            "--repo_id=test/corrupt",
            f"--root={root}",
        )
    assert exit_info.value.code == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if "frame 2" in line]
    assert len(lines) == 1
    assert "episode 1, frame 2" in lines[0] and "episode-000001/frame-000002.png" in lines[0]
    assert not (root / JOURNAL_DIR).exists()  # the broken episode's files went with the stage
    ds = load_offline(root, "test/corrupt", monkeypatch)
    assert (ds.num_episodes, len(ds)) == (1, F)


def test_abandoned_session_keeps_its_saved_episodes_and_resumes(tmp_path, monkeypatch):
    """The API the online trainer's --record.* uses (open_recording, save_episode per episode): a session
    left without close() (as by SIGKILL) reads as its saved episodes; resuming appends after them."""
    cfg = RecordConfig(
        env=env_cfg(obs_type="state"),
        repo_id="test/session",
        root=tmp_path / "ds",
        num_episodes=1,
        image_writer_threads=0,
    )
    vec = make_single_env(cfg.env)
    try:
        _, info = vec.reset(seed=0)
        features = recorder.dataset_features(
            vec.single_observation_space, vec.single_action_space, recorder.unbatch(info), False
        )
        cfg.reward_keys = recorder.default_reward_keys(features)
        source = action_sources.RandomActions(vec.action_space, 0)
        stepper = recorder.EpisodeStepper(vec)
        abandoned = recorder.open_recording(cfg, features, horizon=None)
        for episode in range(2):
            recorder._record_episode(cfg, stepper, source, abandoned.dataset, "reach", episode)
            abandoned.save_episode()
        recorder._record_episode(cfg, stepper, source, abandoned.dataset, "reach", 2)  # never saved
        assert load_offline(cfg.root, "test/session", monkeypatch).num_episodes == 2
        cfg.resume = True
        session = recorder.open_recording(cfg, features, horizon=None)
        recorder._record_episode(cfg, stepper, source, session.dataset, "reach", 2)
        session.save_episode()
        session.close()
    finally:
        vec.close()
    assert not (cfg.root / JOURNAL_DIR).exists()
    ds = load_offline(cfg.root, "test/session", monkeypatch)
    assert (ds.num_episodes, len(ds)) == (3, 3 * F)
    assert [int(e) for e in ds.hf_dataset["episode_index"]] == [e for e in range(3) for _ in range(F)]


def test_resume_appends_with_fresh_seeds(tmp_path, monkeypatch):
    record_tiny(tmp_path / "ds", "state", policy="scripted")
    record_tiny(tmp_path / "ds", "state", policy="scripted", resume=True, num_episodes=1)
    ds = load_offline(tmp_path / "ds", "test/sawyer_reach_state", monkeypatch)
    assert ds.num_episodes == 3
    goals = {tuple(ds[e * F]["observation.goal_state"].tolist()) for e in range(3)}
    assert len(goals) == 3  # episode e is seeded with seed + e, resumed ones included


def _cli(monkeypatch, *args: str):
    """Run scripts/record.py's entry point in-process (same parser, no interpreter start-up)."""
    monkeypatch.setattr(sys, "argv", ["record.py", *args])
    return recorder.main()


def test_cli_rejects_unknown_env_type(tmp_path, monkeypatch, capsys):
    with pytest.raises(SystemExit) as exit_info:
        _cli(monkeypatch, "--env.type=no_such_task", "--repo_id=test/x", f"--root={tmp_path / 'ds'}")
    assert exit_info.value.code != 0
    assert "no_such_task" in capsys.readouterr().err
    assert not (tmp_path / "ds").exists()


@pytest.mark.parametrize("num_episodes", [0, -3])
def test_rejects_non_positive_num_episodes(tmp_path, monkeypatch, capsys, num_episodes):
    with pytest.raises(ValueError, match="num_episodes must be > 0"):
        RecordConfig(env=env_cfg(), repo_id="test/x", num_episodes=num_episodes)
    with pytest.raises(SystemExit) as err:
        _cli(
            monkeypatch,
            "--env.type=sawyer_reach",
            "--repo_id=test/x",
            f"--root={tmp_path / 'ds'}",
            f"--num_episodes={num_episodes}",
        )
    assert err.value.code == 1
    assert capsys.readouterr().err == f"error: num_episodes must be > 0, got {num_episodes}\n"
    assert not (tmp_path / "ds").exists()


def test_existing_dataset_without_resume_is_not_touched(tmp_path, monkeypatch):
    root = tmp_path / "ds"
    record_tiny(root, "state", num_episodes=1)
    digest = tree_digest(root)
    with pytest.raises(FileExistsError, match="--resume=true"):
        record_tiny(root, "state", num_episodes=1)
    assert tree_digest(root) == digest
    with pytest.raises(FileExistsError, match="already exists"):
        _cli(monkeypatch, "--env.type=sawyer_reach", "--repo_id=test/sawyer_reach_state", f"--root={root}")
    assert tree_digest(root) == digest


def test_resume_without_dataset_is_an_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="no dataset"):
        record_tiny(tmp_path / "missing", "state", resume=True, num_episodes=1)


def test_resume_with_other_features_is_an_error(tmp_path):
    root = tmp_path / "ds"
    record_tiny(root, "state", num_episodes=1)
    digest = tree_digest(root)
    with pytest.raises(ValueError, match="other features"):
        record(resume_cfg(root, env_cfg(obs_type="rgbd")))
    assert tree_digest(root) == digest


def test_records_with_a_pretrained_policy_checkpoint(tmp_path, monkeypatch):
    """``--policy=<dir>``: a saved indicator_ddpg policy drives the env, fed as lerobot-eval feeds it."""
    from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata
    from lerobot.policies.factory import make_policy, make_pre_post_processors

    from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig

    record_tiny(tmp_path / "seed_ds", "state", num_episodes=1)
    meta = LeRobotDatasetMetadata("test/sawyer_reach_state", root=tmp_path / "seed_ds")
    policy_cfg = IndicatorDDPGConfig(
        observation_keys=["observation.state"], horizon=T, hidden_dims=[16], device="cpu"
    )
    policy = make_policy(policy_cfg, ds_meta=meta)
    pre, post = make_pre_post_processors(policy_cfg, dataset_stats=meta.stats)
    ckpt = tmp_path / "pretrained_model"
    policy.save_pretrained(ckpt)
    pre.save_pretrained(ckpt)
    post.save_pretrained(ckpt)

    record_tiny(tmp_path / "ds", "state", policy=str(ckpt), num_episodes=1)
    ds = load_offline(tmp_path / "ds", "test/sawyer_reach_state", monkeypatch)
    policy.eval()
    for t in range(T):
        item = ds[t]
        batch = pre(
            {k: item[k][None] for k in ("observation.state", "observation.goal_state")}
            | {"task": [item["task"]]}
        )
        with torch.no_grad():
            expected = post(policy.select_action(batch))[0]
        assert torch.allclose(item["action"], expected, atol=1e-6)


def test_rope_scripted_expert_reaches_the_goal_bit_for_bit(tmp_path, monkeypatch):
    """rope_push's ``scripted_action()`` replays the hidden goal pushes: the recorded images hit the goal
    image exactly, so the indicator reward turns R+ (and stays R+ under the final no-op push)."""
    record_tiny(tmp_path / "ds", "rgbd", "rope_push", policy="scripted", num_episodes=1)
    ds = load_offline(tmp_path / "ds", "test/rope_push_rgbd", monkeypatch)
    assert [ds[t]["next.reward"].item() for t in range(T)] == [-1.0, 1.0, 1.0]
    last = ds[T]  # o_T
    assert torch.equal(last["observation.images.front"], last["observation.images.goal_front"])
    assert torch.equal(last["observation.images.front_depth"], last["observation.images.goal_front_depth"])
    assert last["observation.gt_distance"].item() == 0.0
