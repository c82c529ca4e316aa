"""``--online.backend=ray`` on a local Ray cluster: a short online run with 2 workers gives the local
backend's results exactly (CPU, same seeds), also when a worker is killed in the middle of a cycle."""

import json
from pathlib import Path

import numpy as np
import pytest
import torch

ray = pytest.importorskip("ray")

from lerobot_indicator.training.ray_rollouts import PackedArray, RayRollouts, WireRollouts  # noqa: E402
from lerobot_indicator.training.rollout import Rollouts  # noqa: E402

ARGS = [
    "--env.type=sawyer_reach",
    "--env.obs_type=state",
    "--env.episode_length=5",
    "--policy.type=indicator_ddpg",
    "--policy.push_to_hub=false",
    "--policy.device=cpu",
    "--policy.hidden_dims=[16,16,16]",
    "--online.n_envs=1",
    "--online.use_async_envs=false",
    "--online.episodes_per_cycle=3",
    "--online.updates_per_cycle=3",
    "--online.batch_size=8",
    "--online.eval_episodes=1",
    "--env_eval_freq=6",
    "--save_freq=6",
    "--seed=3",
    "--steps=6",
]


@pytest.fixture(scope="module")
def ray_cluster():
    # Ray gives its raylet a fixed 30 s to register at start-up, which a machine busy with other jobs can miss
    # (a cold first start loads its binaries): a few attempts.
    for attempt in range(3):
        try:
            ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
            break
        except Exception:
            ray.shutdown()
            if attempt == 2:
                raise
    yield
    ray.shutdown()


def _train(
    out: Path, *args: str, kill_in_cycle: int | None = None, monkeypatch=None
) -> tuple[list[dict], dict]:
    """One in-process online run; returns its metrics (without wall time) and final actor weights."""
    import draccus
    from lerobot.utils.import_utils import register_third_party_plugins

    from lerobot_indicator.training.config import OnlineTrainConfig
    from lerobot_indicator.training.online import OnlineTrainer

    register_third_party_plugins()
    cfg = draccus.parse(OnlineTrainConfig, args=[*ARGS, f"--output_dir={out}", *args])
    cfg.validate()
    trainer = OnlineTrainer(cfg)
    if kill_in_cycle is not None:
        submit, calls = RayRollouts.submit, []

        def submit_then_kill(self, batches, policy):
            submit(self, batches, policy)
            calls.append(len(batches))
            if len(calls) == kill_in_cycle + 1:
                ray.kill(self.workers[0])  # its batch is in flight

        monkeypatch.setattr(RayRollouts, "submit", submit_then_kill)
    try:
        trainer.train()
        replacements = trainer.ray_rollouts.replacements if trainer.ray_rollouts else 0
    finally:
        trainer.close()
    rows = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    for row in rows:  # wall times (wall_time_s, data_s, update_s) differ between any two runs
        for key in [k for k in row if k.endswith("_s")]:
            row.pop(key)
    weights = {k: v.clone() for k, v in trainer.policy.state_dict().items()}
    return rows, {"weights": weights, "replacements": replacements}


@pytest.fixture(scope="module")
def local_run(tmp_path_factory):
    return _train(tmp_path_factory.mktemp("local") / "run")


def test_starting_ray_keeps_the_callers_sigterm_handler(monkeypatch):
    """Ray's ``init`` installs its own SIGTERM handler (exit at once); the trainer's must survive it."""
    import signal
    import sys
    import types

    def rays_handler(signum, frame):
        raise SystemExit(signum)

    def trainers_handler(signum, frame):
        raise KeyboardInterrupt

    fake = types.SimpleNamespace(
        is_initialized=lambda: False,
        init=lambda **kwargs: signal.signal(signal.SIGTERM, rays_handler),
        remote=lambda **kwargs: lambda cls: types.SimpleNamespace(remote=lambda cfg: object()),
    )
    monkeypatch.setitem(sys.modules, "ray", fake)
    previous = signal.signal(signal.SIGTERM, trainers_handler)
    try:
        RayRollouts(cfg=None, num_workers=1)
        assert signal.getsignal(signal.SIGTERM) is trainers_handler
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_two_ray_workers_equal_the_local_backend_despite_a_killed_worker(
    ray_cluster, local_run, tmp_path, monkeypatch
):
    rows, state = _train(
        tmp_path / "ray",
        "--online.backend=ray",
        "--online.num_workers=2",
        kill_in_cycle=1,
        monkeypatch=monkeypatch,
    )
    local_rows, local_state = local_run
    assert state["replacements"] == 1  # the kill was seen and the worker replaced
    assert [r["episodes"] for r in rows] == [3, 6]  # no episode lost or counted twice
    assert rows == local_rows
    for k, v in local_state["weights"].items():
        assert torch.equal(state["weights"][k], v), k


