"""Run persistence without an env: replay chunks follow the buffer's FIFO, a resumed buffer is the same
buffer, and the resume state survives a crash between its two renames."""

import json
import shutil

import numpy as np
import torch

from lerobot_indicator.training import atomic_dir
from lerobot_indicator.training.replay_buffer import EpisodeReplayBuffer
from lerobot_indicator.training.rollout import Rollouts
from lerobot_indicator.training.run_state import (
    REPLAY_DIR,
    RESUME_DIR,
    Progress,
    RunDir,
    RunPersistence,
    add_replay_chunk,
)

T = 2


def _rollouts(first_episode: int, n: int) -> Rollouts:
    """``n`` episodes whose every value is its global episode index, so a slot says what it holds."""
    ids = np.arange(first_episode, first_episode + n, dtype=np.float32)
    state = np.broadcast_to(ids[:, None, None], (n, T + 1, 3)).copy()
    return Rollouts(
        observations={"observation.state": state, "observation.goal_state": state[:, :1] + 100},
        actions=np.broadcast_to(ids[:, None, None], (n, T, 3)).copy(),
        success=np.zeros(n, bool),
        final_distance=np.zeros(n, np.float32),
        gt_achieved=state.copy(),
        gt_desired=state[:, 0] + 100,
    )


def _store(run_dir: RunDir, buffer: EpisodeReplayBuffer, progress: Progress, rollouts: Rollouts) -> None:
    for episode in rollouts.episodes():
        buffer.add_episode(*episode)
    run_dir.append_replay([rollouts], buffer, progress)
    progress.cycle += 1


def _policy_and_optimizer(seed: int) -> tuple[torch.nn.Module, torch.optim.Optimizer]:
    torch.manual_seed(seed)
    policy = torch.nn.Linear(3, 2)
    optimizer = torch.optim.Adam(policy.parameters(), lr=1e-2)
    policy(torch.ones(1, 3)).sum().backward()
    optimizer.step()
    return policy, optimizer


def test_evicted_chunks_are_deleted_and_a_resumed_buffer_matches(tmp_path):
    run_dir, progress = RunDir(tmp_path), Progress()
    buffer = EpisodeReplayBuffer(capacity_transitions=3 * T, horizon=T)  # 3 episodes
    for cycle in range(5):  # 2 episodes per cycle: episodes 0..9, the buffer keeps 7, 8, 9
        _store(run_dir, buffer, progress, _rollouts(2 * cycle, 2))
    # cycle 3 holds episodes 6 (evicted) and 7 (kept); cycles 0-2 hold only evicted ones.
    assert progress.replay_files == [("cycle_0000003.npz", 6), ("cycle_0000004.npz", 8)]
    assert len(list((tmp_path / REPLAY_DIR).iterdir())) == 5  # deleted only with the next resume state

    policy, optimizer = _policy_and_optimizer(0)
    run_dir.save_state(policy, optimizer, progress)
    kept = sorted(p.name for p in (tmp_path / REPLAY_DIR).iterdir())
    assert kept == ["cycle_0000003.npz", "cycle_0000004.npz"]
    fresh_policy, fresh_optimizer = _policy_and_optimizer(1)
    resumed = EpisodeReplayBuffer(capacity_transitions=3 * T, horizon=T)
    persistence = RunPersistence(tmp_path)
    fresh_optimizer, loaded = persistence.resume(fresh_policy, fresh_optimizer, resumed, seed_buffer=None)
    assert loaded == progress
    assert (resumed.next_slot, resumed.num_episodes, resumed.total_episodes_added) == (
        buffer.next_slot,
        buffer.num_episodes,
        buffer.total_episodes_added,
    )
    for key in buffer.obs:
        np.testing.assert_array_equal(resumed.obs[key][:], buffer.obs[key][:])
    np.testing.assert_array_equal(resumed.actions, buffer.actions)
    np.testing.assert_array_equal(resumed.gt_desired, buffer.gt_desired)
    torch.testing.assert_close(fresh_policy.state_dict(), policy.state_dict(), rtol=0, atol=0)
    assert fresh_optimizer.state_dict()["state"][0]["step"] == optimizer.state_dict()["state"][0]["step"]


