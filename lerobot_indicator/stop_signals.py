"""SIGINT/SIGTERM as one exception, so every CLI stops a run the same way and exits as a shell expects.

:class:`Interrupted` is a ``KeyboardInterrupt``: code that already cleans up on Ctrl-C (env workers, the
recorded dataset, wandb) does the same on SIGTERM (``kill``, a scheduler's preemption). The exit code is
the shell's 128 + signal number (130 for SIGINT, 143 for SIGTERM).
"""

from __future__ import annotations

import signal


class Interrupted(KeyboardInterrupt):
    """A run stopped by signal ``signum`` (SIGINT for a plain ``KeyboardInterrupt``)."""

    def __init__(self, signum: int = signal.SIGINT):
        super().__init__(signal.Signals(signum).name)
        self.signum = int(signum)


def raise_interrupted(signum: int, frame: object) -> None:
    """Signal handler: raise :class:`Interrupted` in the main thread."""
    raise Interrupted(signum)


def exit_code(exc: KeyboardInterrupt) -> int:
    """128 + the signal that stopped the run (a bare ``KeyboardInterrupt`` is Ctrl-C: SIGINT)."""
    return 128 + getattr(exc, "signum", signal.SIGINT)


def stopping_signal(returncode: int) -> int | None:
    """The SIGINT/SIGTERM that stopped a child process with ``returncode`` (its :func:`exit_code`, or Popen's
    negative signal number when it died of it), else None."""
    for signum in (signal.SIGINT, signal.SIGTERM):
        if returncode in (128 + signum, -signum):
            return int(signum)
    return None
