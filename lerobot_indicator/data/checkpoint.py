"""Crash safety of a recorded dataset: LeRobot's writer works in a stage and every saved episode is committed
to the dataset at once. The one mechanism behind the recorder CLI and the online trainer's ``--record.*``.

``LeRobotDataset`` keeps parquet writers open until ``finalize()`` (no footer before that), writes a new
episode's rows before its metadata, and rewrites ``meta/info.json``/``stats.json``/``tasks.parquet`` in
place, so a dataset it is writing into is unreadable (or inconsistent) between those steps. Hence
:class:`StagedRecording`: LeRobot's writer works in ``<root>/.recording/stage``, a dataset root of its own
that starts empty or from a copy of ``<root>``'s metadata files (:func:`prepare_stage`), and it starts new
data, episode-metadata and video files for every episode. After each ``save_episode`` those files are
closed and :func:`commit_episode` brings them into ``<root>``:

1. the new metadata files are prepared in ``<root>/.recording/publish`` and the commit is described
   in ``<root>/.recording/commit.json``;
2. the new files are hard-linked into ``<root>`` under their own, new names (videos, then data, then
   episode metadata: a file is in place before anything refers to it), so a reader of the previous
   state never meets a half-written file;
3. ``tasks.parquet``, ``stats.json``, the content hashes (data/integrity.py: the new files' hashes
   added to those of the committed ones) and, last, ``info.json`` are replaced atomically: ``info.json`` is
   the commit point.

``<root>`` is thus a complete dataset at every instant and LeRobot reads it as it is, whatever ends the
writer (between steps 2 and 3 it still reads as the previous state: the new rows come after the
``total_frames`` it counts). :func:`recover_recording` finishes a commit that ``commit.json`` describes
(nothing is rolled back) and drops the stage, which holds at most the episode that was being saved.
"""

from __future__ import annotations

import contextlib
import filecmp
import json
import logging
import os
import shutil
from pathlib import Path

import PIL.Image
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from lerobot_indicator.data.errors import DatasetError
from lerobot_indicator.data.integrity import HASHES, INFO, updated_hashes
from lerobot_indicator.data.storage import video_encoders

JOURNAL_DIR = ".recording"
STAGE_DIR = "stage"
PUBLISH_DIR = "publish"
COMMIT_FILE = "commit.json"
# What LeRobot's ``resume`` reads besides the last episode-metadata file.
RESUME_META = (INFO, "meta/stats.json", "meta/tasks.parquet")
# Directories where LeRobot starts new files, in commit order: videos and data rows before the
# episode metadata that refers to them.
NEW_FILE_DIRS = ("videos", "data", "meta/episodes")
# Replaced in this order: info.json (the episode count) last.
COMMITTED_META = ("meta/tasks.parquet", "meta/stats.json", HASHES, INFO)


def write_atomic(path: Path, content: str | bytes) -> None:
    """Write ``path`` so that a reader (or a crash) sees either its old or its new content."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    if isinstance(content, str):
        tmp.write_text(content, encoding="utf-8")
    else:
        tmp.write_bytes(content)
    os.replace(tmp, path)


def info_json(info: dict) -> str:
    """``info.json`` text as LeRobot's ``write_info`` formats it."""
    return json.dumps(info, indent=4, ensure_ascii=False)


# ---------------- the commit protocol (files only) ----------------


def stage_root(root: Path) -> Path:
    return Path(root) / JOURNAL_DIR / STAGE_DIR


def prepare_stage(root: Path) -> Path:
    """A fresh stage for resuming ``root``: the files of :data:`RESUME_META` and the last episode-metadata
    file (its last row tells the writer where the next episode goes). Copies, never links: LeRobot rewrites
    the meta files in place."""
    root = Path(root)
    stage = stage_root(root)
    shutil.rmtree(stage, ignore_errors=True)
    (stage / "meta").mkdir(parents=True)
    for rel in RESUME_META:
        if (root / rel).exists():
            shutil.copyfile(root / rel, stage / rel)
    episode_files = sorted((root / "meta" / "episodes").glob("*/*.parquet"))
    if episode_files:
        rel = episode_files[-1].relative_to(root)
        (stage / rel).parent.mkdir(parents=True)
        shutil.copyfile(root / rel, stage / rel)
    return stage


def staged_files(stage: Path) -> list[str]:
    """Files of ``stage`` a commit brings into the dataset, in commit order."""
    stage = Path(stage)
    return [
        p.relative_to(stage).as_posix()
        for directory in NEW_FILE_DIRS
        for p in sorted((stage / directory).rglob("*"))
        if p.is_file()
    ]