def test_wire_format_is_lossless_and_sends_goals_once():
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (2, 4, 3, 16, 16)).astype(np.float32) / 255  # (n, T + 1, C, H, W), k/255
    goal = np.repeat(rgb[:, :1], 4, axis=1)
    state = rng.normal(size=(2, 4, 3)).astype(np.float32)
    rollouts = Rollouts(
        observations={
            "observation.images.front": rgb,
            "observation.images.goal_front": goal,
            "observation.state": state,
        },
        actions=rng.normal(size=(2, 3, 3)).astype(np.float32),
        success=np.array([True, False]),
        final_distance=np.array([0.1, 0.2], np.float32),
        gt_achieved=None,
        gt_desired=None,
    )
    wire = WireRollouts.of(rollouts)
    assert wire.observations["observation.images.front"].data.dtype == np.uint8
    assert wire.observations["observation.images.goal_front"].data.shape == (2, 1, 3, 16, 16)
    assert wire.observations["observation.state"].data.dtype == np.float32
    back = wire.rollouts()
    for k, v in rollouts.observations.items():
        assert back.observations[k].dtype == np.float32 and np.array_equal(
            back.observations[k].view(np.uint32), v.view(np.uint32)
        ), k
    assert np.array_equal(back.actions, rollouts.actions)
    # uint8 frames, one goal per episode: (1 + 1/4) / 8 of the two float32 image arrays, plus the state.
    assert wire.nbytes() < (rgb.nbytes + goal.nbytes) / 4
    assert PackedArray.of(state).per_episode is False


def test_ray_backend_records_and_resumes_as_the_local_backend(ray_cluster, local_run, tmp_path, monkeypatch):
    # --record.* and --resume with Ray workers: interrupted in cycle 1's updates (after cycle 0's episodes
    # and resume state were saved), then resumed, the run ends with the local backend's metrics, weights
    # and recorded episodes.
    from lerobot.datasets import LeRobotDataset

    from lerobot_indicator.training.online import OnlineTrainer

    def record(name: str) -> list[str]:
        root = tmp_path / f"{name}_dataset"
        return [f"--record.repo_id=local/{name}", f"--record.root={root}"]

    local_rows, local_state = _train(tmp_path / "local", *record("local"))
    assert local_rows == local_run[0]  # recording changes nothing the run computes
    ray_args = ["--online.backend=ray", "--online.num_workers=2", *record("ray")]
    optimise, calls = OnlineTrainer.optimise, []

    def interrupted(self, *args):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return optimise(self, *args)

    monkeypatch.setattr(OnlineTrainer, "optimise", interrupted)
    with pytest.raises(KeyboardInterrupt):
        _train(tmp_path / "ray", *ray_args)
    monkeypatch.setattr(OnlineTrainer, "optimise", optimise)
    rows, state = _train(tmp_path / "ray", *ray_args, "--resume=true")
    assert rows == local_rows
    for k, v in local_state["weights"].items():
        assert torch.equal(state["weights"][k], v), k
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    local_ds, ray_ds = (
        LeRobotDataset(f"local/{n}", root=tmp_path / f"{n}_dataset", video_backend="pyav")
        for n in ("local", "ray")
    )
    assert local_ds.num_episodes == ray_ds.num_episodes == 6 and len(local_ds) == len(ray_ds)
    for i in range(len(local_ds)):
        a, b = local_ds[i], ray_ds[i]
        for key in ("action", "observation.state", "observation.goal_state", "episode_index", "next.reward"):
            assert torch.equal(a[key], b[key]), (i, key)
