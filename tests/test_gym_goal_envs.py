"""The wrapped gymnasium goal tasks (reacher, fetch_reach, fetch_push, fetch_slide) under the task contract of
docs/conventions.md: keys, goal images rendered in the goal configuration, exact restore, hidden markers,
LeRobot's make_env path and one tiny lerobot-indicator-train cycle."""

import json
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

os.environ.setdefault("MUJOCO_GL", "egl")
pytest.importorskip("gymnasium_robotics")

from lerobot.envs.factory import make_env, make_env_config, make_env_pre_post_processors  # noqa: E402
from lerobot.envs.utils import close_envs, env_to_policy_features, preprocess_observation  # noqa: E402

import lerobot_indicator  # noqa: E402, F401  (registers the gym ids and env types)
from lerobot_indicator.envs.configs import load_env_config, save_env_config  # noqa: E402
from lerobot_indicator.envs.gym_goal import GYM_GEOM_GROUPS, MARKER_GROUP  # noqa: E402
from lerobot_indicator.envs.reacher import two_link_ik  # noqa: E402
from lerobot_indicator.envs.rendering import RGBDRenderer  # noqa: E402
from lerobot_indicator.keys import GT_INFO_KEYS  # noqa: E402

H, W = 24, 32
SMALL = {"width": W, "height": H}
# env type -> (gym id, state_dim, action_dim, environment_state dim, paper epsilon, default obs type)
TASKS = {
    "reacher": ("lerobot_indicator/Reacher-v0", 2, 2, 6, 0.01, "rgb"),
    "fetch_reach": ("lerobot_indicator/FetchReach-v0", 3, 3, 10, 0.05, "rgbd"),
    "fetch_push": ("lerobot_indicator/FetchPush-v0", 3, 4, 25, 0.05, "state"),
    "fetch_slide": ("lerobot_indicator/FetchSlide-v0", 3, 4, 25, 0.05, "state"),
}
_ENVS: dict[tuple[str, str], gym.Env] = {}


def env_of(task: str, obs_type: str):
    """One unwrapped env per (task, obs type) for the whole module (building a Fetch env takes a second)."""
    if (task, obs_type) not in _ENVS:
        gym_id = TASKS[task][0]
        _ENVS[task, obs_type] = gym.make(gym_id, obs_type=obs_type, camera=dict(SMALL)).unwrapped
    return _ENVS[task, obs_type]


@pytest.fixture(scope="module", autouse=True)
def _close_envs():
    yield
    for env in _ENVS.values():
        env.close()
    _ENVS.clear()


def rng_actions(env, n: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.uniform(-1, 1, env.action_space.shape).astype(np.float32) for _ in range(n)]


@pytest.mark.parametrize("task", sorted(TASKS))
def test_env_types_have_the_papers_defaults(task):
    gym_id, state_dim, action_dim, env_dim, epsilon, obs_type = TASKS[task]
    cfg = make_env_config(task)
    assert (cfg.episode_length, cfg.epsilon, cfg.obs_type) == (50, epsilon, obs_type)
    assert (cfg.camera.width, cfg.camera.height) == (100, 100)
    assert (cfg.state_dim, cfg.action_dim, cfg.env_state_dim) == (state_dim, action_dim, env_dim)
    assert cfg.gym_id == gym_id and gym.spec(gym_id).max_episode_steps == 50
    # a camera dict keeps the task's camera pose
    small = make_env_config(task, camera={"width": 40})
    assert small.camera.width == 40 and small.camera.pos == cfg.camera.pos