def commit_episode(root: Path, info: dict, committed: set[str]) -> set[str]:
    """Commit the stage's closed files and metadata to ``root`` (see the module docstring).

    ``info`` is the new ``info.json`` content; ``committed`` the stage files an earlier commit already
    brought in. Returns the files this commit brought in. The stage keeps only those afterwards: LeRobot
    looks at its latest files only (to decide that the next episode starts new ones).
    """
    root = Path(root)
    journal, stage = root / JOURNAL_DIR, stage_root(root)
    publish = journal / PUBLISH_DIR
    (publish / "meta").mkdir(parents=True, exist_ok=True)
    new = [rel for rel in staged_files(stage) if rel not in committed]
    (publish / HASHES).write_text(updated_hashes(root, stage, info, new), encoding="utf-8")
    (publish / INFO).write_text(info_json(info), encoding="utf-8")
    for rel in COMMITTED_META:
        # Moved, not copied: LeRobot writes these from memory, tasks.parquet only when a task is new.
        if rel not in (HASHES, INFO) and (stage / rel).exists():
            os.replace(stage / rel, publish / rel)
    replace = [rel for rel in COMMITTED_META if (publish / rel).exists()]
    commit = {"total_episodes": info["total_episodes"], "link": new, "replace": replace}
    # Written after everything it names; a crash while writing it leaves unparsable JSON, which
    # apply_commit() discards (nothing of that commit reached root yet).
    (journal / COMMIT_FILE).write_text(json.dumps(commit))
    apply_commit(root)
    for rel in committed:
        (stage / rel).unlink(missing_ok=True)
    return set(new)


def _link(src: Path, dst: Path) -> None:
    if dst.exists():
        if not src.exists() or dst.samefile(src) or filecmp.cmp(src, dst, shallow=False):
            return  # brought in by an earlier try of the same commit
        raise FileExistsError(f"{dst} exists and differs from the recorded {src}: not overwriting it")
    dst.parent.mkdir(parents=True, exist_ok=True)
    try:
        os.link(src, dst)
    except OSError:  # no hard links here: copy under a name no reader looks for, then rename
        tmp = dst.with_name(dst.name + ".tmp")
        shutil.copyfile(src, tmp)
        os.replace(tmp, dst)


def _replace_meta(root: Path, publish: Path, rels: list[str]) -> None:
    for rel in rels:
        if (publish / rel).exists():  # else already replaced by an earlier try of this commit
            os.replace(publish / rel, root / rel)


def apply_commit(root: Path) -> int | None:
    """Carry out the commit ``commit.json`` describes (again, if it was cut short); returns the episode
    count it commits, ``None`` if no commit is pending. Idempotent."""
    root = Path(root)
    journal = root / JOURNAL_DIR
    path = journal / COMMIT_FILE
    if not path.exists():
        return None
    try:
        commit = json.loads(path.read_text())
    except json.JSONDecodeError:  # cut short while being written: nothing of it was applied
        path.unlink()
        return None
    for rel in commit["link"]:
        _link(stage_root(root) / rel, root / rel)
    _replace_meta(root, journal / PUBLISH_DIR, commit["replace"])
    path.unlink()
    return int(commit["total_episodes"])


def discard_stage(root: Path) -> None:
    """Remove the stage (and the journal directory once nothing else is in it)."""
    journal = Path(root) / JOURNAL_DIR
    for name in (STAGE_DIR, PUBLISH_DIR):
        shutil.rmtree(journal / name, ignore_errors=True)
    if journal.is_dir() and not any(journal.iterdir()):
        journal.rmdir()


def recover_recording(root: Path) -> int | None:
    """After an interrupted recording: finish its last commit if it was cut short, drop the stage (the
    episode being saved). Never removes a committed episode. Returns the episode count of a finished
    commit, ``None`` if there was none to finish."""
    root = Path(root)
    finished = apply_commit(root)
    if finished is not None:
        logging.warning(
            "Finished the last commit of an interrupted recording at %s (%d episodes).", root, finished
        )
    discard_stage(root)
    return finished


def committed_counts(root: Path) -> tuple[int, int]:
    """``(total_episodes, total_frames)`` that ``root``'s ``info.json`` commits; ``(0, 0)`` if none."""
    path = Path(root) / INFO
    if not path.exists():
        return 0, 0
    info = json.loads(path.read_text())
    return int(info["total_episodes"]), int(info["total_frames"])


# ---------------- LeRobot's writer in the stage ----------------


class CorruptFrameError(DatasetError, RuntimeError):
    """An image/video frame file of the episode being saved cannot be read back."""


