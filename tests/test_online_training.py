"""Online trainer end to end at tiny sizes: checkpoints in lerobot-train's layout, lerobot-eval loads
them, and --resume continues bit for bit."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from lerobot_indicator.keys import goal_key, is_goal_key

BIN = Path(sys.executable).parent
TINY = [
    "--policy.type=indicator_ddpg",
    "--policy.push_to_hub=false",
    "--policy.device=cpu",
    "--online.n_envs=1",
    "--online.use_async_envs=false",
    "--online.episodes_per_cycle=1",
    "--online.updates_per_cycle=5",
    "--online.batch_size=16",
    "--online.eval_episodes=1",
    "--env_eval_freq=10",
    "--save_freq=10",
    "--seed=7",
]
ENVS = {
    "sawyer_reach": ["--env.type=sawyer_reach", "--env.obs_type=state", "--env.episode_length=5"],
    "rope_push": ["--env.type=rope_push", "--env.obs_type=state"],
}
POLICY_KEYS = {"sawyer_reach": [], "rope_push": ["--policy.observation_keys=[observation.rope_xy]"]}


def _env() -> dict[str, str]:
    return {**os.environ, "HF_HUB_OFFLINE": "1", "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}


def _train(out: Path, *args: str) -> subprocess.CompletedProcess:
    cmd = [str(BIN / "lerobot-indicator-train"), *TINY, f"--output_dir={out}", *args]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=_env())
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]
    return proc


def lerobot_eval(pretrained: Path, eval_dir: Path, *args: str, env: dict[str, str] | None = None) -> dict:
    """``lerobot-eval`` of a saved policy (CPU, one env at a time); its ``eval_info.json``."""
    cmd = [str(BIN / "lerobot-eval"), f"--policy.path={pretrained}", "--policy.device=cpu", "--eval.batch_size=1",
           f"--output_dir={eval_dir}", *args]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env or _env())
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-6000:]
    return json.loads((eval_dir / "eval_info.json").read_text())


def _metrics(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]


@pytest.mark.parametrize("env_type", sorted(ENVS))
def test_online_run_checkpoint_loads_in_lerobot_eval(tmp_path, env_type):
    out = tmp_path / "run"
    _train(out, *ENVS[env_type], *POLICY_KEYS[env_type], "--steps=10")
    rows = _metrics(out)
    horizon = 5 if env_type == "sawyer_reach" else 3
    assert [r["cycle"] for r in rows] == [0, 1]
    assert rows[-1]["step"] == 10 and rows[-1]["env_steps"] == 2 * horizon
    for key in ("critic_loss", "actor_loss", "q_mean", "frac_positive", "frac_filtered", "reward_accuracy"):
        assert key in rows[-1], key
    assert "eval_success_rate" in rows[-1] and "eval_final_distance" in rows[-1]
    assert (out / "learning_curve.png").stat().st_size > 0
    pretrained = out / "checkpoints" / "last" / "pretrained_model"
    for name in ("config.json", "model.safetensors", "train_config.json"):
        assert (pretrained / name).exists(), name
    assert (out / "checkpoints" / "000010" / "training_state" / "training_step.json").exists()
    _assert_input_stats_cover_every_cycle(out, pretrained)

    overall = lerobot_eval(
        pretrained,
        tmp_path / "eval",
        *ENVS[env_type],
        "--env.eval_reward=final_distance",
        "--eval.n_episodes=2",
    )["overall"]
    assert 0.0 <= overall["pc_success"] <= 100.0
    mean_final_distance = -overall["avg_sum_reward"]  # eval_reward=final_distance
    assert 0.0 < mean_final_distance < 1.0


def _assert_input_stats_cover_every_cycle(out: Path, pretrained: Path) -> None:
    """The saved normalisation is the running one: mean/std over both cycles' frames and goals."""
    from safetensors.torch import load_file

    chunks = [dict(np.load(f)) for f in sorted((out / "replay").glob("cycle_*.npz"))]
    assert len(chunks) == 2
    (obs_key,) = [k for k in chunks[0] if k.startswith("obs/") and not is_goal_key(k)]
    goal = f"obs/{goal_key(obs_key[4:])}"
    frames = np.concatenate([np.concatenate([c[obs_key], c[goal][:, :1]], axis=1) for c in chunks])
    frames = frames.reshape(-1, frames.shape[-1])
    weights = load_file(pretrained / "model.safetensors")
    for net in ("actor", "critic", "target_actor", "target_critic"):
        np.testing.assert_allclose(weights[f"{net}.encoder.mean_0"], frames.mean(0), rtol=1e-5, atol=1e-6)
        std = np.maximum(frames.std(0), 1e-2)  # the encoder's floor for constant dimensions
        np.testing.assert_allclose(weights[f"{net}.encoder.std_0"], std, rtol=1e-4, atol=1e-6)


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory) -> list[dict]:
    """The metrics of a 20-step run on the state Sawyer reach, the reference of the resume tests."""
    full = tmp_path_factory.mktemp("uninterrupted") / "run"
    _train(full, *ENVS["sawyer_reach"], "--steps=20")
    return _metrics(full)


