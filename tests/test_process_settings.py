"""lerobot-indicator-train's process settings (``--cpu_threads``, ``--keep_freed_memory``,
``--video_decoder_threads``): parsed, checked and applied by the CLI once its trainer is built, and never by
the policy (tests/test_policy.py, tests/test_video_decoder_threads.py)."""

from types import SimpleNamespace

import draccus
import pytest

from lerobot_indicator import process
from lerobot_indicator.training import online
from lerobot_indicator.training.config import OnlineTrainConfig

ARGS = [
    "--env.type=sawyer_reach",
    "--env.obs_type=state",
    "--policy.type=indicator_ddpg",
    "--policy.device=cpu",
    "--policy.push_to_hub=false",
]


def parse(tmp_path, *args: str) -> OnlineTrainConfig:
    return draccus.parse(OnlineTrainConfig, args=[*ARGS, f"--output_dir={tmp_path / 'run'}", *args])


def test_defaults_and_flags(tmp_path):
    cfg = parse(tmp_path)
    assert (cfg.cpu_threads, cfg.keep_freed_memory, cfg.video_decoder_threads) == (1, True, 1)
    cfg = parse(tmp_path, "--cpu_threads=2", "--keep_freed_memory=false", "--video_decoder_threads=null")
    assert (cfg.cpu_threads, cfg.keep_freed_memory, cfg.video_decoder_threads) == (2, False, None)


@pytest.mark.parametrize("flag", ["cpu_threads", "video_decoder_threads"])
def test_a_bad_count_names_the_flag(tmp_path, flag):
    cfg = parse(tmp_path, f"--{flag}=0")
    with pytest.raises(ValueError, match=rf"--{flag} must be null \(the library's choice\) or >= 1, got 0"):
        cfg.validate()


def test_train_applies_the_settings_after_building_the_trainer(tmp_path, monkeypatch):
    events = []

    class Trainer:
        def __init__(self, cfg):
            events.append("built")

        def train(self):
            events.append("trained")
            return {}

        def close(self):
            pass

    monkeypatch.setattr(online, "OnlineTrainer", Trainer)
    monkeypatch.setattr(process, "apply", lambda *settings: events.append(settings))
    online.train(parse(tmp_path, "--cpu_threads=2", "--keep_freed_memory=false"))
    assert events == ["built", (2, False, 1), "trained"]


def test_torch_threads_are_set_only_for_a_policy_on_cpu(monkeypatch):
    applied = []
    monkeypatch.setattr(process, "apply", lambda *settings: applied.append(settings))
    for device in ("cpu", "cuda"):
        cfg = SimpleNamespace(
            policy=SimpleNamespace(device=device),
            cpu_threads=1,
            keep_freed_memory=True,
            video_decoder_threads=1,
        )
        online.apply_process_settings(cfg)
    assert applied == [(1, True, 1), (None, True, 1)]


def test_environment_gives_each_setting_its_variables():
    assert process.environment() == {
        "OMP_NUM_THREADS": "1",
        "MALLOC_MMAP_MAX_": "0",
        "MALLOC_TRIM_THRESHOLD_": "2147483647",
        "LEROBOT_INDICATOR_VIDEO_DECODER_THREADS": "1",
    }
    assert process.environment(cpu_threads=None, keep_freed=False, video_decoder_threads=None) == {}