@pytest.mark.parametrize(
    "task,obs_type",
    [
        ("reacher", "rgb"),
        ("reacher", "state"),
        ("fetch_reach", "rgbd"),
        ("fetch_push", "state"),
        ("fetch_slide", "rgb"),
    ],
)
def test_reset_step_keys_shapes_dtypes_and_info(task, obs_type):
    _, state_dim, action_dim, env_dim, epsilon, _ = TASKS[task]
    env = env_of(task, obs_type)
    assert env.action_space.shape == (action_dim,) and env.epsilon == epsilon
    first, _ = env.reset(seed=3)
    for obs in (first, env.step(env.action_space.sample())[0]):
        assert env.observation_space.contains(obs)
        expected = {"agent_pos", "goal_state"}
        assert obs["agent_pos"].shape == obs["goal_state"].shape == (state_dim,)
        assert obs["agent_pos"].dtype == np.float32
        if obs_type == "state":
            expected.add("environment_state")
            assert obs["environment_state"].shape == (env_dim,)
        else:
            expected.add("pixels")
            assert set(obs["pixels"]) == {"front", "goal_front"}
            assert all(v.shape == (H, W, 3) and v.dtype == np.uint8 for v in obs["pixels"].values())
        if obs_type == "rgbd":
            expected |= {"front_depth", "goal_front_depth"}
            for key in ("front_depth", "goal_front_depth"):
                assert obs[key].shape == (H, W, 1) and obs[key].dtype == np.uint16
            assert 300 < obs["front_depth"][obs["front_depth"] > 0].mean() < 3000  # millimetres
        assert set(obs) == expected
    obs, reward, terminated, truncated, info = env.step(np.zeros(action_dim, dtype=np.float32))
    assert set(info) == {*GT_INFO_KEYS, "is_success"}
    assert info["gt_achieved_goal"].shape == info["gt_desired_goal"].shape == (state_dim,)
    distance = np.linalg.norm(info["gt_achieved_goal"] - info["gt_desired_goal"])
    assert info["gt_distance"] == pytest.approx(distance, abs=1e-6)
    assert info["is_success"] == (info["gt_distance"] <= epsilon) and reward == (
        1.0 if info["is_success"] else -1.0
    )
    assert not terminated and not truncated
    # the compared state is the ground-truth goal space (the paper's goal dimension)
    np.testing.assert_array_equal(info["gt_achieved_goal"], obs["agent_pos"])
    np.testing.assert_array_equal(info["gt_desired_goal"], obs["goal_state"])
    assert env.render().shape == (H, W, 3)


@pytest.mark.parametrize(
    "task,obs_type", [("reacher", "rgb"), ("fetch_reach", "rgbd"), ("fetch_push", "rgb")]
)
def test_observation_in_the_goal_configuration_is_the_goal(task, obs_type):
    env = env_of(task, obs_type)
    obs, info = env.reset(seed=5)
    assert info["gt_distance"] > env.epsilon  # no episode starts solved
    env._enter_goal_configuration()
    at_goal = env.camera_observation()
    for key, image in at_goal.items():
        goal = obs["pixels"]["goal_" + key] if image.shape[-1] == 3 else obs["goal_" + key]
        np.testing.assert_array_equal(image, goal)
    np.testing.assert_array_equal(env._agent_state().astype(np.float32), obs["goal_state"])
    assert not np.array_equal(at_goal["front"], obs["pixels"]["front"])  # the goal differs from the start


@pytest.mark.parametrize("task,obs_type", [("reacher", "rgb"), ("fetch_reach", "rgbd")])
def test_goal_renders_are_identical_and_restore_leaves_the_episode_bit_identical(task, obs_type):
    gym_id = TASKS[task][0]
    a = gym.make(gym_id, obs_type=obs_type, camera=dict(SMALL)).unwrapped
    b = env_of(task, obs_type)
    try:
        obs_a, _ = a.reset(seed=11)
        obs_b, _ = b.reset(seed=11)
        goal = {k: v.copy() for k, v in b._goal_obs.items()}
        b._render_goal_observation()  # again, mid-episode: same images, state restored exactly
        for key, image in goal.items():
            np.testing.assert_array_equal(b._goal_obs[key], image)
        for action in rng_actions(a, 6):
            obs_a, *_ = a.step(action)
            obs_b, *_ = b.step(action)
            if b._elapsed == 3:
                b._render_goal_observation()
        np.testing.assert_array_equal(a.save_state(), b.save_state())
        np.testing.assert_array_equal(obs_a["pixels"]["front"], obs_b["pixels"]["front"])
        np.testing.assert_array_equal(obs_a["agent_pos"], obs_b["agent_pos"])
    finally:
        a.close()


