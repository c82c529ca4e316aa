"""Crash safety of recorded datasets: staged per-episode commits, and rollback checkpoints.

``LeRobotDataset`` keeps parquet writers open until ``finalize()`` (no footer before that), writes a
new episode's rows before its metadata, and rewrites ``meta/info.json``/``stats.json``/``tasks.parquet``
in place, so a dataset it is writing into is unreadable (or inconsistent) between those steps.

**Staged commits** (``lerobot-indicator-record``): LeRobot's writer works in ``<root>/.recording/stage``,
a dataset root of its own that starts from a copy of ``<root>``'s metadata files (:func:`prepare_stage`),
and it starts new data, episode-metadata and video files for every episode. After each
``save_episode`` the recorder closes those files and :func:`commit_episode` brings them into ``<root>``:

1. the new metadata files are prepared in ``<root>/.recording/publish`` and the commit is described
   in ``<root>/.recording/commit.json``;
2. the new files are hard-linked into ``<root>`` under their own, new names (videos, then data, then
   episode metadata: a file is in place before anything refers to it), so a reader of the previous
   state never meets a half-written file;
3. ``tasks.parquet``, ``stats.json`` and, last, ``info.json`` are replaced atomically: ``info.json`` is
   the commit point.

``<root>`` is thus a complete dataset at every instant and LeRobot reads it as it is, whatever ends
the recorder (between steps 2 and 3 it still reads as the previous state: the new rows come after the
``total_frames`` it counts). :func:`recover_recording` finishes a commit that ``commit.json`` describes
(nothing is rolled back) and drops the stage, which holds at most the episode that was in flight.

**Rollback checkpoints** (the online trainer's ``--record.*``, which writes straight into ``<root>``):
at checkpoints the dataset is finalized and :func:`write_checkpoint` journals that consistent state
(``<root>/.recording/checkpoint.json``: every file plus the bytes of the three rewritten meta files).
After finalize, LeRobot's ``resume`` always opens *new* data/episode/video files, so the listed files
are never modified later. :func:`restore_checkpoint` keeps the dataset as it is when it is consistent by
itself (e.g. finalized after an exception or Ctrl-C), else rolls it back to the checkpoint: deleting
unlisted files and restoring the three meta files. The journal is removed after a clean finish.
"""

from __future__ import annotations

import base64
import filecmp
import json
import logging
import os
import shutil
from pathlib import Path

import pyarrow.parquet as pq

JOURNAL_DIR = ".recording"
JOURNAL_FILE = "checkpoint.json"
STAGE_DIR = "stage"
PUBLISH_DIR = "publish"
COMMIT_FILE = "commit.json"
INFO = "meta/info.json"
REWRITTEN_META = (INFO, "meta/stats.json", "meta/tasks.parquet")
# Directories where LeRobot starts new files, in commit order: videos and data rows before the
# episode metadata that refers to them.
NEW_FILE_DIRS = ("videos", "data", "meta/episodes")
# Replaced in this order: info.json (the episode count) last.
COMMITTED_META = ("meta/tasks.parquet", "meta/stats.json", INFO)


def _journal_path(root: Path) -> Path:
    return Path(root) / JOURNAL_DIR / JOURNAL_FILE


def _dataset_files(root: Path) -> list[str]:
    return sorted(
        p.relative_to(root).as_posix()
        for p in root.rglob("*")
        if p.is_file() and p.relative_to(root).parts[0] != JOURNAL_DIR
    )


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


# ---------------- staged per-episode commits ----------------


def stage_root(root: Path) -> Path:
    return Path(root) / JOURNAL_DIR / STAGE_DIR


def prepare_stage(root: Path) -> Path:
    """A fresh stage for resuming ``root``: what LeRobot's ``resume`` reads (``info.json``, ``stats.json``,
    ``tasks.parquet``) and the last episode-metadata file (its last row tells the writer where the next
    episode goes). Copies, never links: LeRobot rewrites the meta files in place."""
    root = Path(root)
    stage = stage_root(root)
    shutil.rmtree(stage, ignore_errors=True)
    (stage / "meta").mkdir(parents=True)
    for rel in REWRITTEN_META:
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
    (publish / INFO).write_text(info_json(info), encoding="utf-8")
    for rel in COMMITTED_META:
        # Moved, not copied: LeRobot writes these from memory, tasks.parquet only when a task is new.
        if rel != INFO and (stage / rel).exists():
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


