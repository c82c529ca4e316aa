"""Own data and own robot: datasets without goal columns (a LeRobot teleoperation recording: joint state, two
cameras, no reward, no goal) train with ``lerobot-train`` and ``lerobot-indicator-train``, and a policy made
from one reaches a saved goal image at deployment (``--policy.goal_path``) through LeRobot's rollout engine."""

import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from lerobot.configs import FeatureType, PolicyFeature

from lerobot_indicator.keys import goal_key
from lerobot_indicator.policy import goal_observations, indicator_core
from lerobot_indicator.policy.configuration_indicator_ddpg import (
    EPISODE_END_OFFSET,
    IndicatorDDPGConfig,
)

BIN = Path(sys.executable).parent
FRONT, WRIST, STATE = "observation.images.front", "observation.images.wrist", "observation.state"
CAMERAS = [FRONT, WRIST]
TELEOP_ID = "local/teleop"
# Teleoperated episodes end when the operator stops: their lengths differ, so --policy.horizon sets T.
LENGTHS = [7, 9, 8]
SIZE = 64  # the smallest frame LeRobot's default video codec encodes
HORIZON = 8


def env() -> dict[str, str]:
    return {**os.environ, "HF_HUB_OFFLINE": "1", "CUDA_VISIBLE_DEVICES": "", "MUJOCO_GL": "egl"}


def make_teleop_dataset(root: Path) -> Path:
    """A LeRobot robot recording made with LeRobot's own API: 6-d joint state and action, a front and a wrist
    camera as video, 30 fps, no reward and no goal column."""
    from lerobot.datasets import LeRobotDataset

    names = [f"joint_{i}" for i in range(6)]
    camera = {"dtype": "video", "shape": (SIZE, SIZE, 3), "names": ["height", "width", "channels"]}
    features = {
        STATE: {"dtype": "float32", "shape": (6,), "names": names},
        "action": {"dtype": "float32", "shape": (6,), "names": names},
        FRONT: camera,
        WRIST: camera,
    }
    ds = LeRobotDataset.create(TELEOP_ID, fps=30, features=features, root=root, robot_type="so100_follower")
    rng = np.random.default_rng(0)
    for length in LENGTHS:
        for _ in range(length):
            frame = {STATE: rng.standard_normal(6).astype(np.float32), "task": "teleop"}
            frame["action"] = rng.uniform(-1, 1, 6).astype(np.float32)
            for key in CAMERAS:
                frame[key] = rng.integers(0, 256, (SIZE, SIZE, 3), dtype=np.uint8)
            ds.add_frame(frame)
        ds.save_episode()
    ds.finalize()
    return root


@pytest.fixture(scope="module")
def teleop(tmp_path_factory) -> Path:
    return make_teleop_dataset(tmp_path_factory.mktemp("data") / "teleop")


@pytest.fixture(scope="module")
def trained(teleop: Path, tmp_path_factory) -> tuple[Path, str]:
    """Two lerobot-train steps on the teleoperation dataset, as its user would start them; (checkpoint, log)."""
    out = tmp_path_factory.mktemp("train") / "run"
    args = [
        "--policy.type=indicator_ddpg",
        f"--dataset.repo_id={TELEOP_ID}",
        f"--dataset.root={teleop}",
        "--dataset.video_backend=pyav",
        "--policy.push_to_hub=false",
        "--policy.device=cpu",
        f"--policy.horizon={HORIZON}",
        "--policy.future_offsets=[2,3]",
        "--policy.hidden_dims=[16,16,16]",
        "--batch_size=4",
        "--num_workers=0",
        "--log_freq=1",
        "--steps=2",
        "--save_freq=2",
        "--wandb.enable=false",
        f"--output_dir={out}",
    ]
    proc = subprocess.run(
        [str(BIN / "lerobot-train"), *args], capture_output=True, text=True, timeout=300, env=env()
    )
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log[-6000:]
    return out / "checkpoints" / "000002" / "pretrained_model", log