def test_observation_is_a_function_of_the_state():
    """Every observation equals a render of its state restored: mj_forward runs before rendering, since
    Reacher-v5's step leaves positions one substep stale (at 64x64, 7 of these 8 frames differ without it)."""
    env = gym.make("lerobot_indicator/Reacher-v0", camera={"width": 64, "height": 64}).unwrapped
    try:
        env.reset(seed=2)
        for _ in range(8):
            obs, *_ = env.step(np.ones(2, dtype=np.float32))
            env.restore_state(env.save_state())
            np.testing.assert_array_equal(env.camera_observation()["front"], obs["pixels"]["front"])
    finally:
        env.close()


def _with_markers(env) -> np.ndarray:
    renderer = RGBDRenderer(env.model, W, H, geom_groups=(*GYM_GEOM_GROUPS, MARKER_GROUP))
    try:
        env._mj.mj_forward(env.model, env.data)
        return renderer.render(env.data, env._camera(), depth=False)[0]
    finally:
        renderer.close()


def test_reacher_target_is_hidden():
    env = env_of("reacher", "rgb")
    obs, _ = env.reset(seed=4)
    target = env.model.joint("target_x").qposadr[0]
    shown = _with_markers(env)
    assert not np.array_equal(shown, obs["pixels"]["front"])  # the target is in view ...
    env.data.qpos[target : target + 2] += 0.05
    env._mj.mj_forward(env.model, env.data)
    np.testing.assert_array_equal(
        env.camera_observation()["front"], obs["pixels"]["front"]
    )  # ... never drawn
    assert not np.array_equal(_with_markers(env), shown)


def test_fetch_target_site_and_mocap_are_hidden():
    env = env_of("fetch_reach", "rgbd")
    obs, _ = env.reset(seed=4)
    mocap = env.model.body("robot0:mocap").mocapid[0]
    env.data.mocap_pos[mocap] = env.data.site_xpos[env.model.site("robot0:grip").id] + [0.0, 0.05, 0.05]
    shown = _with_markers(env)
    assert not np.array_equal(shown, obs["pixels"]["front"])  # the mocap crosshair is in view ...
    env.model.site_pos[env.model.site("target0").id] = env.data.site_xpos[env.model.site("robot0:grip").id]
    current = env.camera_observation()
    np.testing.assert_array_equal(current["front"], obs["pixels"]["front"])  # ... never drawn
    np.testing.assert_array_equal(current["front_depth"], obs["front_depth"])


def test_seeded_resets_repeat_and_differ():
    env = env_of("fetch_push", "state")
    first = env.reset(seed=21)[0]
    again = env.reset(seed=21)[0]
    other = env.reset(seed=22)[0]
    for key in first:
        np.testing.assert_array_equal(first[key], again[key])
    assert not np.array_equal(first["goal_state"], other["goal_state"])


def test_images_come_with_the_environment_state_only_when_asked():
    env = gym.make(
        TASKS["reacher"][0], obs_type="rgb", camera=dict(SMALL), env_state_with_images=True
    ).unwrapped
    try:
        obs, _ = env.reset(seed=3)
        obs, *_ = env.step(np.ones(2, dtype=np.float32))
        assert set(obs["pixels"]) == {"front", "goal_front"}
        np.testing.assert_array_equal(obs["environment_state"], env.environment_state().astype(np.float32))
        assert obs["environment_state"][4:].any()  # the velocities a full-torque step leaves
    finally:
        env.close()
    assert "environment_state" not in env_of("reacher", "rgb").reset(seed=3)[0]


