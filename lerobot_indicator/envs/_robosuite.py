"""Lazy, checked import of robosuite (installed with --no-deps, so it may be missing)."""

import logging
from types import ModuleType

ROBOSUITE_FIX = ".venv/bin/pip install --no-deps robosuite==1.5.2  (or: make install)"

# What robosuite 1.5.2 logs on every import (so once per process and per env worker, twice each: its own handler
# and the root logger's): its optional private macro file and the robots and IK solver of other tasks. None of it
# concerns the Sawyer tasks; every other robosuite message is kept.
ROBOSUITE_IMPORT_NOTICES = (
    "No private macro file found!",
    "It is recommended to use a private macro file",
    "To setup, run: python ",
    "Could not import robosuite_models.",
    "Could not load the mink-based whole-body IK.",
)


class _DropImportNotices(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).startswith(ROBOSUITE_IMPORT_NOTICES)


def require_robosuite() -> ModuleType:
    """Import robosuite or fail with the exact command that fixes it.

    Kept out of module import time so that ``import lerobot_indicator`` (done by every LeRobot CLI through
    plugin discovery) stays fast and works without robosuite.
    """
    logger = logging.getLogger("robosuite_logs")  # the logger robosuite configures when imported
    if not any(isinstance(f, _DropImportNotices) for f in logger.filters):
        logger.addFilter(_DropImportNotices())
    try:
        import robosuite
    except ImportError as err:
        raise ImportError(
            f"The Sawyer sim tasks need robosuite, which is not importable ({err}). Install it with:\n"
            f"    {ROBOSUITE_FIX}"
        ) from err
    return robosuite