def test_lerobot_train_trains_on_a_dataset_without_goal_columns(trained):
    checkpoint, log = trained
    assert "critic_loss" in log and "frac_positive" in log, log[-3000:]
    assert log.count("the data has no goal columns") == 1
    cfg = json.loads((checkpoint / "config.json").read_text())
    # The cameras are compared, the joint state is not; the goals take their camera's shape.
    assert cfg["observation_keys"] == CAMERAS
    assert sorted(cfg["input_features"]) == sorted([*CAMERAS, *(goal_key(k) for k in CAMERAS)])
    for key in CAMERAS:
        assert cfg["input_features"][goal_key(key)] == cfg["input_features"][key]
    assert cfg["episode_end_goal"] is True and cfg["horizon"] == HORIZON


def test_lerobot_delta_indices_bring_each_episode_last_frame(teleop: Path):
    """A fresh lerobot-train chooses the frames before it reads the data: it fetches EPISODE_END_OFFSET, which
    LeRobot clamps to the episode's last frame and flags as padding."""
    from lerobot.datasets import LeRobotDataset
    from lerobot.datasets.factory import resolve_delta_timestamps

    cfg = IndicatorDDPGConfig(device="cpu", future_offsets=[2, 3])
    assert cfg.observation_delta_indices == [0, 1, 2, 3, EPISODE_END_OFFSET]
    plain = LeRobotDataset(TELEOP_ID, root=teleop, video_backend="pyav")
    stacked = LeRobotDataset(
        TELEOP_ID,
        root=teleop,
        video_backend="pyav",
        delta_timestamps=resolve_delta_timestamps(cfg, plain.meta),
    )
    starts = np.cumsum([0, *LENGTHS])
    for ep, t in [(0, 0), (1, 4), (2, 7)]:
        item = stacked[int(starts[ep]) + t]
        last = plain[int(starts[ep + 1]) - 1]
        assert torch.equal(item[STATE][-1], last[STATE])
        assert torch.equal(item[FRONT][-1], last[FRONT])
        assert bool(item[f"{STATE}_is_pad"][-1])
    # A config made for data with goal columns does not fetch it; one made for data without them does.
    with_goals = make_config({STATE: vec(), goal_key(STATE): vec()})
    with_goals.validate_features()
    assert with_goals.observation_delta_indices == [0, 1, 2, 3] and with_goals.episode_end_goal is False
    without = make_config({STATE: vec()})
    without.validate_features()
    assert without.observation_delta_indices == [0, 1, 2, 3, EPISODE_END_OFFSET]


def vec(n: int = 6) -> PolicyFeature:
    return PolicyFeature(type=FeatureType.STATE, shape=(n,))


def img(size: int = 16) -> PolicyFeature:
    return PolicyFeature(type=FeatureType.VISUAL, shape=(3, size, size))


def make_config(inputs: dict, **kwargs) -> IndicatorDDPGConfig:
    cfg = IndicatorDDPGConfig(device="cpu", horizon=HORIZON, future_offsets=[2, 3], **kwargs)
    cfg.input_features = dict(inputs)
    cfg.output_features = {"action": PolicyFeature(type=FeatureType.ACTION, shape=(6,))}
    return cfg