def test_a_run_killed_after_a_cycle_evicted_chunks_resumes_from_its_last_state(tmp_path):
    """Killed after a cycle stored its episodes (evicting the oldest chunk) but before its resume state was
    saved: every chunk the saved state lists is still on disk, and resuming rebuilds that state's buffer."""
    run_dir, progress = RunDir(tmp_path), Progress()
    buffer = EpisodeReplayBuffer(capacity_transitions=3 * T, horizon=T)
    policy, optimizer = _policy_and_optimizer(0)
    for cycle in range(3):
        _store(run_dir, buffer, progress, _rollouts(2 * cycle, 2))
        run_dir.save_state(policy, optimizer, progress)
    saved = RunDir(tmp_path).read_progress()
    expected = (buffer.obs["observation.state"][:].copy(), buffer.total_episodes_added)
    _store(run_dir, buffer, progress, _rollouts(6, 2))  # evicts cycle 1's chunk; then the process dies
    assert progress.replay_files[0][0] != saved.replay_files[0][0]
    resumed = EpisodeReplayBuffer(capacity_transitions=3 * T, horizon=T)
    _, loaded = RunPersistence(tmp_path).resume(*_policy_and_optimizer(1), resumed, seed_buffer=None)
    assert loaded == saved
    np.testing.assert_array_equal(resumed.obs["observation.state"][:], expected[0])
    assert resumed.total_episodes_added == expected[1]


def test_a_crash_between_the_renames_resumes_from_the_previous_state(tmp_path):
    run_dir = RunDir(tmp_path)
    policy, optimizer = _policy_and_optimizer(0)
    run_dir.save_state(policy, optimizer, Progress(cycle=3, step=30))
    (tmp_path / RESUME_DIR).rename(tmp_path / f"{RESUME_DIR}.old")  # the swap's first rename, then a kill
    restored, _ = _policy_and_optimizer(1)
    _, progress = run_dir.load_state(restored, optimizer)
    assert (progress.cycle, progress.step) == (3, 30)
    torch.testing.assert_close(restored.state_dict(), policy.state_dict(), rtol=0, atol=0)


def test_a_kill_after_the_second_rename_leaves_a_state_the_next_save_replaces(tmp_path):
    """resume/ and a stale resume.old/ both on disk (killed before resume.old was deleted): the run resumes from
    resume/, and its next save still swaps in."""
    run_dir = RunDir(tmp_path)
    policy, optimizer = _policy_and_optimizer(0)
    run_dir.save_state(policy, optimizer, Progress(cycle=1, step=10))
    shutil.copytree(tmp_path / RESUME_DIR, tmp_path / f"{RESUME_DIR}.old")
    run_dir.save_state(policy, optimizer, Progress(cycle=2, step=20))
    assert run_dir.read_progress().cycle == 2
    assert not (tmp_path / f"{RESUME_DIR}.old").exists()
    (tmp_path / f"{RESUME_DIR}.old").mkdir()  # an old copy beside a newer complete one is never read
    (tmp_path / f"{RESUME_DIR}.old" / "progress.json").write_text(json.dumps(Progress(cycle=1).__dict__))
    assert run_dir.read_progress().cycle == 2


def test_an_interrupted_write_never_replaces_the_state(tmp_path):
    final = tmp_path / "ckpt"
    final.mkdir()
    (final / "a").write_text("complete")
    tmp = atomic_dir.staging(final)
    (tmp / "a").write_text("half")  # killed here: the swap never ran
    assert atomic_dir.newest(final) == final and (final / "a").read_text() == "complete"
    assert not any(atomic_dir.staging(final).iterdir())  # the next write starts from an empty directory
    assert atomic_dir.newest(tmp_path / "never_written") is None


def test_metrics_of_cycles_after_the_resume_state_are_dropped(tmp_path):
    run_dir = RunDir(tmp_path)
    for cycle in range(4):
        run_dir.append_metrics({"cycle": cycle, "critic_loss": float(cycle)})
    run_dir.drop_metrics_from(2)
    lines = (tmp_path / "metrics.jsonl").read_text().splitlines()
    assert [json.loads(line)["cycle"] for line in lines] == [0, 1]


def test_ground_truth_survives_a_chunk_round_trip(tmp_path):
    run_dir, progress = RunDir(tmp_path), Progress()
    buffer = EpisodeReplayBuffer(capacity_transitions=10 * T, horizon=T)
    _store(run_dir, buffer, progress, _rollouts(5, 1))
    (chunk,) = run_dir.replay_chunks(progress.replay_files)
    rebuilt = EpisodeReplayBuffer(capacity_transitions=10 * T, horizon=T)
    add_replay_chunk(rebuilt, chunk)
    sample = rebuilt.sample(4, np.random.default_rng(0))
    assert np.all(sample["gt_desired"] == 105) and np.all(sample["gt_next_achieved"] == 5)
