"""The installed distribution is discovered by LeRobot's own plugin mechanism, with no extra flags."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

BIN = Path(sys.executable).parent

DISCOVERY = """
import logging, sys
from lerobot.utils.import_utils import register_third_party_plugins
from lerobot.configs.policies import PreTrainedConfig
from lerobot.envs.configs import EnvConfig
assert "lerobot_indicator" not in sys.modules, "imported before discovery: test would prove nothing"
logging.basicConfig(level=logging.INFO)
register_third_party_plugins()
assert "lerobot_policy_indicator_ddpg" in sys.modules, "distribution was not imported by discovery"
print("POLICIES", sorted(PreTrainedConfig.get_known_choices()))
print("ENVS", sorted(EnvConfig.get_known_choices()))
"""


# torchcodec prints a traceback block when the machine has no FFmpeg shared libraries (LeRobot then falls
# back to PyAV). It is about the machine, not about plugins, so it is cut out before looking for errors.
TORCHCODEC_BLOCK = re.compile(
    r"\[start of libtorchcodec loading traceback\].*?\[end of libtorchcodec loading traceback\]", re.S
)


def _run(args: list[str], timeout: float = 300) -> subprocess.CompletedProcess:
    env = {**os.environ, "HF_HUB_OFFLINE": "1"}
    return subprocess.run(args, capture_output=True, text=True, timeout=timeout, env=env)


def test_distribution_name_is_importable_by_discovery():
    from importlib.metadata import distribution

    name = distribution("lerobot_policy_indicator_ddpg").metadata["Name"]
    # register_third_party_plugins() imports the *name* verbatim; hyphens would make it skip us.
    assert name == "lerobot_policy_indicator_ddpg"


def test_register_third_party_plugins_finds_our_types():
    proc = _run([sys.executable, "-c", DISCOVERY])
    assert proc.returncode == 0, proc.stderr
    assert "Could not import third-party plugin" not in proc.stderr, proc.stderr
    policies = next(line for line in proc.stdout.splitlines() if line.startswith("POLICIES"))
    envs = next(line for line in proc.stdout.splitlines() if line.startswith("ENVS"))
    assert "'indicator_ddpg'" in policies
    assert "'sawyer_reach'" in envs


@pytest.mark.parametrize("cli", ["lerobot-train", "lerobot-eval"])
def test_lerobot_cli_help_sees_plugin(cli: str):
    proc = _run([str(BIN / cli), "--help"])
    log = TORCHCODEC_BLOCK.sub("", proc.stdout + proc.stderr)
    assert proc.returncode == 0, log[-3000:]
    assert "Traceback" not in log and "Could not import third-party plugin" not in log, log[-3000:]
    assert "indicator_ddpg" in log
    if cli == "lerobot-eval":
        assert "sawyer_reach" in log
