"""The crash-safe state of an online run's directory: what ``--resume=true`` continues from.

* ``resume/``: weights, optimizer and ``Progress``, written to ``resume.tmp/`` and swapped in, so a crash
  leaves the previous state intact;
* ``replay/cycle_*.npz``: each cycle's new episodes; a file is deleted once the replay buffer's FIFO has
  evicted all of its episodes, so disk use stays bounded by the buffer capacity;
* ``metrics.jsonl``: one strict-JSON line per cycle (a non-finite value is ``null``); a resumed run drops the
  lines written after its state, and a last line cut short by a crash or a full disk.

``RunPersistence`` is the trainer's interface to all of it plus the optional ``--record`` dataset.
"""

from __future__ import annotations

import json
import logging
import math
import shutil
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from lerobot.optim import load_optimizer_state, save_optimizer_state
from safetensors.torch import load_model, save_model

from lerobot_indicator.finite import check_module
from lerobot_indicator.io_errors import CorruptFileError, reading
from lerobot_indicator.keys import GT_ACHIEVED_GOAL, GT_DESIRED_GOAL
from lerobot_indicator.training import atomic_dir
from lerobot_indicator.training.recording import RolloutRecorder
from lerobot_indicator.training.replay_buffer import EpisodeReplayBuffer
from lerobot_indicator.training.rollout import Rollouts

METRICS_FILE = "metrics.jsonl"
RESUME_DIR = "resume"
REPLAY_DIR = "replay"
# Array names inside a replay chunk besides ``obs/<key>``.
CHUNK_ACTIONS, CHUNK_GT_ACHIEVED, CHUNK_GT_DESIRED = "actions", "gt_achieved", "gt_desired"
# What a CorruptFileError in the resume state says to do.
RESUME_HINT = (
    "this run cannot resume from it; start a new run, or a --policy.path run from one of its checkpoints"
)


@dataclass
class Progress:
    """Counters saved with the resume state."""

    cycle: int = 0  # cycles completed
    step: int = 0  # optimisation steps done
    env_steps: int = 0  # env steps of the collected episodes
    episodes: int = 0  # episodes added to the replay buffer, seeded ones included
    wall_time_s: float = 0.0  # of the completed cycles, evaluation included
    seeded_episodes: int = 0  # from --dataset, before any rollout
    recorded_episodes: int = 0  # in the --record dataset's last checkpoint when this state was saved
    # False when training a --policy.path policy, which keeps its own input normalisation (a resumed run
    # also loads a checkpoint as pretrained_path, so this is decided once, at the start, and saved).
    own_input_stats: bool = True
    # (file name, global index of its first episode) of the episode chunks still needed to rebuild the buffer
    replay_files: list[tuple[str, int]] = field(default_factory=list)


def replay_chunk(rollouts: list[Rollouts]) -> dict[str, np.ndarray]:
    """One cycle's episodes as the arrays of a ``replay/cycle_*.npz`` file."""
    chunk = {
        f"obs/{k}": np.concatenate([r.observations[k] for r in rollouts]) for k in rollouts[0].observations
    }
    chunk[CHUNK_ACTIONS] = np.concatenate([r.actions for r in rollouts])
    if rollouts[0].gt_achieved is not None:
        chunk[CHUNK_GT_ACHIEVED] = np.concatenate([r.gt_achieved for r in rollouts])
        chunk[CHUNK_GT_DESIRED] = np.concatenate([r.gt_desired for r in rollouts])
    return chunk


def add_replay_chunk(buffer: EpisodeReplayBuffer, chunk: dict[str, np.ndarray]) -> None:
    """Add the episodes of one replay chunk (``replay_chunk``) to ``buffer``."""
    obs = {k[4:]: v for k, v in chunk.items() if k.startswith("obs/")}
    for i in range(chunk[CHUNK_ACTIONS].shape[0]):
        gt = None
        if CHUNK_GT_ACHIEVED in chunk:
            gt = {GT_ACHIEVED_GOAL: chunk[CHUNK_GT_ACHIEVED][i], GT_DESIRED_GOAL: chunk[CHUNK_GT_DESIRED][i]}
        buffer.add_episode({k: v[i] for k, v in obs.items()}, chunk[CHUNK_ACTIONS][i], gt)


