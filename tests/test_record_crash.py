"""The recorder CLI interrupted (SIGINT, SIGTERM, SIGKILL) at chosen points: inside ``save_episode``,
inside the commit of a saved episode, inside the final ``finalize``, while stepping an episode.

A child process runs ``lerobot_indicator.data.recorder``'s CLI with a hook that, on the n-th call of
the chosen function, writes a marker file and sleeps; the test sends the signal once the marker is
there, so the signal lands inside that call. Then: how many complete episodes ``LeRobotDataset``
reads, as the dataset is and after ``--resume``.
"""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
import torch
from huggingface_hub import constants as hf_constants
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from lerobot_indicator.data.recorder import RecordConfig, record
from lerobot_indicator.envs import SawyerReachEnvConfig

T = 3  # steps per episode
F = T + 1  # frames per episode
REPO_ID = "test/crash"

CHILD = textwrap.dedent(
    """
    import os, sys, time
    from pathlib import Path

    from lerobot.datasets.dataset_metadata import LeRobotDatasetMetadata
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from lerobot_indicator.data import checkpoint, recorder

    target, nth = os.environ["HOOK"].split(":")
    owner, name = {
        "save_episode": (LeRobotDatasetMetadata, "save_episode"),  # inside LeRobot's save_episode
        "commit": (checkpoint, "_replace_meta"),  # new files linked in, info.json not yet replaced
        "finalize": (LeRobotDataset, "finalize"),
        "step": (recorder.EpisodeStepper, "step"),
    }[target]
    real, calls = getattr(owner, name), [0]

    def hooked(*args, **kwargs):
        calls[0] += 1
        if calls[0] == int(nth):
            Path(os.environ["MARKER"]).write_text("reached")
            time.sleep(float(os.environ["WAIT_S"]))
        return real(*args, **kwargs)

    setattr(owner, name, hooked)
    sys.argv = ["lerobot-indicator-record", *sys.argv[1:]]
    recorder.main()
    """
)