def test_cameras_are_compared_by_default_never_the_joint_state(caplog):
    cfg = make_config({STATE: vec(), FRONT: img(), WRIST: img(), "observation.gt_distance": vec(1)})
    with caplog.at_level(logging.INFO):
        cfg.validate_features()
    assert cfg.observation_keys == CAMERAS and STATE not in cfg.observation_keys
    assert STATE not in cfg.input_features and "observation.gt_distance" not in cfg.input_features
    assert cfg.input_features[goal_key(FRONT)] == img() and cfg.episode_end_goal is True
    lines = [r.getMessage() for r in caplog.records if "no goal columns" in r.getMessage()]
    assert len(lines) == 1 and "last frame" in lines[0] and STATE in lines[0]
    # The joint state conditions the networks without being compared when asked for as context.
    with_context = make_config({STATE: vec(), FRONT: img(), WRIST: img()}, context_keys=[STATE])
    with_context.validate_features()
    assert with_context.observation_keys == CAMERAS and STATE in with_context.input_features
    assert goal_key(STATE) not in with_context.input_features
    # Data without a camera compares its state; refusing the stand-in goal is a one-line error.
    state_only = make_config({STATE: vec()})
    state_only.validate_features()
    assert state_only.observation_keys == [STATE]
    # Beside observation.state, the other states (here a torque-driven arm's joint velocities) are context.
    env_state = "observation.environment_state"
    two_states = make_config({STATE: vec(), env_state: vec(4)})
    two_states.validate_features()
    assert two_states.observation_keys == [STATE] and two_states.context_keys == [env_state]
    assert goal_key(env_state) not in two_states.input_features
    # Without observation.state, every state key is compared.
    no_state = make_config({env_state: vec(4), "observation.velocity": vec(2)})
    no_state.validate_features()
    assert no_state.observation_keys == [env_state, "observation.velocity"] and no_state.context_keys == []
    with pytest.raises(ValueError, match="episode_end_goal=false") as err:
        make_config({FRONT: img()}, episode_end_goal=False).validate_features()
    assert "\n" not in str(err.value)


def hand_made_batch(batch_size: int, with_end: bool) -> dict[str, torch.Tensor]:
    """Frame j of sample i holds 100 i + j in every dimension: the value says which frame was picked."""
    n_frames = 2 + 2 + int(with_end)
    values = 100 * torch.arange(batch_size)[:, None] + torch.arange(n_frames)[None, :]
    frames = values[:, :, None].float().expand(batch_size, n_frames, 6).contiguous()
    pad = torch.zeros(batch_size, n_frames, dtype=torch.bool)
    if with_end:
        pad[:, -1] = True
    return {STATE: frames, f"{STATE}_is_pad": pad, "action": torch.zeros(batch_size, 6)}


def test_the_recorded_goal_stand_in_is_the_episode_last_frame():
    cfg = make_config({STATE: vec()})
    cfg.validate_features()
    batch = hand_made_batch(5, with_end=True)
    out = indicator_core.dataset_batch_to_transitions(batch, cfg, torch.Generator().manual_seed(0))
    expected = (100 * torch.arange(5) + 4).float()[:, None].expand(5, 6)
    assert torch.equal(out[goal_key(STATE)], expected)
    assert torch.equal(out[STATE], batch[STATE][:, 0]) and torch.equal(
        out[indicator_core.NEXT + STATE], batch[STATE][:, 1]
    )
    # The future goal is one of the two offsets, never the episode-end frame.
    assert set((out[indicator_core.FUTURE + STATE][:, 0] % 100).tolist()) <= {2.0, 3.0}
    # Balancing's "keep the recorded goal" branch gets the episode's last frame.
    recorded = torch.full((5,), indicator_core.SOURCE_RECORDED)
    goals = indicator_core.select_goals(out, [STATE], recorded)
    assert torch.equal(goals[STATE], expected)
    # A recorded goal column, where the data has one, wins over the stand-in.
    batch[goal_key(STATE)] = torch.full((5, 5, 6), -7.0)
    with_goal = indicator_core.dataset_batch_to_transitions(batch, cfg, torch.Generator().manual_seed(0))
    assert torch.equal(with_goal[goal_key(STATE)], torch.full((5, 6), -7.0))
    # No goal column and no episode-end frame: one line naming the goal key.
    with pytest.raises(ValueError, match=r"no goal 'observation.goal_state'") as err:
        indicator_core.dataset_batch_to_transitions(hand_made_batch(5, with_end=False), cfg)
    assert "\n" not in str(err.value) and str(err.value).endswith(
        "needs --policy.episode_end_goal=true (the episode's last frame stands in for the recorded goal)"
    )