class RunDir:
    """Reads and writes the resume state, replay chunks and metrics of one run directory."""

    def __init__(self, out: Path):
        self.out = Path(out)
        # Chunks whose episodes the buffer has evicted, deleted only once a resume state that no longer lists
        # them is on disk: the last saved state still needs them until then.
        self._evicted: list[str] = []

    def state_dir(self) -> Path:
        if (state := atomic_dir.newest(self.out / RESUME_DIR)) is None:
            raise FileNotFoundError(f"--resume=true but {self.out} has no resume state ({RESUME_DIR}/)")
        return state

    def save_state(
        self, policy: torch.nn.Module, optimizer: torch.optim.Optimizer, progress: Progress
    ) -> None:
        """Atomic: write resume.tmp/, then swap it in; a crash leaves the previous state intact."""
        tmp = atomic_dir.staging(self.out / RESUME_DIR)
        try:
            check_module(policy, "resume state")
            save_model(policy, str(tmp / "model.safetensors"))  # handles the shared encoder
            save_optimizer_state(optimizer, tmp)
            (tmp / "progress.json").write_text(json.dumps(progress.__dict__))
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)  # e.g. the disk filled up: free what was written
            raise
        atomic_dir.swap_in(tmp, self.out / RESUME_DIR)
        for name in self._evicted:
            (self.out / REPLAY_DIR / name).unlink(missing_ok=True)
        self._evicted.clear()

    def read_progress(self) -> Progress:
        path = self.state_dir() / "progress.json"
        with reading(path, "resume state's counters", RESUME_HINT):
            progress = Progress(**json.loads(path.read_text()))
        progress.replay_files = [(name, int(first)) for name, first in progress.replay_files]
        return progress

    def load_state(
        self, policy: torch.nn.Module, optimizer: torch.optim.Optimizer
    ) -> tuple[torch.optim.Optimizer, Progress]:
        state = self.state_dir()
        with reading(state / "model.safetensors", "resume state's weights", RESUME_HINT):
            load_model(policy, str(state / "model.safetensors"))
        with reading(state, "resume state's optimizer state (optimizer_*)", RESUME_HINT):
            optimizer = load_optimizer_state(optimizer, state)
        return optimizer, self.read_progress()

    def replay_chunks(self, files: list[tuple[str, int]]) -> Iterator[dict[str, np.ndarray]]:
        for name, _ in files:
            path = self.out / REPLAY_DIR / name
            with reading(path, "replay chunk", RESUME_HINT), np.load(path) as chunk:
                data = dict(chunk)
            yield data

    def append_replay(
        self, rollouts: list[Rollouts], buffer: EpisodeReplayBuffer, progress: Progress
    ) -> None:
        """Persist this cycle's episodes (already in ``buffer``); the chunks it has evicted are deleted by the
        next ``save_state``."""
        chunk = replay_chunk(rollouts)
        (self.out / REPLAY_DIR).mkdir(exist_ok=True)
        name = f"cycle_{progress.cycle:07d}.npz"
        np.savez(self.out / REPLAY_DIR / name, **chunk)
        progress.replay_files.append((name, buffer.total_episodes_added - chunk[CHUNK_ACTIONS].shape[0]))
        # A chunk is no longer needed once every one of its episodes has been evicted.
        oldest_kept = buffer.total_episodes_added - buffer.capacity
        while len(progress.replay_files) > 1 and progress.replay_files[1][1] <= oldest_kept:
            self._evicted.append(progress.replay_files.pop(0)[0])

    def append_metrics(self, record: dict) -> None:
        """One line, in one write: a crash or a full disk can only cut the last line short."""
        with open(self.out / METRICS_FILE, "a") as f:
            f.write(metrics_line(record))

    def drop_metrics_from(self, cycle: int) -> None:
        """Drop the metrics lines of cycles >= ``cycle`` (written after the state a run resumes from) and a last
        line cut short; rewritten atomically."""
        metrics = self.out / METRICS_FILE
        if metrics.exists():
            rows = [r for r in read_metrics_rows(metrics) if r["cycle"] < cycle]
            tmp = metrics.with_name(f"{METRICS_FILE}.tmp")
            tmp.write_text("".join(metrics_line(r) for r in rows))
            tmp.replace(metrics)


