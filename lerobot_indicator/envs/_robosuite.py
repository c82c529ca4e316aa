"""Lazy, checked import of robosuite (installed with --no-deps, so it may be missing)."""

from types import ModuleType

ROBOSUITE_FIX = ".venv/bin/pip install --no-deps robosuite==1.5.2  (or: make install)"


def require_robosuite() -> ModuleType:
    """Import robosuite or fail with the exact command that fixes it.

    Kept out of module import time so that ``import lerobot_indicator`` (done by every LeRobot CLI through
    plugin discovery) stays fast and works without robosuite.
    """
    try:
        import robosuite
    except ImportError as err:
        raise ImportError(
            f"The Sawyer sim tasks need robosuite, which is not importable ({err}). Install it with:\n"
            f"    {ROBOSUITE_FIX}"
        ) from err
    return robosuite
