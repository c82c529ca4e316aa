"""What LeRobot's tools and third-party checkers read of a recorded dataset: per-dimension ``names`` on every
vector feature, ``robot_type``, a dataset card with paper, citation, simulator, sensors and the command, YAML
that ``yaml.safe_load`` reads, and the final-observation frame marked as padding (docs/dataset_format.md)."""

import os
import re
import shlex

import draccus
import gymnasium as gym
import numpy as np
import pytest
import yaml
from huggingface_hub import DatasetCard
from lerobot.datasets.utils import create_lerobot_dataset_card
from lerobot.utils.feature_utils import dataset_to_policy_features

import lerobot_indicator  # noqa: F401  (registers the gym ids)
from lerobot_indicator.data import recorder
from lerobot_indicator.data.features import dataset_features
from lerobot_indicator.data.recorder import (
    RecordConfig,
    dataset_card,
    record,
    record_command,
    recording_settings,
)
from lerobot_indicator.envs import RopePushEnvConfig, SawyerReachEnvConfig
from lerobot_indicator.keys import ACTION_IS_PAD

T = 3
BOOKKEEPING = {"timestamp", "frame_index", "episode_index", "index", "task_index"}
SMALL_CAMERA = {"width": 32, "height": 32}


@pytest.fixture(autouse=True)
def _egl(monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")


def _record(tmp_path, env, name: str, **kwargs):
    cfg = RecordConfig(
        env=env,
        repo_id=f"test/{name}",
        root=tmp_path / name,
        num_episodes=2,
        image_writer_threads=0,
        **kwargs,
    )
    return cfg, record(cfg)


@pytest.fixture(scope="module")
def reach_rgbd(tmp_path_factory):
    env = SawyerReachEnvConfig(obs_type="rgbd", episode_length=T, camera=dict(SMALL_CAMERA))
    return _record(tmp_path_factory.mktemp("reach"), env, "reach_rgbd", policy="noisy_scripted")


def _vector_features(features: dict) -> dict:
    return {
        k: ft for k, ft in features.items() if ft["dtype"] not in ("image", "video") and k not in BOOKKEEPING
    }


def _assert_every_vector_is_named(features: dict) -> None:
    for key, ft in _vector_features(features).items():
        names = ft["names"]
        assert isinstance(names, list) and all(isinstance(n, str) and n for n in names), key
        assert len(names) == int(np.prod(ft["shape"])) and len(set(names)) == len(names), key


def test_reach_features_are_named_and_the_robot_is_sawyer(reach_rgbd):
    _, ds = reach_rgbd
    features = ds.meta.features
    _assert_every_vector_is_named(features)
    assert ds.meta.robot_type == "sawyer"
    for key in ("observation.state", "observation.goal_state", "observation.gt_achieved_goal"):
        assert features[key]["names"] == ["x", "y", "z"], key
    assert features["action"]["names"] == ["delta_x", "delta_y", "delta_z"]


def test_rope_names_its_links_and_pushes(tmp_path):
    _, ds = _record(tmp_path, RopePushEnvConfig(obs_type="state"), "rope", policy="scripted")
    features = ds.meta.features
    _assert_every_vector_is_named(features)
    assert ds.meta.robot_type == "sawyer"
    links = [f"link{i}_{axis}" for i in range(15) for axis in "xy"]
    for key in ("observation.rope_xy", "observation.goal_rope_xy", "observation.gt_desired_goal"):
        assert features[key]["names"] == links, key
    assert features["observation.state"]["names"][:4] == ["link0_x", "link0_y", "link0_z", "link1_x"]
    assert features["action"]["names"] == ["push_start_x", "push_start_y", "push_end_x", "push_end_y"]


@pytest.mark.parametrize(
    ("gym_id", "robot"),
    [
        ("lerobot_indicator/Reacher-v0", "reacher"),
        ("lerobot_indicator/FetchReach-v0", "fetch"),
        ("lerobot_indicator/FetchPush-v0", "fetch"),
    ],
)
def test_gym_wrapped_tasks_name_every_dimension_with_their_own_robot(gym_id, robot):
    pytest.importorskip("gymnasium_robotics")
    env = gym.make(gym_id, obs_type="state").unwrapped
    try:
        _, info = env.reset(seed=0)
        # dataset_features refuses names whose count differs from the dimension (a mis-named env fails here).
        features = dataset_features(env.observation_space, env.action_space, info, False, env.feature_names())
        assert env.robot_type == robot
        _assert_every_vector_is_named(features)
        assert not any(
            n.startswith("environment_state_") for n in features["observation.environment_state"]["names"]
        )
    finally:
        env.close()


def test_env_without_names_gets_indexed_names_and_mismatched_names_are_refused():
    obs = gym.spaces.Dict(
        {"agent_pos": gym.spaces.Box(-1, 1, (2,)), "goal_state": gym.spaces.Box(-1, 1, (2,))}
    )
    features = dataset_features(obs, gym.spaces.Box(-1, 1, (2,)), {}, False)
    assert features["observation.goal_state"]["names"] == ["goal_state_0", "goal_state_1"]
    assert features["action"]["names"] == ["action_0", "action_1"]
    with pytest.raises(ValueError, match="feature names of 'agent_pos': 3 names for shape \\(2,\\)"):
        dataset_features(obs, gym.spaces.Box(-1, 1, (2,)), {}, False, {"agent_pos": ["x", "y", "z"]})


def test_final_observation_frame_is_marked_and_repeats_the_last_action(reach_rgbd):
    _, ds = reach_rgbd
    frame = np.asarray(ds.hf_dataset["frame_index"])
    pad = np.asarray(ds.hf_dataset[ACTION_IS_PAD]).reshape(-1)
    actions = np.stack([np.asarray(a) for a in ds.hf_dataset["action"]])
    np.testing.assert_array_equal(pad, frame == T)  # o_T alone, in every episode
    last = np.flatnonzero(frame == T)
    np.testing.assert_array_equal(actions[last], actions[last - 1])  # LeRobot's padding, never a zero "stop"
    assert np.abs(actions[last]).max() > 0
    # No policy takes the marker as an input or output feature; `action` stays the only action feature.
    policy_features = dataset_to_policy_features(ds.meta.features)
    assert ACTION_IS_PAD not in policy_features
    assert [k for k, ft in policy_features.items() if ft.type.name == "ACTION"] == ["action"]


def test_dataset_recorded_without_the_marker_resumes_without_it(tmp_path, monkeypatch):
    def unmarked(*args, **kwargs):
        return {k: v for k, v in dataset_features(*args, **kwargs).items() if k != ACTION_IS_PAD}

    env = SawyerReachEnvConfig(obs_type="state", episode_length=T)
    with monkeypatch.context() as m:
        m.setattr(recorder, "dataset_features", unmarked)
        _record(tmp_path, env, "old")
    cfg = RecordConfig(env=env, repo_id="test/old", root=tmp_path / "old", num_episodes=1, resume=True)
    ds = record(cfg)
    assert ds.meta.total_episodes == 3 and ACTION_IS_PAD not in ds.meta.features
    assert len(ds) == 3 * (T + 1)


def test_card_names_paper_citation_simulator_sensors_and_command(reach_rgbd):
    cfg, ds = reach_rgbd
    command = record_command(cfg, ds.meta.total_episodes)
    fields = dataset_card(ds, cfg, command)
    card = create_lerobot_dataset_card(
        tags=["lerobot-indicator"],
        dataset_info=ds.meta.info,
        license=cfg.license,
        repo_id=cfg.repo_id,
        **fields,
    )
    text = str(card)
    header = text.split("---")[1]
    assert yaml.safe_load(header)["license"] == "apache-2.0"
    assert "- **Paper:** https://arxiv.org/abs/1905.07866" in text
    citation = text.split("## Citation")[1]
    assert "[More Information Needed]" not in citation and "@inproceedings{lin2019" in citation
    assert "Lin, Xingyu and Baweja, Harjatin Singh and Held, David" in text
    assert "**simulated** with MuJoCo" in text and "robosuite" in text and "(robot: sawyer)" in text
    assert "`observation.images.front`: simulated RGB camera, 32x32x3 uint8" in text
    assert "`observation.images.front_depth`: simulated depth camera, 32x32x1 uint16 millimetres" in text
    assert "`observation.state`: float32 vector (3: x, y, z)" in text
    assert "scripts/record.py" not in text and f"```bash\n{command}\n```" in text
    # The command records the same dataset: parsed back, it gives the same env and reward settings.
    assert command.startswith("lerobot-indicator-record ")
    parsed = draccus.parse(RecordConfig, args=shlex.split(command)[1:])
    assert recording_settings(parsed) == recording_settings(cfg)
    assert (parsed.policy, parsed.num_episodes) == (cfg.policy, ds.meta.total_episodes)
    # A dataset that is never pushed carries the same card as its local README.md (third-party checkers and
    # readers of the folder look for it there).
    local = DatasetCard((ds.root / "README.md").read_text())
    assert {"lerobot-indicator", "indicator-rewards", "sawyer_reach"} <= set(local.data.tags)
    assert local.text == card.text and "@inproceedings{lin2019" in local.text
    assert not (ds.root / "README.md.tmp").exists()
    # The env config block is plain YAML (no python tags) equal to the recorded settings.
    (block,) = re.findall(r"```yaml\n(.*?)```", text, flags=re.S)
    assert "!!python" not in block
    assert yaml.safe_load(block) == recording_settings(cfg)["env"]