def make_state_dataset(root: Path, episodes: int, horizon: int) -> Path:
    """A goal-free recording with the sawyer_reach state task's keys: T + 1 frames per episode."""
    from lerobot.datasets import LeRobotDataset

    features = {
        STATE: {"dtype": "float32", "shape": (3,), "names": ["x", "y", "z"]},
        "action": {"dtype": "float32", "shape": (3,), "names": ["dx", "dy", "dz"]},
    }
    ds = LeRobotDataset.create("local/reach_no_goal", fps=30, features=features, root=root, use_videos=False)
    for ep in range(episodes):
        for t in range(horizon + 1):
            value = np.full(3, ep + t / 100, dtype=np.float32)
            ds.add_frame({STATE: value, "action": np.zeros(3, np.float32), "task": "reach"})
        ds.save_episode()
    ds.finalize()
    return root


def test_online_buffer_seed_uses_each_episode_last_frame_as_its_goal(tmp_path, caplog):
    from lerobot.configs.default import DatasetConfig

    from lerobot_indicator.training.dataset_seed import dataset_episodes, load_dataset

    root = make_state_dataset(tmp_path / "d", episodes=2, horizon=4)
    dataset = load_dataset(DatasetConfig(repo_id="local/reach_no_goal", root=str(root)))
    with caplog.at_level(logging.INFO):
        episodes = list(dataset_episodes(dataset, [STATE, goal_key(STATE)], horizon=4))
    assert len(episodes) == 2
    for ep, (obs, actions, gt) in enumerate(episodes):
        assert obs[STATE].shape == (5, 3) and actions.shape == (4, 3) and gt is None
        np.testing.assert_array_equal(obs[goal_key(STATE)], np.full((1, 3), ep + 0.04, np.float32))
    assert sum("has no goal columns" in r.getMessage() for r in caplog.records) == 1


def test_lerobot_indicator_train_trains_from_a_dataset_without_goal_columns(tmp_path):
    root = make_state_dataset(tmp_path / "d", episodes=2, horizon=5)
    out = tmp_path / "run"
    cmd = [
        str(BIN / "lerobot-indicator-train"),
        "--env.type=sawyer_reach",
        "--env.obs_type=state",
        "--env.episode_length=5",
        "--policy.type=indicator_ddpg",
        "--policy.push_to_hub=false",
        "--policy.device=cpu",
        "--policy.hidden_dims=[16,16,16]",
        "--dataset.repo_id=local/reach_no_goal",
        f"--dataset.root={root}",
        "--online.episodes_per_cycle=0",
        "--online.n_envs=1",
        "--online.use_async_envs=false",
        "--online.updates_per_cycle=2",
        "--online.batch_size=8",
        "--online.eval_episodes=1",
        "--steps=2",
        f"--output_dir={out}",
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env())
    assert proc.returncode == 0, proc.stderr[-4000:]
    assert "has no goal columns" in proc.stdout + proc.stderr
    rows = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    assert rows[-1]["step"] == 2 and rows[-1]["env_steps"] == 0 and rows[-1]["episodes"] == 2
    assert np.isfinite(rows[-1]["critic_loss"])


# ---------------- deployment: a goal image ----------------


def robot_frames(seed: int) -> dict[str, np.ndarray]:
    """What a robot's cameras and joints give ``build_dataset_frame``: HxWx3 uint8 images, joint values."""
    rng = np.random.default_rng(seed)
    frames = {f"joint_{i}": float(v) for i, v in enumerate(rng.standard_normal(6))}
    return frames | {
        k.rpartition(".")[2]: rng.integers(0, 256, (SIZE, SIZE, 3), dtype=np.uint8) for k in CAMERAS
    }


