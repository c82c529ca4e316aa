"""Failure paths of issue 53 ("Every byte checked, every failure one line"): a policy evaluated or trained beside an
env that does not give its inputs ends at start-up in one line with the fix; robosuite's import notices are not
printed; the online trainer says what it collects before its first update and writes watchable eval videos."""

import logging
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

BIN = Path(sys.executable).parent
SIZE = 32  # the camera size the policy below was made for


def _env() -> dict[str, str]:
    return {
        **os.environ,
        "HF_HUB_OFFLINE": "1",
        "CUDA_VISIBLE_DEVICES": "",
        "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
    }


def _rgbd_env_config(size: int = SIZE, **kwargs):
    from lerobot_indicator.envs import SawyerReachEnvConfig

    return SawyerReachEnvConfig(obs_type="rgbd", camera={"width": size, "height": size}, **kwargs)


def _rgbd_policy(size: int = SIZE):
    """A new indicator_ddpg policy for the sawyer_reach RGB-D observations at ``size`` px."""
    from lerobot.configs import FeatureType
    from lerobot.envs.utils import env_to_policy_features

    from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig
    from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

    features = env_to_policy_features(_rgbd_env_config(size))
    cfg = IndicatorDDPGConfig(device="cpu", horizon=25, push_to_hub=False, hidden_dims=[16, 16, 16])
    cfg.output_features = {k: f for k, f in features.items() if f.type is FeatureType.ACTION}
    cfg.input_features = {k: f for k, f in features.items() if k not in cfg.output_features}
    return IndicatorDDPGPolicy(cfg)


@pytest.fixture(scope="module")
def policy_32px(tmp_path_factory) -> Path:
    """A saved 32 px RGB-D policy with its processors, as lerobot-eval and lerobot-train load it."""
    from lerobot_indicator.policy.processor_indicator_ddpg import make_indicator_ddpg_pre_post_processors

    out = tmp_path_factory.mktemp("policy") / "pretrained_model"
    policy = _rgbd_policy()
    policy.save_pretrained(out)
    for pipeline in make_indicator_ddpg_pre_post_processors(policy.config):
        pipeline.save_pretrained(out)
    return out


def _error_lines(proc: subprocess.CompletedProcess) -> list[str]:
    return [line for line in proc.stderr.splitlines() if line.startswith("error:")]


# ---------------- lerobot-eval: the eval env lacks an input, or gives another image size ----------------


@pytest.mark.parametrize(
    ("env_args", "named", "fix"),
    [
        (
            ["--env.obs_type=state"],
            "the policy's inputs ['observation.images.front', 'observation.images.front_depth'",
            "use --env.obs_type=rgbd --env.camera.height=32 --env.camera.width=32",
        ),
        (
            ["--env.obs_type=rgbd", "--env.camera.height=64", "--env.camera.width=64"],
            "observation.images.front (3, 32, 32) vs (3, 64, 64)",
            "use --env.camera.height=32 --env.camera.width=32",
        ),
    ],
)
def test_lerobot_eval_with_an_env_that_lacks_the_policys_inputs_ends_in_one_line_with_the_fix(
    policy_32px, tmp_path, env_args, named, fix
):
    cmd = [str(BIN / "lerobot-eval"), f"--policy.path={policy_32px}", "--policy.device=cpu",
           "--env.type=sawyer_reach", *env_args, "--eval.n_episodes=1", "--eval.batch_size=1",
           f"--output_dir={tmp_path / 'eval'}"]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=_env())
    assert proc.returncode == 1, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr and "KeyError" not in proc.stderr, proc.stderr[-3000:]
    (line,) = _error_lines(proc)
    assert "eval env sawyer_reach" in line and named in line and line.endswith(fix), line


