"""Bad input to the CLIs ends in one line that names the field or key, not a generic parser error."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

BIN = Path(sys.executable).parent


@pytest.mark.parametrize(
    "cli",
    [
        ["lerobot-indicator-train", "--env.type=sawyer_reach"],
        ["lerobot-train", "--dataset.repo_id=user/none", "--policy.push_to_hub=false"],
    ],
)
def test_a_goal_key_as_observation_key_is_named(cli):
    cmd = [str(BIN / cli[0]), *cli[1:], "--policy.type=indicator_ddpg"]
    cmd.append("--policy.observation_keys=[observation.goal_state]")
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "MUJOCO_GL": "egl"}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode != 0
    assert "observation_keys: 'observation.goal_state' is a goal key" in proc.stdout + proc.stderr


def test_lerobot_train_prints_one_line_for_the_torchcodec_fallback_and_no_traceback():
    cmd = [str(BIN / "lerobot-train"), "--dataset.repo_id=user/none", "--policy.type=indicator_ddpg"]
    cmd.append("--policy.observation_keys=[observation.goal_state]")
    proc = subprocess.run(
        cmd, capture_output=True, text=True, timeout=300, env={**os.environ, "HF_HUB_OFFLINE": "1"}
    )
    out = proc.stdout + proc.stderr
    assert "libtorchcodec loading traceback" not in out and "Traceback" not in out, out[-3000:]


def test_an_rgbd_env_left_open_exits_without_renderer_tracebacks():
    code = (
        "import gymnasium as gym, lerobot_indicator\n"
        "env = gym.make('lerobot_indicator/SawyerReach-v0', obs_type='rgbd')\n"
        "env.reset(seed=0)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "MUJOCO_GL": "egl"})  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "Exception ignored" not in proc.stderr and "__del__" not in proc.stderr, proc.stderr[-2000:]


# ---------------- config errors of this package's dataclasses: one line in every CLI ----------------

CAMERA_WIDTH_0 = "env:\n  type: sawyer_reach\n  obs_type: rgb\n  camera:\n    width: 0\n"


def _in_process(monkeypatch, capsys, main, *args: str) -> tuple[int, list[str]]:
    """A CLI ``main`` run in this process (no interpreter start-up): its exit code and its stderr lines."""
    from lerobot_indicator.training import online

    monkeypatch.setattr(sys, "argv", ["cli", *args])
    monkeypatch.setattr(online, "init_logging", lambda: None)
    monkeypatch.setattr(online.signal, "signal", lambda *a: None)
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_info:
        main()
    return exit_info.value.code, capsys.readouterr().err.strip().splitlines()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--env.type=sawyer_reach", "--num_episodes=0"], "error: num_episodes must be > 0, got 0"),
        (
            ["--env.type=sawyer_reach", "--repo_id=../../escaped"],
            "error: repo_id='../../escaped' is not a Hub",
        ),
        (["--config_path={yaml}"], "error: camera.width must be > 0, got 0"),
    ],
)
def test_lerobot_indicator_record_config_errors_are_one_line(tmp_path, monkeypatch, capsys, args, message):
    from lerobot.utils.constants import HF_LEROBOT_HOME

    from lerobot_indicator.data import recorder

    yaml = tmp_path / "env.yaml"
    yaml.write_text(CAMERA_WIDTH_0)
    args = [a.format(yaml=yaml) for a in args]
    if not any(a.startswith("--repo_id") for a in args):
        args += ["--repo_id=test/x", f"--root={tmp_path / 'ds'}"]
    code, lines = _in_process(monkeypatch, capsys, recorder.main, *args)
    assert code == 1 and len(lines) == 1 and lines[0].startswith(message), lines
    assert not (tmp_path / "ds").exists() and not (HF_LEROBOT_HOME.parent.parent / "escaped").exists()


TRAIN = ["--policy.type=indicator_ddpg", "--policy.push_to_hub=false", "--policy.device=cpu"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--env.type=sawyer_reach", "--online.backend=mpi"], "error: --online.backend must be one of"),
        (["--env.type=sawyer_reach", "--record.repo_id=../x"], "error: --record.repo_id='../x' is not a Hub"),
        (["--env.type=sawyer_reach", "--resume=true"], "error: --resume=true but"),
        (["--config_path={yaml}"], "error: camera.width must be > 0, got 0"),
        (["--config_path={tmp}/none.yaml"], "error: --config_path="),
        # An env_configs/*.yaml as --config_path: the env comes from it, the rest from the command line.
        (["--config_path=env_configs/sawyer_reach_state_sim.yaml", "--online.backend=mpi"],
         "error: --online.backend must be one of"),
    ],
)  # fmt: skip
def test_lerobot_indicator_train_config_errors_are_one_line(tmp_path, monkeypatch, capsys, args, message):
    from lerobot_indicator.training import online

    yaml = tmp_path / "env.yaml"
    yaml.write_text(CAMERA_WIDTH_0)
    args = [a.format(yaml=yaml, tmp=tmp_path) for a in args]
    code, lines = _in_process(
        monkeypatch, capsys, online.main, *TRAIN, *args, f"--output_dir={tmp_path / 'run'}"
    )
    assert code == 1 and len(lines) == 1 and lines[0].startswith(message), lines
    assert not (tmp_path / "run").exists()


def test_config_path_takes_an_env_file_or_a_saved_train_config(tmp_path):
    import draccus

    from lerobot_indicator.training.config import OnlineTrainConfig

    cfg = OnlineTrainConfig.from_pretrained(
        "env_configs/sawyer_reach_state_sim.yaml", cli_args=[*TRAIN, "--steps=123"]
    )
    assert cfg.env.type == "sawyer_reach" and cfg.env.obs_type == "state" and cfg.steps == 123
    cfg = draccus.parse(OnlineTrainConfig, args=[*TRAIN, "--env.type=rope_push", "--steps=77", "--seed=5"])
    cfg._save_pretrained(tmp_path)
    again = OnlineTrainConfig.from_pretrained(tmp_path, cli_args=["--seed=6"])
    assert (again.env.type, again.steps, again.seed, again.policy.type) == (
        "rope_push",
        77,
        6,
        "indicator_ddpg",
    )


# ---------------- start-up checks of a policy's inputs against the env or dataset ----------------


def _image_policy_config(size: int):
    from lerobot.configs import FeatureType, PolicyFeature

    from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig

    img = PolicyFeature(type=FeatureType.VISUAL, shape=(3, size, size))
    cfg = IndicatorDDPGConfig(device="cpu", horizon=25, observation_keys=["observation.images.front"])
    cfg.input_features = {"observation.images.front": img, "observation.images.goal_front": img}
    cfg.output_features = {"action": PolicyFeature(type=FeatureType.ACTION, shape=(3,))}
    return cfg


@pytest.mark.parametrize(
    ("env_args", "fix"),
    [
        (["--env.obs_type=state"], "use --env.obs_type=rgb --env.camera.height=32 --env.camera.width=32"),
        (["--env.obs_type=rgb"], "use --env.camera.height=32 --env.camera.width=32"),
    ],
)
def test_a_pretrained_policy_for_other_observations_is_refused_at_start_with_the_fix(
    tmp_path, monkeypatch, capsys, env_args, fix
):
    from lerobot_indicator.training import online

    _image_policy_config(32).save_pretrained(tmp_path / "policy")
    args = [f"--policy.path={tmp_path / 'policy'}", "--policy.device=cpu", "--policy.push_to_hub=false",
            "--env.type=sawyer_reach", *env_args, f"--output_dir={tmp_path / 'run'}"]  # fmt: skip
    code, lines = _in_process(monkeypatch, capsys, online.main, *args)
    assert code == 1 and len(lines) == 1, lines
    assert "observation.images.front" in lines[0] and lines[0].endswith(fix), lines[0]
    assert not (tmp_path / "run").exists()  # refused before anything is built


def test_a_state_policy_comparing_a_key_the_env_has_no_goal_for_is_told_which_keys_it_can_compare():
    """Already obs_type=state, so "use --env.obs_type=state" would fix nothing: the hint names the keys the env
    gives goals for (a goal-free dataset's state keys are all compared unless --policy.observation_keys says)."""
    from lerobot.configs import FeatureType, PolicyFeature

    from lerobot_indicator.envs import SawyerReachEnvConfig
    from lerobot_indicator.policy.configuration_indicator_ddpg import IndicatorDDPGConfig
    from lerobot_indicator.policy.input_checks import PolicyInputError, check_env_for_policy

    vec = PolicyFeature(type=FeatureType.STATE, shape=(3,))
    keys = ["observation.state", "observation.environment_state"]
    cfg = IndicatorDDPGConfig(device="cpu", horizon=25, observation_keys=keys)
    cfg.input_features = {k: vec for k in keys} | {
        "observation.goal_state": vec,
        "observation.goal_environment_state": vec,
    }
    cfg.output_features = {"action": PolicyFeature(type=FeatureType.ACTION, shape=(3,))}
    with pytest.raises(PolicyInputError) as err:
        check_env_for_policy(cfg, SawyerReachEnvConfig(obs_type="state"))
    message = str(err.value)
    assert "observation.environment_state" in message and "--env.obs_type" not in message
    assert message.endswith(
        "the env gives goals only for ['observation.state']: train the policy with "
        "--policy.observation_keys=[observation.state]"
    ), message


def test_a_pretrained_policy_on_a_dataset_of_other_image_sizes_is_refused_when_made():
    """lerobot-train: make_policy gives the policy the dataset's metadata; a pretrained policy keeps its own
    input features, so the dataset's are checked against them."""
    from types import SimpleNamespace

    from lerobot_indicator.policy.input_checks import PolicyInputError
    from lerobot_indicator.policy.modeling_indicator_ddpg import IndicatorDDPGPolicy

    image = {"dtype": "image", "shape": (64, 64, 3), "names": ["height", "width", "channels"]}
    features = {"observation.images.front": image, "observation.images.goal_front": image}
    meta = SimpleNamespace(features=features, repo_id="user/reach_64px", episodes=None)
    with pytest.raises(PolicyInputError) as err:
        IndicatorDDPGPolicy(_image_policy_config(32), dataset_meta=meta)
    message = str(err.value)
    assert (
        "dataset user/reach_64px" in message
        and "observation.images.front (3, 32, 32) vs (3, 64, 64)" in message
    )
    meta.features = {k: {**v, "shape": (32, 32, 3)} for k, v in features.items()}
    IndicatorDDPGPolicy(_image_policy_config(32), dataset_meta=meta)  # the same sizes: made