def test_save_goal_from_a_dataset_frame_with_the_cli(teleop: Path, tmp_path, monkeypatch):
    from lerobot.datasets import LeRobotDataset
    from safetensors.torch import load_file

    argv = ["save_goal", f"--dataset.repo_id={TELEOP_ID}", f"--dataset.root={teleop}", "--episode=1",
            "--frame=-1", f"--output_dir={tmp_path / 'goal'}"]  # fmt: skip
    monkeypatch.setattr(sys, "argv", argv)
    goal_observations.main()
    saved = load_file(str(tmp_path / "goal" / goal_observations.GOAL_FILE))
    assert sorted(saved) == sorted(goal_key(k) for k in CAMERAS)
    last = LeRobotDataset(TELEOP_ID, root=teleop)[sum(LENGTHS[:2]) - 1]
    for key in CAMERAS:
        assert saved[goal_key(key)].dtype == torch.float32 and torch.equal(saved[goal_key(key)], last[key])


def test_processor_step_adds_the_goal_bit_for_bit_and_names_a_missing_one(trained, tmp_path):
    from lerobot.configs import PreTrainedConfig
    from lerobot.processor import PolicyProcessorPipeline

    from lerobot_indicator.policy.processor_indicator_ddpg import (
        GoalObservationsProcessorStep,
        make_indicator_ddpg_pre_post_processors,
    )

    checkpoint, _ = trained
    goal = goal_observations.camera_observation({k: robot_frames(1)[k.rpartition(".")[2]] for k in CAMERAS})
    goal_observations.save_goal(tmp_path / "goal", goal, CAMERAS)
    cfg = PreTrainedConfig.from_pretrained(checkpoint, cli_overrides=[f"--goal_path={tmp_path / 'goal'}"])
    pre, _ = make_indicator_ddpg_pre_post_processors(cfg)
    steps = [s for s in pre.steps if isinstance(s, GoalObservationsProcessorStep)]
    assert len(steps) == 1
    pre.save_pretrained(tmp_path / "saved")
    reloaded = PolicyProcessorPipeline.from_pretrained(tmp_path / "saved", "policy_preprocessor.json")
    step = next(s for s in reloaded.steps if isinstance(s, GoalObservationsProcessorStep))
    observation = {k: torch.rand(2, 3, SIZE, SIZE) for k in CAMERAS} | {STATE: torch.rand(2, 6)}
    out = step.observation(observation)
    for key in CAMERAS:
        assert out[goal_key(key)].shape == (2, 3, SIZE, SIZE)
        assert all(torch.equal(row, goal[key][0]) for row in out[goal_key(key)])
    # An observation that has its goals keeps them.
    given = {**observation, goal_key(FRONT): observation[FRONT], goal_key(WRIST): observation[WRIST]}
    kept = step.observation(given)
    assert kept[goal_key(FRONT)] is observation[FRONT]
    # A goal file without one of the compared keys: one line naming the key.
    goal_observations.save_goal(tmp_path / "front_only", goal, [FRONT])
    with pytest.raises(goal_observations.GoalObservationError, match=repr(goal_key(WRIST))) as err:
        GoalObservationsProcessorStep(str(tmp_path / "front_only"), CAMERAS).observation(observation)
    assert "\n" not in str(err.value)
    with pytest.raises(goal_observations.GoalObservationError, match="does not exist"):
        GoalObservationsProcessorStep(str(tmp_path / "nowhere"), CAMERAS).observation(observation)