@pytest.mark.parametrize("task,obs_type", [("reacher", "rgb"), ("fetch_reach", "rgbd")])
def test_previous_frame_shows_the_last_observation_and_the_goal_again(task, obs_type):
    env = gym.make(TASKS[task][0], obs_type=obs_type, camera=dict(SMALL), previous_frame=True).unwrapped
    image_keys = [("pixels", "front"), (None, "front_depth")] if obs_type == "rgbd" else [("pixels", "front")]

    def image(obs, nest, name):
        return obs[nest][name] if nest else obs[name]

    def prev(name):
        return name.replace("front", "front_prev")

    try:
        obs, _ = env.reset(seed=5)
        assert set(obs["pixels"]) == {"front", "goal_front", "front_prev", "goal_front_prev"}
        assert set(env.observation_space.spaces["pixels"].spaces) == set(obs["pixels"])
        for nest, name in image_keys:  # at reset the start's own images; the goal at rest
            np.testing.assert_array_equal(image(obs, nest, prev(name)), image(obs, nest, name))
            np.testing.assert_array_equal(
                image(obs, nest, "goal_" + prev(name)), image(obs, nest, "goal_" + name)
            )
        for action in rng_actions(env, 3, seed=5):
            last = obs
            obs, *_ = env.step(action)
            for nest, name in image_keys:
                np.testing.assert_array_equal(image(obs, nest, prev(name)), image(last, nest, name))
                np.testing.assert_array_equal(
                    image(obs, nest, "goal_" + prev(name)), image(obs, nest, "goal_" + name)
                )
            assert not np.array_equal(obs["pixels"]["front"], obs["pixels"]["front_prev"])  # the arm moved
        again, _ = env.reset(seed=5)  # a reset forgets the last episode's frames
        np.testing.assert_array_equal(again["pixels"]["front_prev"], again["pixels"]["front"])
    finally:
        env.close()
    assert "front_prev" not in env_of(task, obs_type).reset(seed=5)[0]["pixels"]
    with pytest.raises(ValueError, match="previous_frame"):
        make_env_config(task, obs_type="state", previous_frame=True)


def test_reacher_environment_state_is_the_wrapped_observation_without_its_goal():
    env = env_of("reacher", "state")
    env.reset(seed=1)
    inner_obs, *_ = env.inner.step(np.zeros(2))
    np.testing.assert_allclose(env.environment_state(), np.concatenate([inner_obs[:4], inner_obs[6:8]]))


def test_two_link_ik_reaches_the_target_on_one_elbow_branch():
    l1, l2 = 0.1, 0.11
    for x, y in [(0.15, 0.05), (-0.1, 0.12), (0.02, -0.19), (0.0, 0.205)]:
        shoulder, elbow = two_link_ik(np.array([x, y]), l1, l2, elbow_limit=3.0)
        tip = [
            l1 * np.cos(shoulder) + l2 * np.cos(shoulder + elbow),
            l1 * np.sin(shoulder) + l2 * np.sin(shoulder + elbow),
        ]
        np.testing.assert_allclose(tip, [x, y], atol=1e-12)
        assert 0.0 <= elbow <= 3.0


def test_config_validation_and_file_round_trip(tmp_path):
    cfg = make_env_config("reacher", obs_type="rgbd", camera={"width": 64, "height": 48})
    save_env_config(cfg, tmp_path / "reacher.yaml")
    assert load_env_config(tmp_path / "reacher.yaml") == cfg
    with pytest.raises(ValueError, match="state_dim, action_dim, env_state_dim"):
        make_env_config("fetch_push", action_dim=3)
    with pytest.raises(ValueError, match="epsilon"):
        make_env_config("fetch_reach", epsilon=0.0)
    with pytest.raises(ValueError, match="fps"):
        gym.make("lerobot_indicator/Reacher-v0", fps=20)


def eval_batch(cfg, n_envs=2):
    """One observation batch exactly as lerobot-eval's rollout builds it."""
    envs = make_env(cfg, n_envs=n_envs)
    vec = envs[cfg.type][0]
    try:
        obs, _ = vec.reset(seed=list(range(n_envs)))
        env_pre, _ = make_env_pre_post_processors(cfg, policy_cfg=None)
        batch = env_pre(preprocess_observation(obs))
        _, _, _, _, info = vec.step(np.zeros((n_envs, cfg.action_dim), dtype=np.float32))
        return batch, info, vec.call("render"), vec.call("_max_episode_steps")[0]
    finally:
        close_envs(envs)