@pytest.fixture(autouse=True)
def _offline(monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setattr(hf_constants, "HF_HUB_OFFLINE", True)


def interrupt(tmp_path: Path, hook: str, sig: int, num_episodes: int, obs_type: str = "state"):
    """Run the CLI until ``hook`` is reached, send ``sig`` there; returns (exit code, stderr)."""
    child, marker, err = tmp_path / "child.py", tmp_path / "marker", tmp_path / "stderr.txt"
    child.write_text(CHILD)
    args = [
        "--env.type=sawyer_reach",
        f"--env.obs_type={obs_type}",
        f"--env.episode_length={T}",
        "--env.camera.width=32",
        "--env.camera.height=32",
        "--policy=noisy_scripted",
        f"--num_episodes={num_episodes}",
        f"--repo_id={REPO_ID}",
        f"--root={tmp_path / 'ds'}",
    ]
    # The sleep ends early when the signal kills the child or interrupts the call; a deferred signal
    # (inside save_episode, a commit, the final finalize) lets the call sleep on, then finish.
    deferred = sig != signal.SIGKILL and not hook.startswith("step")
    env = {**os.environ, "HOOK": hook, "MARKER": str(marker), "WAIT_S": "3" if deferred else "120"}
    with err.open("w") as stderr:
        proc = subprocess.Popen(
            [sys.executable, str(child), *args], env=env, stdout=subprocess.DEVNULL, stderr=stderr
        )
        try:
            deadline = time.monotonic() + 180
            while not marker.exists():
                assert proc.poll() is None, f"recorder exited before {hook}: {err.read_text()[-3000:]}"
                assert time.monotonic() < deadline, f"recorder never reached {hook}"
                time.sleep(0.02)
            proc.send_signal(sig)
            code = proc.wait(timeout=180)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    return code, err.read_text()


def readable_episodes(root: Path) -> tuple[int, list[torch.Tensor]]:
    """Complete episodes LeRobotDataset reads at ``root`` (each checked frame by frame), and the actions."""
    ds = LeRobotDataset(REPO_ID, root=root, video_backend="pyav")
    items = [ds[i] for i in range(len(ds))]
    assert len(items) == ds.num_episodes * F
    assert [int(item["episode_index"]) for item in items] == [i // F for i in range(len(items))]
    assert [int(item["frame_index"]) for item in items] == [i % F for i in range(len(items))]
    return ds.num_episodes, [item["action"] for item in items]


def resume(root: Path, num_episodes: int = 1, obs_type: str = "state") -> None:
    cfg = RecordConfig(
        env=SawyerReachEnvConfig(obs_type=obs_type, episode_length=T, camera={"width": 32, "height": 32}),
        repo_id=REPO_ID,
        root=root,
        policy="noisy_scripted",
        num_episodes=num_episodes,
        resume=True,
    )
    record(cfg)


def assert_one_line_exit(code: int, stderr: str, sig: int, episodes: int) -> None:
    assert code == 128 + sig
    assert "Traceback" not in stderr
    lines = [
        line
        for line in stderr.splitlines()
        if line.startswith(f"{signal.Signals(sig).name}: recording stopped")
    ]
    assert len(lines) == 1, stderr[-3000:]
    assert f"{episodes} complete episodes" in lines[0]


@pytest.mark.parametrize(
    ("hook", "sig", "kept"),
    [
        # SIGINT/SIGTERM while an episode is saved or committed: that episode is finished and kept.
        ("save_episode:3", signal.SIGINT, 3),
        ("commit:3", signal.SIGTERM, 3),
        # SIGTERM while an episode is stepped: that episode (in flight) is dropped.
        ("step:8", signal.SIGTERM, 2),
    ],
)
def test_signal_keeps_every_saved_episode_and_says_so_in_one_line(tmp_path, hook, sig, kept):
    code, stderr = interrupt(tmp_path, hook, sig, num_episodes=5)
    assert_one_line_exit(code, stderr, sig, kept)
    assert f"--resume=true --num_episodes={5 - kept}" in stderr
    assert ("episode 2, being recorded, was dropped" in stderr) == (hook.startswith("step"))
    root = tmp_path / "ds"
    assert not (root / ".recording").exists()  # nothing left to recover
    count, actions = readable_episodes(root)
    assert count == kept
    resume(root)
    count, after = readable_episodes(root)
    assert count == kept + 1 and all(torch.equal(a, b) for a, b in zip(actions, after, strict=False))


@pytest.mark.parametrize(
    ("hook", "obs_type", "readable", "resumed"),
    [
        # Killed inside LeRobot's save_episode: the episode in flight is lost, the others load as they are.
        ("save_episode:3", "rgb", 2, 2),
        # Killed between linking an episode's files and replacing info.json: the dataset still reads as the
        # previous state; --resume finishes that commit (nothing is rolled back).
        ("commit:3", "state", 2, 3),
        # Killed while stepping an episode.
        ("step:8", "state", 2, 2),
    ],
)
def test_sigkill_loses_at_most_the_episode_in_flight(tmp_path, hook, obs_type, readable, resumed):
    code, _ = interrupt(tmp_path, hook, signal.SIGKILL, num_episodes=5, obs_type=obs_type)
    assert code == -signal.SIGKILL
    root = tmp_path / "ds"
    count, actions = readable_episodes(root)  # no --resume, no recovery step
    assert count == readable
    resume(root, obs_type=obs_type)
    count, after = readable_episodes(root)
    assert count == resumed + 1
    assert all(torch.equal(a, b) for a, b in zip(actions, after, strict=False))
    assert not (root / ".recording").exists()
    assert not list(root.glob("images/**/*.png"))


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT])
def test_interrupted_final_finalize_keeps_every_episode(tmp_path, sig):
    code, stderr = interrupt(tmp_path, "finalize:1", sig, num_episodes=3)
    if sig == signal.SIGKILL:
        assert code == -signal.SIGKILL
    else:
        assert_one_line_exit(code, stderr, sig, 3)
        assert "All 3 requested episodes are there." in stderr
    count, _ = readable_episodes(tmp_path / "ds")
    assert count == 3