def test_rollout_engine_drives_the_policy_toward_the_saved_goal(trained, teleop, tmp_path, monkeypatch):
    """LeRobot's own per-tick inference (lerobot-rollout's SyncInferenceEngine) on a fake robot's frames, with
    the checkpoint's own pre-processor: --policy.goal_path supplies the goal the robot never sends."""
    from lerobot.configs import PreTrainedConfig
    from lerobot.datasets import LeRobotDatasetMetadata
    from lerobot.policies import make_pre_post_processors
    from lerobot.rollout.inference.sync import SyncInferenceEngine
    from lerobot.utils.feature_utils import build_dataset_frame

    from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

    checkpoint, _ = trained
    goal_frames = robot_frames(1)
    goal = goal_observations.camera_observation({k: goal_frames[k.rpartition(".")[2]] for k in CAMERAS})
    goal_observations.save_goal(tmp_path / "goal", goal, CAMERAS)
    loads = []
    load_file = goal_observations.load_file
    monkeypatch.setattr(goal_observations, "load_file", lambda p: loads.append(p) or load_file(p))

    def engine(goal_path: Path | None) -> tuple[SyncInferenceEngine, list]:
        overrides = [f"--goal_path={goal_path}"] if goal_path else []
        cfg = PreTrainedConfig.from_pretrained(checkpoint, cli_overrides=overrides)
        policy = IndicatorDDPGPolicy.from_pretrained(checkpoint, config=cfg)
        pre, post = make_pre_post_processors(cfg, pretrained_path=str(checkpoint))
        seen = []
        actor_forward = policy.actor.forward
        monkeypatch.setattr(policy.actor, "forward", lambda o, g: seen.append((o, g)) or actor_forward(o, g))
        action_keys = [f"joint_{i}" for i in range(6)]
        run = SyncInferenceEngine(policy, pre, post, features, action_keys, "teleop", "cpu", "so100_follower")
        return run, seen

    features = LeRobotDatasetMetadata(TELEOP_ID, root=teleop).features
    run, seen = engine(tmp_path / "goal")
    for tick in range(2):
        frames = goal_frames if tick == 1 else robot_frames(10 + tick)
        action = run.get_action(build_dataset_frame(features, frames, prefix="observation"))
        assert action.shape == (6,) and torch.isfinite(action).all()
    assert len(loads) == 1  # loaded once, on the first tick
    for (obs, goal_seen), reached in zip(seen, [False, True], strict=True):
        for key in CAMERAS:
            assert torch.equal(goal_seen[key][0], goal[key][0])
        equal = indicator_core.indicator_reward(obs, goal_seen, 1.0, -1.0)
        assert equal.tolist() == [1.0 if reached else -1.0]  # the robot at the goal frame is at the goal
    # Without --policy.goal_path the robot's observations lack the goal: one line naming it and the flag.
    run, _ = engine(None)
    with pytest.raises(KeyError, match="observation.images.goal_front") as err:
        run.get_action(build_dataset_frame(features, robot_frames(3), prefix="observation"))
    assert "--policy.goal_path" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("stored_goal", [True, False])
def test_lerobot_train_fetches_the_episode_end_only_for_local_data_without_goals(tmp_path, stored_goal):
    """Before lerobot-train makes the dataset, an unset episode_end_goal is chosen from its info.json: data with
    goal columns reads no extra frame per sample, data without reads the episode's last frame."""
    from types import SimpleNamespace

    from lerobot_indicator.data.integrity import fetch_episode_end_only_without_goals

    features = {FRONT: {"dtype": "video", "shape": [SIZE, SIZE, 3]}}
    if stored_goal:
        features[goal_key(FRONT)] = features[FRONT]
    (tmp_path / "meta").mkdir()
    (tmp_path / "meta" / "info.json").write_text(json.dumps({"features": features}))
    cfg = SimpleNamespace(policy=IndicatorDDPGConfig(device="cpu"))
    assert cfg.policy.observation_delta_indices[-1] == EPISODE_END_OFFSET  # unknown data: fetched
    fetch_episode_end_only_without_goals(cfg, tmp_path)
    assert cfg.policy.episode_end_goal is (not stored_goal)
    assert (cfg.policy.observation_delta_indices[-1] == EPISODE_END_OFFSET) is (not stored_goal)
    given = SimpleNamespace(policy=IndicatorDDPGConfig(device="cpu", episode_end_goal=True))
    fetch_episode_end_only_without_goals(given, tmp_path)
    assert given.policy.episode_end_goal is True  # a given value stays
