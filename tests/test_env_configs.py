"""env_configs/*.yaml load, validate and round-trip; bad configs fail naming the field."""

from pathlib import Path

import pytest

from lerobot_indicator.envs import GoalEnvConfig, SawyerReachEnvConfig
from lerobot_indicator.envs.configs import load_env_config, save_env_config
from lerobot_indicator.envs.hardware import EndEffectorConfig, GoalCameraConfig

CONFIG_DIR = Path(__file__).resolve().parents[1] / "env_configs"
CONFIG_FILES = sorted(CONFIG_DIR.glob("*.yaml"))


def test_config_dir_has_the_documented_files():
    names = {p.stem for p in CONFIG_FILES}
    assert {"sawyer_reach_sim", "sawyer_reach_real_d435", "sawyer_reach_state_sim"} <= names


@pytest.mark.parametrize("path", CONFIG_FILES, ids=lambda p: p.stem)
def test_config_files_load_and_round_trip(path, tmp_path):
    cfg = load_env_config(path)
    assert isinstance(cfg, GoalEnvConfig)
    out = tmp_path / "round_trip.yaml"
    save_env_config(cfg, out)
    again = load_env_config(out)
    assert again == cfg
    assert again.features == cfg.features and again.features_map == cfg.features_map


def test_real_d435_config_maps_to_lerobot_realsense_config():
    cfg = load_env_config(CONFIG_DIR / "sawyer_reach_real_d435.yaml")
    rs = cfg.camera.to_lerobot_camera_config()
    assert (rs.width, rs.height, rs.fps, rs.use_depth) == (424, 240, 30, True)
    assert cfg.epsilon == 0.1 and cfg.end_effector.max_ee_step_m == 0.05


def test_sim_fields_reach_the_env_kwargs():
    cfg = load_env_config(CONFIG_DIR / "sawyer_reach_sim.yaml")
    kwargs = cfg.gym_kwargs
    assert kwargs["camera"].width == 100 and kwargs["camera"].fovy_deg == 58.0
    assert kwargs["end_effector"].end_effector_bounds["max"] == [0.3, 0.3, 1.25]
    assert kwargs["max_episode_steps"] == 25 and kwargs["epsilon"] == 0.05


BAD_CONFIGS = {
    "unknown key": ("  bogus: 1\n", "bogus"),
    "unknown camera type": ("  camera: {type: kinect}\n", "camera.type"),
    "zero resolution": ("  camera: {width: 0}\n", "camera.width"),
    "misspelt camera field": ("  camera: {widht: 64}\n", "widht"),
    "inverted bounds": (
        "  end_effector: {end_effector_bounds: {min: [0.3, -0.3, 0.85], max: [0.2, 0.3, 1.25]}}\n",
        "end_effector_bounds",
    ),
    "zero step size": (
        "  end_effector: {end_effector_step_sizes: {x: 0.0, y: 0.05, z: 0.05}}\n",
        "step_sizes.x",
    ),
    "step above max": (
        "  end_effector: {end_effector_step_sizes: {x: 0.1, y: 0.05, z: 0.05}}\n",
        "step_sizes.x",
    ),
    "bad depth range": ("  camera: {depth_min_m: 2.0, depth_max_m: 1.0}\n", "depth_m"),
    "unknown obs type": ("  obs_type: lidar\n", "obs_type"),
    "realsense without serial": ("  camera: {type: intelrealsense}\n", "serial_number_or_name"),
}


@pytest.mark.parametrize("name", sorted(BAD_CONFIGS))
def test_bad_config_fails_at_load_naming_the_field(name, tmp_path):
    body, field_name = BAD_CONFIGS[name]
    path = tmp_path / "bad.yaml"
    path.write_text("env:\n  type: sawyer_reach\n" + body)
    with pytest.raises(ValueError, match=field_name.replace(".", r"\.")):
        load_env_config(path)


def test_dataclass_validation_without_yaml():
    with pytest.raises(ValueError, match="camera.height"):
        GoalCameraConfig(height=-1)
    with pytest.raises(ValueError, match="min z"):
        EndEffectorConfig(end_effector_bounds={"min": [0, 0, 1.0], "max": [0.1, 0.1, 0.9]})
    with pytest.raises(ValueError, match="epsilon"):
        SawyerReachEnvConfig(epsilon=-1.0)


def test_package_import_needs_neither_robosuite_nor_mujoco():
    """Every LeRobot CLI imports the plugin: it must work (and stay light) without robosuite."""
    import subprocess
    import sys

    code = (
        "import sys; sys.modules['robosuite'] = None\n"
        "import lerobot_indicator\n"
        "from lerobot.envs.factory import make_env_config\n"
        "cfg = make_env_config('sawyer_reach', obs_type='rgbd')\n"
        "assert 'mujoco' not in sys.modules, 'mujoco imported at package import'\n"
        "from lerobot_indicator.envs.sawyer_reach import SawyerReachEnv\n"
        "try:\n"
        "    SawyerReachEnv()\n"
        "except ImportError as err:\n"
        "    print(err)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "pip install --no-deps robosuite==1.5.2" in out.stdout