def _link_files(root: Path, stage: Path, rels: list[str]) -> None:
    for rel in rels:
        _link(stage / rel, root / rel)


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
    _link_files(root, stage_root(root), commit["link"])
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
    """After an interrupted staged recording: finish its last commit if it was cut short, drop the
    stage (the episode that was in flight). Never removes a committed episode. Returns the episode count
    of a finished commit, ``None`` if there was none to finish."""
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


# ---------------- rollback checkpoints ----------------


def is_consistent(root: Path) -> bool:
    """Whether ``root`` is a complete dataset by itself: every data and episode-metadata parquet file has
    its footer, ``info.json`` counts exactly their rows, and every video file they refer to exists."""
    root = Path(root)
    try:
        info = json.loads((root / INFO).read_text())
        if (root / "meta" / "stats.json").exists():
            json.loads((root / "meta" / "stats.json").read_text())
        if (root / "meta" / "tasks.parquet").exists():
            pq.read_metadata(root / "meta" / "tasks.parquet")
        data_rows = sum(pq.read_metadata(p).num_rows for p in (root / "data").glob("*/*.parquet"))
        episodes = [pq.read_table(p) for p in sorted((root / "meta" / "episodes").glob("*/*.parquet"))]
        if sum(t.num_rows for t in episodes) != info["total_episodes"] or data_rows != info["total_frames"]:
            return False
        video_path = info.get("video_path")
        for table in episodes:
            keys = {c.split("/")[1] for c in table.column_names if c.startswith("videos/")}
            for key in keys:
                chunks = table.column(f"videos/{key}/chunk_index").to_pylist()
                files = table.column(f"videos/{key}/file_index").to_pylist()
                for chunk, file in zip(chunks, files, strict=True):
                    if not (
                        root / video_path.format(video_key=key, chunk_index=chunk, file_index=file)
                    ).exists():
                        return False
    except Exception:  # any unreadable or missing piece: not consistent
        return False
    return True


def write_checkpoint(root: Path, total_episodes: int) -> None:
    """Record the current (finalized, consistent) state of the dataset at ``root``. Atomic."""
    root = Path(root)
    meta = {
        rel: base64.b64encode((root / rel).read_bytes()).decode()
        for rel in REWRITTEN_META
        if (root / rel).exists()
    }
    state = {"total_episodes": total_episodes, "files": _dataset_files(root), "meta": meta}
    write_atomic(_journal_path(root), json.dumps(state))  # the commit point: the old or the new checkpoint


def has_checkpoint(root: Path) -> bool:
    return _journal_path(root).exists()


def restore_checkpoint(root: Path) -> int | None:
    """Bring an interrupted recording back to a consistent state; returns its episode count.

    A dataset that is consistent by itself (see :func:`is_consistent`) is kept as it is, episodes after
    the checkpoint included; otherwise it is rolled back to the checkpoint. Returns ``None`` when there is
    no journal (the last recording ended cleanly).
    """
    root = Path(root)
    path = _journal_path(root)
    if not path.exists():
        return None
    state = json.loads(path.read_text())
    if is_consistent(root):
        path.unlink()
        kept, _ = committed_counts(root)
        logging.warning(
            "The interrupted recording at %s is consistent: kept all its %d episodes (%d at its last "
            "checkpoint).",
            root,
            kept,
            state["total_episodes"],
        )
        return kept
    keep = set(state["files"])
    for rel in _dataset_files(root):
        if rel not in keep:
            (root / rel).unlink()
    for rel, content in state["meta"].items():
        (root / rel).write_bytes(base64.b64decode(content))
    for directory in sorted((p for p in root.rglob("*") if p.is_dir()), key=lambda p: -len(p.parts)):
        if directory.relative_to(root).parts[0] != JOURNAL_DIR and not any(directory.iterdir()):
            directory.rmdir()
    logging.warning(
        "Recovered an interrupted recording at %s: rolled back to its last checkpoint (%d episodes).",
        root,
        state["total_episodes"],
    )
    return state["total_episodes"]


def clear_checkpoint(root: Path) -> None:
    shutil.rmtree(Path(root) / JOURNAL_DIR, ignore_errors=True)