def test_resume_continues_bit_for_bit(tmp_path, uninterrupted):
    env_args = ENVS["sawyer_reach"]
    split = tmp_path / "split"
    _train(split, *env_args, "--steps=10")  # "killed" after two cycles
    _train(split, *env_args, "--steps=20", "--resume=true")
    a, b = uninterrupted, _metrics(split)
    assert [r["step"] for r in b] == [5, 10, 15, 20], "resume must continue the step counter"
    for ra, rb in zip(a, b, strict=True):
        for key in ("critic_loss", "actor_loss", "q_mean", "train_final_distance"):
            assert ra[key] == rb[key], (ra["cycle"], key, ra[key], rb[key])


def test_resume_before_the_first_checkpoint_continues_bit_for_bit(tmp_path, uninterrupted):
    """A run stopped before its first LeRobot checkpoint has only its per-cycle resume state; --resume
    continues from it (the same command plus --resume=true)."""
    env_args = ENVS["sawyer_reach"]
    split = tmp_path / "split"
    _train(split, *env_args, "--steps=10", "--save_checkpoint=false")
    assert not (split / "checkpoints").exists() and (split / "resume").is_dir()
    _train(split, *env_args, "--steps=20", "--resume=true")
    for ra, rb in zip(uninterrupted, _metrics(split), strict=True):
        assert ra["critic_loss"] == rb["critic_loss"] and ra["q_mean"] == rb["q_mean"], ra["cycle"]


def test_resume_without_a_resume_state_says_what_the_directory_holds(tmp_path):
    out = tmp_path / "run"
    (out / "checkpoints").mkdir(parents=True)
    cmd = [str(BIN / "lerobot-indicator-train"), *TINY, *ENVS["sawyer_reach"], f"--output_dir={out}"]
    proc = subprocess.run([*cmd, "--resume=true"], capture_output=True, text=True, timeout=300, env=_env())
    assert proc.returncode != 0
    assert "has no resume state (resume/); it holds ['checkpoints']" in proc.stderr