def test_the_batch_select_action_gets_is_checked_in_one_line():
    """Where LeRobot's eval (or lerobot-rollout) hands observations to the policy, whoever calls it."""
    from lerobot_indicator.io_errors import report_line
    from lerobot_indicator.policy.input_checks import PolicyInputError

    policy = _rgbd_policy()
    state_batch = {"observation.state": torch.zeros(1, 3), "observation.goal_state": torch.zeros(1, 3)}
    with pytest.raises(PolicyInputError) as err:
        policy.select_action(state_batch)
    line = report_line(err.value)
    assert (
        line.startswith("error: batch lacks the policy inputs ['observation.images.front'")
        and "\n" not in line
    )
    assert "use --env.obs_type=rgbd --env.camera.height=32 --env.camera.width=32 (this plugin's envs)" in line
    assert isinstance(err.value, KeyError)  # what it raised before, for callers that catch it
    big = {k: torch.zeros(1, f.shape[0], 64, 64) for k, f in policy.config.input_features.items()}
    with pytest.raises(PolicyInputError) as err:
        policy.select_action(big)
    line = report_line(err.value)
    assert line.startswith(
        "error: observation.images.front: the policy was made for 32x32 (HxW) images, got 64x64"
    )
    assert line.endswith("(this plugin's envs: --env.camera.height=32 --env.camera.width=32)"), line
    right = {k: torch.zeros(1, *f.shape) for k, f in policy.config.input_features.items()}
    assert policy.select_action(right).shape == (1, 3)


# ---------------- lerobot-train: the eval env of another image size, found at start-up ----------------


@pytest.fixture(scope="module")
def dataset_32px(tmp_path_factory) -> Path:
    from lerobot_indicator.data.recorder import RecordConfig, record

    root = tmp_path_factory.mktemp("data") / "reach_32px"
    cfg = RecordConfig(env=_rgbd_env_config(), repo_id="local/reach_32px", root=root, policy="noisy_scripted",
                       num_episodes=1, image_writer_threads=0)  # fmt: skip
    record(cfg)
    return root


@pytest.mark.parametrize("policy", ["pretrained", "new"])
def test_lerobot_train_with_an_eval_env_of_other_image_size_fails_at_start_up(
    policy_32px, dataset_32px, tmp_path, policy
):
    """A 32 px policy (from --policy.path, or made from a 32 px dataset) and a 100 px eval env: one line naming
    both shapes before the first step, not at the first evaluation."""
    policy_args = (
        [f"--policy.path={policy_32px}"] if policy == "pretrained" else ["--policy.type=indicator_ddpg"]
    )
    cmd = [str(BIN / "lerobot-train"), *policy_args, "--dataset.repo_id=local/reach_32px",
           f"--dataset.root={dataset_32px}", "--policy.push_to_hub=false", "--policy.device=cpu",
           "--env.type=sawyer_reach", "--env.obs_type=rgbd", "--batch_size=4", "--num_workers=0", "--steps=2",
           "--wandb.enable=false", f"--output_dir={tmp_path / 'run'}"]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=_env())
    assert proc.returncode == 1, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    (line,) = _error_lines(proc)
    assert "observation.images.front (3, 32, 32) vs (3, 100, 100)" in line, line
    assert line.endswith("use --env.camera.height=32 --env.camera.width=32"), line
    assert not list((tmp_path / "run").glob("checkpoints/*")), "it trained before failing"


# ---------------- robosuite's import notices ----------------


def test_building_a_sawyer_env_prints_no_robosuite_warning():
    code = (
        "from lerobot_indicator.envs import SawyerReachEnvConfig\n"
        "from lerobot.envs.factory import make_env\n"
        "envs = make_env(SawyerReachEnvConfig(), n_envs=2, use_async_envs=True)\n"
        "vec = envs['sawyer_reach'][0]\n"
        "vec.reset(seed=0)\n"
        "vec.close()\n"
        "print('built')\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=_env()
    )
    assert proc.returncode == 0 and "built" in proc.stdout, proc.stderr[-3000:]
    noise = [line for line in proc.stderr.splitlines() if "robosuite" in line.lower()]
    assert not noise, noise


def test_other_robosuite_warnings_are_kept(caplog):
    from lerobot_indicator.envs._robosuite import require_robosuite

    require_robosuite()
    with caplog.at_level(logging.WARNING, logger="robosuite_logs"):
        logging.getLogger("robosuite_logs").warning("No private macro file found!")
        logging.getLogger("robosuite_logs").warning("Controller config not found")
    assert [r.getMessage() for r in caplog.records] == ["Controller config not found"]


# ---------------- the online trainer: its start-up line and its eval videos ----------------