def verify_frames(dataset: LeRobotDataset) -> None:
    """Every image/video frame file of the buffered episode decodes (LeRobot's image writer only logs a
    failed write, and would embed or encode whatever is on disk)."""
    writer = dataset.writer
    if writer.image_writer is not None:
        writer.image_writer.wait_until_done()
    episode = dataset.meta.total_episodes
    for key in dataset.meta.camera_keys:
        for frame, path in enumerate(writer.episode_buffer.get(key, [])):
            if path is None:  # fed to a streaming video encoder, never written as a file
                continue
            try:
                with PIL.Image.open(path) as image:
                    image.load()
            except Exception as err:
                reason = " ".join(str(err).split()) or type(err).__name__
                raise CorruptFrameError(
                    f"episode {episode}, frame {frame}: {key} cannot be read back from {path} ({reason}); "
                    "the episode was not saved"
                ) from err


def _close_episode_files(dataset: LeRobotDataset) -> None:
    """Close the data and episode-metadata parquet files of the episode just saved (their footers written).

    LeRobot closes them only in ``finalize()``, which also ends the writer (``finalize()`` + ``resume()`` per
    episode would rebuild the writer and reload its metadata through an Arrow cache every time). The data
    file has the public ``DatasetWriter.close_writer()``; the episode metadata has no public counterpart, so
    this is the one place that calls LeRobot's private ``LeRobotDatasetMetadata._close_writer()`` (which
    flushes the buffered rows, then closes the file).
    """
    dataset.writer.close_writer()
    dataset.meta._close_writer()


class StagedRecording:
    """LeRobot's writer working in the stage of ``root``; :meth:`save_episode` saves and commits.

    Open it with :meth:`create` (a new dataset) or :meth:`resume` (after :func:`recover_recording`), fill
    ``dataset``'s episode buffer with ``add_frame``, then call :meth:`save_episode` per episode and
    :meth:`close` once.
    """

    def __init__(self, root: Path, dataset: LeRobotDataset):
        self.root = Path(root)
        self.dataset = dataset
        info = dataset.meta.info
        # The dataset's own file size limits, written to the committed info.json.
        self.file_sizes = {
            "data_files_size_in_mb": info.data_files_size_in_mb,
            "video_files_size_in_mb": info.video_files_size_in_mb,
        }
        # With limits of 0, LeRobot starts new data, episode-metadata and video files for every episode,
        # so an episode's files can be closed and committed while the next ones go elsewhere (LeRobot's
        # chunk settings API refuses 0). In the stage only: see file_sizes.
        info.data_files_size_in_mb = 0
        info.video_files_size_in_mb = 0
        self.committed = set(staged_files(stage_root(self.root)))

    @classmethod
    def create(
        cls,
        root: Path,
        repo_id: str,
        fps: int,
        features: dict,
        use_videos: bool,
        image_writer_threads: int,
        robot_type: str | None = None,
    ) -> StagedRecording:
        """A new, empty dataset at ``root`` (its ``info.json`` is written at once, with 0 episodes)."""
        dataset = LeRobotDataset.create(
            repo_id,
            fps=fps,
            features=features,
            root=stage_root(root),
            robot_type=robot_type,
            use_videos=use_videos,
            video_backend="pyav",
            image_writer_threads=image_writer_threads,
            **video_encoders(),
        )
        write_atomic(Path(root) / INFO, info_json(dataset.meta.info.to_dict()))
        return cls(root, dataset)

    @classmethod
    def resume(cls, root: Path, repo_id: str, image_writer_threads: int) -> StagedRecording:
        """More episodes for the dataset at ``root``, which :func:`recover_recording` has cleaned up."""
        stage = prepare_stage(root)
        try:
            dataset = LeRobotDataset.resume(
                repo_id,
                root=stage,
                video_backend="pyav",
                image_writer_threads=image_writer_threads,
                **video_encoders(),
            )
        except BaseException:
            discard_stage(root)
            raise
        return cls(root, dataset)

    @property
    def total_episodes(self) -> int:
        return self.dataset.meta.total_episodes

    def save_episode(self) -> None:
        """Save the buffered episode with LeRobot's writer, close its files and commit them to ``root``."""
        verify_frames(self.dataset)
        self.dataset.save_episode()
        _close_episode_files(self.dataset)
        self.committed = commit_episode(
            self.root, self.dataset.meta.info.to_dict() | self.file_sizes, self.committed
        )

    def close(self, clean: bool = True) -> None:
        """Stop LeRobot's writer and drop the stage (everything it held is committed, or the episode that
        was being saved); a commit cut short is finished first. Idempotent."""
        if clean:
            self.dataset.finalize()
        else:
            with contextlib.suppress(Exception):  # waits for (and stops) the image writer threads
                self.dataset.finalize()
        recover_recording(self.root)

    def committed_dataset(self) -> LeRobotDataset:
        """A finalized handle on the dataset at ``root`` (counts, ``push_to_hub``; frames load on first
        read), opened with LeRobot's ``resume``, which reads the metadata only."""
        dataset = LeRobotDataset.resume(self.dataset.repo_id, root=self.root, video_backend="pyav")
        dataset.finalize()
        return dataset
