"""Failures of reading and writing a run's files, and of building a config, as one line each.

* :class:`CorruptFileError`: a saved file (weights, optimizer state, resume counters) that cannot be read, e.g.
  a ``model.safetensors`` cut short by a crash or a full disk; the message names the file.
* :class:`DiskFullError`: saving ran out of disk space; the message says what is kept and how to go on.
* :class:`~lerobot_indicator.data.errors.DatasetError`: a dataset file, key, episode or frame that cannot be used.
* :func:`config_error_line`: a ``ValueError`` raised by one of this package's config dataclasses while draccus
  builds a config, which draccus turns into "Couldn't instantiate class ..." and a traceback, as one line.

The CLIs print these as ``error: <message>`` and exit with code 1 (``LEROBOT_INDICATOR_TRACEBACK=1`` shows the
traceback); :func:`install_excepthook` does the same in LeRobot's own CLIs, which import this plugin.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import sys
import zipfile
from collections.abc import Iterator
from pathlib import Path

from lerobot_indicator.data.errors import DatasetError, one_line, tracebacks_requested
from lerobot_indicator.policy.input_checks import PolicyInputError

PACKAGE_DIR = Path(__file__).resolve().parent
DISK_FULL = os.strerror(errno.ENOSPC)  # "No space left on device"


class CorruptFileError(RuntimeError):
    """A saved file that cannot be read as what it should be (truncated or corrupt)."""


class DiskFullError(Exception):
    """Saving a run's files ran out of disk space."""


class ConfigError(Exception):
    """A bad command-line option or config file, found after draccus built the config (``validate``)."""


def _chain(exc: BaseException) -> Iterator[BaseException]:
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        yield exc
        exc = exc.__cause__ or exc.__context__


def is_disk_full(exc: BaseException) -> bool:
    """``exc`` or an exception it was raised from is ENOSPC: an ``OSError`` with that errno, or a library error
    that only kept the OS message (safetensors' ``SafetensorError: ... No space left on device``)."""
    for e in _chain(exc):
        if isinstance(e, OSError) and e.errno == errno.ENOSPC:
            return True
        if DISK_FULL in str(e) or "StorageFull" in str(e):
            return True
    return False


# What a truncated or corrupt file raises when read: safetensors' SafetensorError (a plain Exception, matched by
# name below), a JSON or UTF-8 decoding error, a truncated .npz (BadZipFile, EOFError).
_CORRUPT = (json.JSONDecodeError, UnicodeDecodeError, zipfile.BadZipFile, EOFError)


@contextlib.contextmanager
def reading(path: str | Path, what: str, hint: str = "") -> Iterator[None]:
    """Errors reading ``path`` in the block as one :class:`CorruptFileError` line naming the file and ``what``
    it holds; ``hint`` (what to do instead) is appended."""
    try:
        yield
    except Exception as err:
        if not (isinstance(err, _CORRUPT) or type(err).__name__ == "SafetensorError"):
            raise
        size = Path(path).stat().st_size if Path(path).is_file() else None
        sized = f", {size} bytes" if size is not None else ""
        message = f"{path}: cannot read the {what} ({one_line(err)}{sized}): the file is truncated or corrupt"
        raise CorruptFileError(message + (f"; {hint}" if hint else "")) from err


def config_error_line(exc: BaseException) -> str | None:
    """The message of a ``ValueError``/``TypeError`` that one of this package's config dataclasses raised while
    draccus built a config (draccus replaces it by ``ParsingError("Couldn't instantiate class ...")``), else
    None."""
    from draccus.utils import ParsingError

    if not isinstance(exc, ParsingError):
        return None
    for cause in _chain(exc):
        if isinstance(cause, ParsingError) or not isinstance(cause, (ValueError, TypeError)):
            continue
        tb = cause.__traceback__
        while tb is not None and tb.tb_next is not None:
            tb = tb.tb_next
        if tb is not None and Path(tb.tb_frame.f_code.co_filename).resolve().is_relative_to(PACKAGE_DIR):
            return one_line(cause)
    return None


# PolicyInputError: a pretrained policy made for other inputs than its dataset's (lerobot-train).
ONE_LINE_ERRORS: tuple[type[BaseException], ...] = (
    CorruptFileError,
    DiskFullError,
    ConfigError,
    PolicyInputError,
    DatasetError,
)


def report_line(exc: BaseException) -> str | None:
    """The one line a CLI prints for ``exc`` instead of its traceback, or None to show the traceback."""
    if tracebacks_requested():
        return None
    if isinstance(exc, ONE_LINE_ERRORS):
        return f"error: {one_line(exc)}"
    line = config_error_line(exc)
    return f"error: {line}" if line is not None else None


def install_excepthook() -> None:
    """In a process that ends on one of the errors above (e.g. ``lerobot-eval`` of a truncated checkpoint),
    print its one line instead of a traceback; every other exception keeps the previous hook."""
    previous = sys.excepthook
    if getattr(previous, "_lerobot_indicator", False):
        return

    def hook(exc_type, exc, tb) -> None:
        line = report_line(exc) if exc is not None else None
        if line is None:
            previous(exc_type, exc, tb)
        else:
            print(line, file=sys.stderr, flush=True)

    hook._lerobot_indicator = True  # type: ignore[attr-defined]
    sys.excepthook = hook
