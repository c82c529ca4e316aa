"""A directory replaced as a whole: the new content is written beside it and swapped in with two renames, so an
interruption at any moment leaves one complete copy, ``<dir>`` or ``<dir>.old`` (``newest``)."""

from __future__ import annotations

import shutil
from pathlib import Path


def staging(final: Path) -> Path:
    """An empty ``<final>.tmp`` to write the new content into (a leftover from an interrupted write is dropped)."""
    tmp = final.with_name(final.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    return tmp


def swap_in(tmp: Path, final: Path) -> None:
    """Replace ``final`` with the complete ``tmp``; the previous ``final`` survives as ``final.old`` until the
    new one is in place."""
    old = final.with_name(final.name + ".old")
    shutil.rmtree(old, ignore_errors=True)  # left by an interruption after the second rename
    if final.exists():
        final.rename(old)
    tmp.rename(final)
    shutil.rmtree(old, ignore_errors=True)


def newest(final: Path) -> Path | None:
    """The complete copy: ``final``, else ``final.old`` (an interruption between the two renames), else None."""
    old = final.with_name(final.name + ".old")
    return final if final.exists() else old if old.exists() else None