def _strict(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    return value


def metrics_line(record: dict) -> str:
    """``record`` as one strict-JSON line: NaN and +-inf (e.g. no ground-truth distance) are ``null``."""
    return json.dumps(_strict(record), allow_nan=False) + "\n"


def read_metrics_rows(path: Path) -> list[dict]:
    """The rows of a ``metrics.jsonl``. A last line that is not JSON (cut short by a crash or a full disk while
    it was appended) is skipped with a warning; any other line that is not JSON is a one-line error."""
    lines = Path(path).read_text().splitlines()
    rows = []
    for i, line in enumerate(lines):
        if not line.strip():
            continue
        try:
            rows.append(json.loads(line))
        except json.JSONDecodeError as err:
            if i == len(lines) - 1:
                logging.warning(
                    "%s: skipping its last line, cut short (%d characters): %s", path, len(line), err
                )
                break
            raise CorruptFileError(
                f"{path}:{i + 1}: not a JSON line ({err}); only the last line can be cut short by a crash"
            ) from None
    return rows


def kept_state(out: Path) -> str:
    """What a run directory holds to continue from, for the message of a run stopped while saving."""
    kept = []
    last = Path(out) / "checkpoints" / "last"
    if last.exists():
        kept.append(f"the last complete checkpoint {last.resolve()}")
    try:
        progress = RunDir(out).read_progress()
        kept.append(f"the resume state of cycle {progress.cycle - 1} (step {progress.step})")
    except (FileNotFoundError, ValueError, RuntimeError):
        pass
    return " and ".join(kept) if kept else "nothing to resume from yet"


class RunPersistence:
    """What the online trainer saves and restores: the run directory and, with ``--record``, the dataset.

    With a dataset the resume state is saved only at a dataset checkpoint, taken just before it: a kill
    between the two leaves the dataset ahead of the state, and the recorder then skips the replayed
    episodes it already holds (rollouts replay exactly)."""

    def __init__(self, out: Path, recorder: RolloutRecorder | None = None):
        self.run_dir = RunDir(out)
        self.recorder = recorder

    @property
    def keeps_dataset_frames(self) -> bool:
        return self.recorder is not None

    def resume(
        self,
        policy: torch.nn.Module,
        optimizer: torch.optim.Optimizer,
        buffer: EpisodeReplayBuffer,
        seed_buffer: Callable[[], int] | None,
    ) -> tuple[torch.optim.Optimizer, Progress]:
        """Load the resume state and rebuild ``buffer`` exactly as it was when the state was saved."""
        optimizer, progress = self.run_dir.load_state(policy, optimizer)
        files = progress.replay_files
        if files and files[0][1] > progress.seeded_episodes:
            # Older chunks (and any dataset seed) were evicted by the FIFO: start the buffer where the first
            # kept chunk started, so every episode lands in the same slot as before the interruption.
            buffer.start_at(files[0][1])
        elif seed_buffer is not None:
            seed_buffer()
        for chunk in self.run_dir.replay_chunks(files):
            add_replay_chunk(buffer, chunk)
        self.run_dir.drop_metrics_from(progress.cycle)
        logging.info("resumed at cycle %d, step %d", progress.cycle, progress.step)
        return optimizer, progress

    def start(self, progress: Progress) -> None:
        if self.recorder is not None:
            self.recorder.start(progress.recorded_episodes)

    def store(self, rollouts: list[Rollouts], buffer: EpisodeReplayBuffer, progress: Progress) -> None:
        """This cycle's episodes (already added to ``buffer``) to ``replay/`` and the dataset."""
        if rollouts:
            self.run_dir.append_replay(rollouts, buffer, progress)
        if self.recorder is not None:
            self.recorder.record(rollouts)

    def save_if_due(
        self, policy: torch.nn.Module, optimizer: torch.optim.Optimizer, progress: Progress, is_last: bool
    ) -> None:
        """The resume state, every cycle; with a dataset only when its checkpoint is due (and at the end)."""
        if self.recorder is not None:
            if not self.recorder.checkpoint_if_due(is_last):
                return
            progress.recorded_episodes = self.recorder.total_episodes
        self.run_dir.save_state(policy, optimizer, progress)

    def finish(self, push_tags: list[str] | None) -> None:
        """A complete run: finalize the dataset (and push it when ``push_tags`` is given)."""
        if self.recorder is not None:
            self.recorder.finish(push_tags)

    def close(self) -> None:
        """Also on a crash: every saved episode of the dataset stays readable."""
        if self.recorder is not None:
            self.recorder.close()