@pytest.mark.parametrize(
    "task,obs_type,keys",
    [
        (
            "reacher",
            "rgb",
            {"observation.images.front": (3, H, W), "observation.images.goal_front": (3, H, W)},
        ),
        (
            "fetch_reach",
            "rgbd",
            {"observation.images.front_depth": (1, H, W), "observation.images.goal_front_depth": (1, H, W)},
        ),
        ("fetch_push", "state", {"observation.environment_state": (25,)}),
        (
            "reacher",
            "rgb+env_state_with_images",
            {"observation.images.front": (3, H, W), "observation.environment_state": (6,)},
        ),
        (
            "fetch_reach",
            "rgbd+previous_frame",
            {
                "observation.images.front_prev": (3, H, W),
                "observation.images.goal_front_prev_depth": (1, H, W),
            },
        ),
    ],
)
def test_lerobot_make_env_gives_documented_keys(task, obs_type, keys):
    obs_type, _, flag = obs_type.partition("+")
    cfg = make_env_config(task, obs_type=obs_type, camera=dict(SMALL), **({flag: True} if flag else {}))
    batch, info, frames, max_steps = eval_batch(cfg)
    state_dim = TASKS[task][1]
    keys = {**keys, "observation.state": (state_dim,), "observation.goal_state": (state_dim,)}
    policy_features = env_to_policy_features(cfg)
    for key, shape in keys.items():
        assert tuple(batch[key].shape) == (2, *shape) and batch[key].dtype == torch.float32, key
        assert tuple(policy_features[key].shape) == shape, key
    assert set(policy_features) - {"action"} == {k for k in batch if k.startswith("observation.")}
    assert info["is_success"].dtype == bool and info["gt_distance"].shape == (2,)
    assert max_steps == 50 and frames[0].shape == (H, W, 3) and frames[0].dtype == np.uint8


@pytest.mark.parametrize(
    "context",
    [
        [],
        ["--env.env_state_with_images=true", "--policy.context_keys=[observation.environment_state]"],
        ["--env.previous_frame=true"],
    ],
    ids=["images", "images+environment_state", "images+previous_frame"],
)
def test_online_training_runs_one_tiny_cycle_on_visual_reacher(tmp_path, context):
    cmd = [
        str(Path(sys.executable).parent / "lerobot-indicator-train"),
        "--env.type=reacher",
        "--env.obs_type=rgb",
        "--env.camera.width=24",
        "--env.camera.height=24",
        "--env.episode_length=4",
        "--policy.type=indicator_ddpg",
        "--policy.push_to_hub=false",
        "--policy.device=cpu",
        "--online.n_envs=1",
        "--online.use_async_envs=false",
        "--online.episodes_per_cycle=1",
        "--online.updates_per_cycle=2",
        "--online.batch_size=4",
        "--online.eval_episodes=1",
        "--steps=2",
        "--env_eval_freq=2",
        "--save_freq=2",
        "--seed=1",
        f"--output_dir={tmp_path / 'run'}",
        *context,
    ]
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]
    saved = tmp_path / "run" / "checkpoints" / "last" / "pretrained_model"
    assert (saved / "model.safetensors").exists()
    config = json.loads((saved / "config.json").read_text())
    assert config["context_keys"] == (
        ["observation.environment_state"] if "--policy.context_keys" in str(context) else []
    )
    previous = ["observation.images.front_prev"] if "--env.previous_frame=true" in context else []
    assert sorted(config["observation_keys"]) == ["observation.images.front", *previous]


@pytest.mark.parametrize(
    "task,obs_type,compared,context",
    [
        ("reacher", "rgb", ["observation.images.front"], []),
        ("reacher", "rgb+previous_frame", ["observation.images.front", "observation.images.front_prev"], []),
        ("reacher", "state", ["observation.state"], ["observation.environment_state"]),
        ("fetch_reach", "rgbd", ["observation.images.front", "observation.images.front_depth"], []),
        ("fetch_reach", "state", ["observation.state"], ["observation.environment_state"]),
        ("fetch_push", "state", ["observation.state"], ["observation.environment_state"]),
    ],
)
def test_policy_defaults_compare_the_goal_state_and_condition_on_the_environment_state(
    task, obs_type, compared, context
):
    """docs/envs.md's table: with no key flags the policy compares the keys with a goal and, for state
    observations, conditions on ``observation.environment_state`` (context, never compared)."""
    from lerobot.configs import FeatureType

    from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig

    obs_type, _, flag = obs_type.partition("+")
    features = env_to_policy_features(
        make_env_config(task, obs_type=obs_type, **({flag: True} if flag else {}))
    )
    cfg = IndicatorDDPGConfig(device="cpu", horizon=50)
    cfg.output_features = {k: f for k, f in features.items() if f.type is FeatureType.ACTION}
    cfg.input_features = {k: f for k, f in features.items() if f.type is not FeatureType.ACTION}
    cfg.validate_features()
    assert sorted(cfg.observation_keys) == sorted(compared) and cfg.context_keys == context
