"""Recording checkpoints: a killed recorder leaves a dataset that can be rolled back to its last checkpoint.

``LeRobotDataset`` keeps parquet writers open until ``finalize()`` (no footer before that) and
rewrites ``meta/info.json``/``stats.json``/``tasks.parquet`` after every episode, so a process killed
mid-recording leaves files that disagree with each other. The recorder therefore finalizes at
checkpoints and writes a journal (``<root>/.recording/checkpoint.json``) listing every file of that
consistent state plus the bytes of the three rewritten meta files. After finalize, LeRobot's
``resume`` always opens *new* data/episode/video files, so the listed files are never modified
later: rolling back = deleting unlisted files and restoring the three meta files.

The journal is removed after a clean finish (the dataset is then consistent by itself).
"""

from __future__ import annotations

import base64
import json
import logging
import os
import shutil
from pathlib import Path

JOURNAL_DIR = ".recording"
JOURNAL_FILE = "checkpoint.json"
REWRITTEN_META = ("meta/info.json", "meta/stats.json", "meta/tasks.parquet")


def _journal_path(root: Path) -> Path:
    return Path(root) / JOURNAL_DIR / JOURNAL_FILE


def _dataset_files(root: Path) -> list[str]:
    return sorted(
        p.relative_to(root).as_posix()
        for p in root.rglob("*")
        if p.is_file() and p.relative_to(root).parts[0] != JOURNAL_DIR
    )


def write_checkpoint(root: Path, total_episodes: int) -> None:
    """Record the current (finalized, consistent) state of the dataset at ``root``. Atomic."""
    root = Path(root)
    meta = {
        rel: base64.b64encode((root / rel).read_bytes()).decode()
        for rel in REWRITTEN_META
        if (root / rel).exists()
    }
    state = {"total_episodes": total_episodes, "files": _dataset_files(root), "meta": meta}
    path = _journal_path(root)
    path.parent.mkdir(exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(state))
    os.replace(tmp, path)  # the commit point: either the old or the new checkpoint is on disk


def has_checkpoint(root: Path) -> bool:
    return _journal_path(root).exists()


def restore_checkpoint(root: Path) -> int | None:
    """Roll an interrupted recording back to its last checkpoint; returns its episode count.

    Returns ``None`` when there is no journal (the last recording ended cleanly).
    """
    root = Path(root)
    path = _journal_path(root)
    if not path.exists():
        return None
    state = json.loads(path.read_text())
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