def test_refuses_to_overwrite_a_run(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "something").write_text("precious")
    cmd = [
        str(BIN / "lerobot-indicator-train"),
        *TINY,
        *ENVS["sawyer_reach"],
        f"--output_dir={out}",
        "--steps=10",
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode != 0
    assert "already exists" in proc.stderr
    assert (out / "something").read_text() == "precious"


def test_online_rollouts_are_recorded_as_a_lerobot_dataset(tmp_path, monkeypatch):
    from lerobot.datasets import LeRobotDataset

    root = tmp_path / "rollouts"
    args = [
        *ENVS["sawyer_reach"],
        "--steps=10",
        "--record.repo_id=local/online_rollouts",
        f"--record.root={root}",
    ]
    _train(tmp_path / "run", *args)
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    ds = LeRobotDataset("local/online_rollouts", root=root, video_backend="pyav")
    horizon = 5
    assert ds.num_episodes == 2 and len(ds) == 2 * (horizon + 1)  # one episode per cycle, o_0..o_T
    first, last = ds[0], ds[horizon]
    assert {"observation.state", "observation.goal_state", "observation.gt_distance", "next.reward"} <= set(
        first
    )
    assert torch.equal(first["observation.goal_state"], last["observation.goal_state"])
    # Frame t's next.reward is the indicator reward of o_{t+1} against the recorded goal.
    for t in range(horizon):
        hit = torch.equal(ds[t + 1]["observation.state"], ds[t]["observation.goal_state"])
        assert ds[t]["next.reward"].item() == (1.0 if hit else -1.0)


KILLED_AT_CALL = """
import importlib, os, signal, sys
from lerobot_indicator.training import online

# KILL_AT = module:Class.method:N raises KeyboardInterrupt at the N-th call of that method, or with
# KILL_WITH=SIGTERM sends this process SIGTERM there.
module, method, call_index = os.environ["KILL_AT"].split(":")
owner_name, method = method.split(".")
owner = getattr(importlib.import_module(module), owner_name)
original, calls = getattr(owner, method), []


def killed(self, *args):
    calls.append(1)
    if len(calls) == int(call_index):
        if os.environ.get("KILL_WITH") == "SIGTERM":
            os.kill(os.getpid(), signal.SIGTERM)
        raise KeyboardInterrupt
    return original(self, *args)


setattr(owner, method, killed)
sys.argv = ["lerobot-indicator-train", *sys.argv[1:]]
online.main()
"""


def _record_args(root: Path, name: str) -> list[str]:
    return [
        *ENVS["sawyer_reach"],
        f"--record.repo_id=local/{name}",
        f"--record.root={root / f'{name}_dataset'}",
    ]


@pytest.fixture(scope="module")
def uninterrupted_recording(tmp_path_factory) -> Path:
    """The dataset a 15-step --record run on the state Sawyer reach records (repo ``local/full``), the
    reference of the interrupted recordings."""
    root = tmp_path_factory.mktemp("uninterrupted_recording")
    _train(root / "full", *_record_args(root, "full"), "--steps=15")
    return root / "full_dataset"


@pytest.mark.parametrize(
    ("kill_at", "kill_with", "exit_code"),
    [
        # Cycle 1's episodes are recorded (each committed as it is saved), its resume state is not saved: the
        # resumed run replays cycle 1 and must skip the episode the dataset already has.
        ("lerobot_indicator.training.run_state:RunDir.save_state:2", "Ctrl-C", 130),
        # SIGTERM while training cycle 2, after its episode was recorded: the resumed run replays cycle 2
        # from the resume state of cycle 1 and records its episode once.
        ("lerobot_indicator.training.online:OnlineTrainer.optimise:3", "SIGTERM", 143),
    ],
)
def test_resumed_recording_has_each_episode_once(
    tmp_path, monkeypatch, kill_at, kill_with, exit_code, uninterrupted_recording
):
    """A run stopped by Ctrl-C or SIGTERM with --record and resumed ends with the same dataset as an
    uninterrupted run; it stops with the shell's exit code for that signal and one line saying how to go on."""
    from lerobot.datasets import LeRobotDataset

    split = [f"--output_dir={tmp_path / 'split'}", *TINY, *_record_args(tmp_path, "split"), "--steps=15"]
    proc = subprocess.run(
        [sys.executable, "-c", KILLED_AT_CALL, *split],
        capture_output=True,
        text=True,
        env={**_env(), "KILL_AT": kill_at, "KILL_WITH": kill_with},
    )
    assert proc.returncode == exit_code, proc.stderr[-2000:]
    last_lines = proc.stderr.strip().splitlines()[-1]
    assert "interrupted: the run continues from its resume/ state" in last_lines, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    _train(tmp_path / "split", *_record_args(tmp_path, "split"), "--steps=15", "--resume=true")
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    full = LeRobotDataset("local/full", root=uninterrupted_recording, video_backend="pyav")
    split_ds = LeRobotDataset("local/split", root=tmp_path / "split_dataset", video_backend="pyav")
    assert full.num_episodes == split_ds.num_episodes == 3
    assert len(full) == len(split_ds)
    for i in range(len(full)):
        a, b = full[i], split_ds[i]
        for key in ("action", "observation.state", "observation.goal_state", "episode_index"):
            assert torch.equal(a[key], b[key]), (i, key)
    assert not (tmp_path / "split_dataset" / ".recording").exists()  # no journal after a clean finish


@pytest.mark.parametrize(
    ("arg", "message"),
    [
        ("--online.input_stats=frozen", "--online.input_stats must be one of"),
        ("--online.episodes_per_cycle=0", "--online.episodes_per_cycle must be >= 1"),
        ("--online.backend=mpi", "--online.backend must be one of \\('local', 'ray'\\), got 'mpi'"),
        ("--online.num_workers=0", "--online.num_workers must be >= 1, got 0"),
    ],
)
def test_config_errors_name_the_bad_option(tmp_path, arg, message):
    import draccus

    from lerobot_indicator.training.config import OnlineTrainConfig

    cfg = draccus.parse(
        OnlineTrainConfig, args=[*TINY, *ENVS["sawyer_reach"], f"--output_dir={tmp_path}", arg]
    )
    with pytest.raises(ValueError, match=message):
        cfg.validate()


def test_wandb_offline_run_holds_the_logged_metrics(tmp_path):
    out = tmp_path / "run"
    _train(
        out, *ENVS["sawyer_reach"], "--steps=10", "--wandb.enable=true", "--wandb.mode=offline",
        "--wandb.project=indicator-test", "--wandb.disable_artifact=true",
    )  # fmt: skip
    runs = list((out / "wandb").glob("offline-run-*/run-*.wandb"))
    assert len(runs) == 1, list((out / "wandb").iterdir())
    logged = _wandb_history(runs[0])
    last = _metrics(out)[-1]
    assert logged["train/critic_loss"] == pytest.approx(last["critic_loss"])
    assert logged["eval/eval_success_rate"] == pytest.approx(last["eval_success_rate"])
    assert logged["train/learning_curve/_type"] == "image-file"


def _wandb_history(path: Path) -> dict:
    """The last logged value of every key in an offline wandb run file (its protobuf records)."""
    from wandb.proto import wandb_internal_pb2
    from wandb.sdk.internal.datastore import DataStore

    store, values = DataStore(), {}
    store.open_for_scan(str(path))
    while (data := store.scan_data()) is not None:
        record = wandb_internal_pb2.Record()
        record.ParseFromString(data)
        if record.WhichOneof("record_type") == "history":
            for item in record.history.item:
                values[item.key or "/".join(item.nested_key)] = json.loads(item.value_json)
    return values


def test_record_flags_parse(tmp_path):
    import draccus

    from lerobot_indicator.training.config import OnlineRecordConfig, OnlineTrainConfig

    record = [
        "--record.repo_id=local/x",
        f"--record.root={tmp_path / 'ds'}",
        "--record.push_to_hub=true",
    ]
    cfg = draccus.parse(
        OnlineTrainConfig, args=[*TINY, *ENVS["sawyer_reach"], f"--output_dir={tmp_path / 'run'}", *record]
    )
    cfg.validate()
    assert cfg.record == OnlineRecordConfig("local/x", str(tmp_path / "ds"), True)


def test_hooks_see_every_phase_with_its_result(tmp_path):
    """Hooks get each cycle's phases in loop order, with what the phase produced and its duration."""
    import draccus

    from lerobot_indicator.training.config import OnlineTrainConfig
    from lerobot_indicator.training.hooks import TrainerHooks
    from lerobot_indicator.training.online import OnlineTrainer

    cfg = draccus.parse(
        OnlineTrainConfig,
        args=[*TINY, *ENVS["sawyer_reach"], f"--output_dir={tmp_path}", "--steps=10", "--env_eval_freq=10"],
    )
    cfg.validate()
    events = []

    def hook(name):
        return lambda *args: events.append((name, *args))

    hooks = TrainerHooks(**{n: hook(n) for n in TrainerHooks.__dataclass_fields__})
    trainer = OnlineTrainer(cfg, hooks)
    try:
        trainer.train()
    finally:
        trainer.close()
    names = [e[0] for e in events]
    cycle = ["on_cycle_start", "on_collect_end", "on_update_end"]
    assert names == [*cycle, "on_cycle_end", *cycle, "on_eval_end", "on_cycle_end"]
    rows = _metrics(tmp_path)
    ends = [e for e in events if e[0] == "on_cycle_end"]
    assert [e[2] for e in ends] == rows  # the metrics.jsonl lines, as written
    updates = [e for e in events if e[0] == "on_update_end"]
    assert [u[1].step for u in updates] == [5, 10]
    assert [u[2]["critic_loss"] for u in updates] == [r["critic_loss"] for r in rows]
    (collect,) = [e for e in events if e[0] == "on_collect_end" and e[1].cycle == 1]
    assert collect[2][0].actions.shape == (1, 5, 3)  # one episode of T = 5
    (evaluation,) = [e for e in events if e[0] == "on_eval_end"]
    assert evaluation[2]["eval_success_rate"] == rows[-1]["eval_success_rate"]
    for _, phase, *_ in (e for e in events if e[0] != "on_cycle_start"):
        assert phase.seconds > 0
    phases = sum(e[1].seconds for e in events if e[0] in ("on_collect_end", "on_update_end", "on_eval_end"))
    assert phases < sum(e[1].seconds for e in ends)


def test_constant_critic_warning_fires_once_below_the_threshold(caplog):
    """A cycle whose mean Q std over the batch is below CONSTANT_Q_STD logs one warning naming the fix; a
    varying critic, a stats dict without q_std and a second constant cycle log nothing."""
    import logging
    from types import SimpleNamespace

    from lerobot_indicator.training.online import CONSTANT_Q_STD, OnlineTrainer

    def trainer(scale: str) -> SimpleNamespace:
        config = SimpleNamespace(critic_output_scale=scale)
        return SimpleNamespace(
            _warned_constant_critic=False,
            progress=SimpleNamespace(step=700),
            policy=SimpleNamespace(config=config),
        )

    warn = OnlineTrainer._warn_if_critic_is_constant
    paper = trainer("paper")
    with caplog.at_level(logging.WARNING):
        warn(paper, {"q_mean": 1.8, "q_std": CONSTANT_Q_STD})
        warn(paper, {"q_mean": 1.8})
        assert not caplog.records
        warn(paper, {"q_mean": 1.8, "q_std": 2e-6})
        warn(paper, {"q_mean": 1.8, "q_std": 1e-6})
    assert len(caplog.records) == 1
    assert "step 700" in caplog.text and "--policy.critic_output_scale=return" in caplog.text
    # Already return-scaled: the advice is not the setting in use.
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        warn(trainer("return"), {"q_mean": 1.8, "q_std": 1e-6})
    assert "already return-scaled" in caplog.text and "rerun with" not in caplog.text


def test_sigterm_with_env_worker_processes_stops_cleanly(tmp_path):
    """SIGTERM with async env workers: one closing line, exit 143, no traceback (the workers are closed,
    not left to fail on a dead pipe), and the resume state is there."""
    out = tmp_path / "run"
    args = [a for a in TINY if not a.startswith(("--online.n_envs", "--online.use_async_envs"))]
    args += ["--online.n_envs=2", "--online.use_async_envs=true", *ENVS["sawyer_reach"], "--steps=50"]
    proc = subprocess.run(
        [sys.executable, "-c", KILLED_AT_CALL, f"--output_dir={out}", *args],
        capture_output=True,
        text=True,
        timeout=600,
        env={
            **_env(),
            "KILL_AT": "lerobot_indicator.training.online:OnlineTrainer.optimise:3",
            "KILL_WITH": "SIGTERM",
        },
    )
    assert proc.returncode == 143, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    assert "interrupted: the run continues from its resume/ state" in proc.stderr.strip().splitlines()[-1]
    assert (out / "resume" / "progress.json").exists()