@pytest.fixture(scope="module")
def rgb_online_run(tmp_path_factory):
    """A tiny lerobot-indicator-train run from 32 px RGB images, with its log records and when its first update
    ended (as an index into them)."""
    import draccus

    from lerobot_indicator.training.config import OnlineTrainConfig
    from lerobot_indicator.training.hooks import TrainerHooks
    from lerobot_indicator.training.online import OnlineTrainer

    out = tmp_path_factory.mktemp("online") / "run"
    args = ["--policy.type=indicator_ddpg", "--policy.push_to_hub=false", "--policy.device=cpu",
            "--policy.hidden_dims=[16,16,16]", "--env.type=sawyer_reach", "--env.obs_type=rgb",
            f"--env.camera.height={SIZE}", f"--env.camera.width={SIZE}", "--env.episode_length=5",
            "--online.n_envs=1", "--online.use_async_envs=false", "--online.episodes_per_cycle=1",
            "--online.warmup_episodes=1", "--online.updates_per_cycle=2", "--online.batch_size=4",
            "--online.eval_episodes=1", "--env_eval_freq=2", "--save_freq=2", "--steps=2", "--seed=3",
            f"--output_dir={out}"]  # fmt: skip
    cfg = draccus.parse(OnlineTrainConfig, args=args)
    cfg.validate()
    records: list[logging.LogRecord] = []
    handler = logging.Handler()
    handler.emit = records.append
    first_update: list[int] = []
    hooks = TrainerHooks(on_update_end=lambda *_: first_update.append(len(records)))
    root = logging.getLogger()
    level = root.level
    root.addHandler(handler)
    root.setLevel(logging.INFO)
    try:
        trainer = OnlineTrainer(cfg, hooks)
        try:
            trainer.train()
        finally:
            trainer.close()
    finally:
        root.removeHandler(handler)
        root.setLevel(level)
    return out, [r.getMessage() for r in records], first_update[0]


def test_the_online_trainer_says_what_it_collects_before_the_first_update(rgb_online_run):
    _, messages, first_update = rgb_online_run
    lines = [i for i, m in enumerate(messages) if m.startswith("cycle 0: collecting 1 warm-up")]
    assert lines and lines[0] < first_update, messages
    assert "episode(s) of 5 steps with 1 env(s), then 2 updates of batch 4" in messages[lines[0]]


def test_video_frames_are_upscaled_with_the_goal_beside_them():
    from lerobot_indicator.training.eval_videos import video_frames

    rng = np.random.default_rng(0)
    for size in (32, 40, 100):
        obs = rng.integers(0, 256, (3, size, size, 3), dtype=np.uint8)
        goal = rng.integers(0, 256, (size, size, 3), dtype=np.uint8)
        frames = video_frames(obs, goal)
        k = frames.shape[1] // size
        assert frames.shape == (3, k * size, 2 * k * size, 3) and k * size >= 256 and k % 2 == 0
        np.testing.assert_array_equal(frames[:, ::k, : k * size : k], obs)  # nearest neighbour: exact
        np.testing.assert_array_equal(frames[1, :, k * size :], goal.repeat(k, 0).repeat(k, 1))


def test_online_eval_videos_are_watchable_and_show_the_goal(rgb_online_run):
    import av

    from lerobot_indicator.envs.sawyer_reach import SawyerReachEnv
    from lerobot_indicator.keys import EVAL_SEED_OFFSET

    out, _, _ = rgb_online_run
    env = SawyerReachEnv(obs_type="rgb", camera={"width": SIZE, "height": SIZE}, episode_length=5)
    try:
        goal = env.reset(seed=EVAL_SEED_OFFSET)[0]["pixels"]["goal_front"]  # the first evaluation episode's
    finally:
        env.close()
    (video,) = sorted(out.glob("eval/videos_step_2/*.mp4"))
    with av.open(str(video)) as container:
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    assert len(frames) == 6  # T + 1 observations
    height, width, _ = frames[0].shape
    assert height >= 256 and width == 2 * height
    k = height // SIZE
    expected = goal.repeat(k, 0).repeat(k, 1).astype(int)
    right = frames[-1][:, width // 2 :].astype(int)
    assert np.abs(right - expected).mean() < 3, np.abs(right - expected).mean()  # lossy H.264, same picture
    left = frames[-1][:, : width // 2].astype(int)
    assert np.abs(left - expected).mean() > np.abs(right - expected).mean()
