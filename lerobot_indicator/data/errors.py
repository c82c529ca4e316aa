"""The one exception for a dataset that cannot be used as it is, and how the CLIs report it.

A :class:`DatasetError` message is one line naming what is wrong and where: the file, the key, the episode,
the frame index, the expected and actual shape. The CLIs print it as ``error: <message>`` and exit with
code 1, without a traceback unless ``LEROBOT_INDICATOR_TRACEBACK=1`` is set.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator

# Set to 1 to see the traceback of an error the CLIs otherwise report in one line.
TRACEBACK_ENV = "LEROBOT_INDICATOR_TRACEBACK"


class DatasetError(Exception):
    """Bad or missing dataset content: a file that does not match its recorded hash or cannot be read, a
    missing ``meta/info.json``, a feature whose stored shape differs from what ``info.json`` or its goal
    key says."""


def tracebacks_requested() -> bool:
    return os.environ.get(TRACEBACK_ENV, "").strip().lower() in ("1", "true", "yes")


def one_line(err: BaseException) -> str:
    """``err``'s message on one line (its type name if it has none)."""
    return " ".join(str(err).split()) or type(err).__name__


@contextlib.contextmanager
def one_line_errors(*types: type[BaseException]) -> Iterator[None]:
    """Report ``types`` (default :class:`DatasetError`) raised in the block as ``error: <message>`` on
    stderr and exit with code 1; with ``LEROBOT_INDICATOR_TRACEBACK=1`` they propagate unchanged."""
    caught = types or (DatasetError,)
    try:
        yield
    except caught as err:
        if tracebacks_requested():
            raise
        print(f"error: {one_line(err)}", file=sys.stderr, flush=True)
        raise SystemExit(1) from None
