"""Standard output closed by its reader (``helmet-anc ... | head``): stop quietly.

When the reader of a pipe exits early, the next write to standard output raises
``BrokenPipeError`` (Python ignores SIGPIPE). A command line then stops with exit
status 141 (128 + SIGPIPE, what a shell reports for a process ended by a closed pipe),
no traceback and nothing on stderr: the reader asked for no more. Files a command
writes are complete before anything is printed about them (sysid.core.files), so stopping
here loses nothing.
"""

from __future__ import annotations

import os
import sys
from typing import Callable

__all__ = ["EXIT_BROKEN_PIPE", "quiet_on_closed_stdout"]

EXIT_BROKEN_PIPE = 141


def quiet_on_closed_stdout(run: Callable[[], int]) -> int:
    """``run()``'s exit status, or EXIT_BROKEN_PIPE when its reader closed standard output."""
    try:
        status = run()
        # Output still buffered meets the closed pipe here, not in the interpreter's final
        # flush (which would print "Exception ignored ... BrokenPipeError" and exit 120).
        sys.stdout.flush()
        return status
    except BrokenPipeError:
        _discard_stdout()
        return EXIT_BROKEN_PIPE


def _discard_stdout() -> None:
    """Point standard output at the null device so that no later flush fails again."""
    try:
        descriptor = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # replaced by an in-memory stream (tests)
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, descriptor)
    finally:
        os.close(null)
