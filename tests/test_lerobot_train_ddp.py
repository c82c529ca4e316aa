"""``accelerate launch --multi_gpu --num_processes=2 lerobot-train --policy.type=indicator_ddpg`` on CPU (DDP
over gloo): both processes train, ``policy.update()`` moves the target networks of the unwrapped policy, and
the checkpoint loads in ``lerobot-eval --policy.path``.

``--multi_gpu`` with the policy on CPU: ``accelerate launch --cpu`` alone starts one process (its simple
launcher), so the 2-process CPU run goes through torchrun like a GPU one, and lerobot-train's
``Accelerator(cpu=True)`` picks gloo."""

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest
import torch
from safetensors.torch import load_file
from test_lerobot_train import REPO_ID, make_tiny_reach_dataset
from test_online_training import lerobot_eval

BIN = Path(sys.executable).parent


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def run_process_group(cmd: list[str], timeout: float, env: dict) -> tuple[int, str]:
    """Run ``cmd`` in its own session; on a timeout kill it and every process under it, ranks included (a
    rank may sit in a session of its own; left alive it keeps the log pipe open, so reading the log would
    wait forever). Raises ``TimeoutError`` with the log so far."""
    with subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, start_new_session=True
    ) as proc:
        try:
            log, _ = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            tree = psutil.Process(proc.pid).children(recursive=True)
            os.killpg(proc.pid, signal.SIGKILL)
            for child in tree:
                with contextlib.suppress(psutil.NoSuchProcess):
                    child.kill()
            log, _ = proc.communicate(timeout=60)
            raise TimeoutError(f"timed out after {timeout} s:\n{log[-6000:]}") from None
    return proc.returncode, log


def test_two_process_lerobot_train_trains_saves_and_evaluates(tmp_path: Path):
    data = make_tiny_reach_dataset(tmp_path / "tiny_reach")
    out = tmp_path / "run"
    env = {
        **os.environ,
        "HF_HUB_OFFLINE": "1",
        "CUDA_VISIBLE_DEVICES": "",
        "OMP_NUM_THREADS": "1",
        "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
    }
    cmd = [
        str(BIN / "accelerate"), "launch", "--multi_gpu", "--num_processes=2", "--num_machines=1",
        f"--main_process_port={free_port()}",
        "--mixed_precision=no", "--dynamo_backend=no", str(BIN / "lerobot-train"),
        "--policy.type=indicator_ddpg", f"--dataset.repo_id={REPO_ID}", f"--dataset.root={data}",
        "--policy.push_to_hub=false", "--policy.device=cpu", "--policy.horizon=6",
        "--policy.future_offsets=[2,3]", "--policy.hidden_dims=[16,16,16]", "--batch_size=4",
        "--num_workers=0", "--log_freq=1", "--save_freq=1", "--steps=3", "--wandb.enable=false",
        f"--output_dir={out}",
    ]  # fmt: skip
    try:
        returncode, log = run_process_group(cmd, timeout=300, env=env)
    except TimeoutError:  # a gloo rendezvous that never completes happens now and then here: one more launch
        returncode, log = run_process_group(
            [*cmd[:5], f"--main_process_port={free_port()}", *cmd[6:]], 300, env
        )
    assert returncode == 0, log[-6000:]
    assert "Effective batch size: 4 x 2 = 8" in log, log[-3000:]  # really two processes
    assert "step:3" in log and "critic_loss" in log, log[-3000:]

    def actors(step: int) -> tuple[dict, dict]:
        weights = load_file(out / "checkpoints" / f"{step:06d}" / "pretrained_model" / "model.safetensors")
        assert not any(k.startswith("module.") for k in weights)  # saved unwrapped, as lerobot-eval loads it
        pick = lambda prefix: {k[len(prefix) :]: v for k, v in weights.items() if k.startswith(prefix)}  # noqa: E731
        return pick("actor."), pick("target_actor.")

    (_, target_2), (online_3, target_3) = actors(2), actors(3)
    float_keys = [k for k, v in online_3.items() if v.is_floating_point() and not k.startswith("encoder.")]
    assert float_keys
    # Step 3's update() on the unwrapped policy: target <- tau * target + (1 - tau) * online, once per step.
    for k in float_keys:
        assert not torch.equal(target_3[k], target_2[k]), k
        torch.testing.assert_close(target_3[k], 0.98 * target_2[k] + 0.02 * online_3[k], rtol=1e-5, atol=1e-6)
    pretrained = out / "checkpoints" / "last" / "pretrained_model"

    info = lerobot_eval(
        pretrained, tmp_path / "eval", "--env.type=sawyer_reach", "--env.obs_type=state", "--env.episode_length=6",
        "--eval.n_episodes=1", env=env,
    )  # fmt: skip
    assert info["overall"]["n_episodes"] == 1


def test_loss_curve_benchmark_reads_lerobot_train_log_lines():
    from benchmarks.experiments.ddp_loss import parse_losses, window_means

    log = (
        "INFO ot_train.py:641 step:2 smpl:16 ep:2 epch:0.76 loss:7.938 grdn:2.835 lr:1.0e-03 updt_s:0.042 "
        "data_s:0.126 smp/s:47 critic_loss:2.010 actor_loss:5.928 q_mean:-5.922\n"
        "INFO ot_train.py:641 step:1 smpl:8 ep:1 epch:0.38 loss:9.473 grdn:4.797 lr:1.0e-03 updt_s:0.039 "
        "data_s:0.265 smp/s:26 critic_loss:3.482 actor_loss:5.991 q_mean:-5.966\n"
    )
    assert parse_losses(log) == {
        "step": [1, 2],
        "loss": [9.473, 7.938],
        "critic_loss": [3.482, 2.010],
        "actor_loss": [5.991, 5.928],
    }
    assert window_means([1.0, 3.0, 5.0, 7.0, 9.0], 2) == [2.0, 6.0]


def test_a_timed_out_launch_ends_even_when_a_rank_sits_in_its_own_session():
    """The launch hangs and its child (in a session of its own, as a rank can be) holds the log pipe: the
    timeout kills both and reports, instead of waiting for the pipe forever."""
    hang = (
        "import subprocess, sys, time; "
        "subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(120)'], start_new_session=True); "
        "print('started', flush=True); time.sleep(120)"
    )
    start = time.monotonic()
    with pytest.raises(TimeoutError, match="timed out after 2 s:\nstarted"):
        run_process_group([sys.executable, "-c", hang], timeout=2, env=dict(os.environ))
    assert time.monotonic() - start < 60
