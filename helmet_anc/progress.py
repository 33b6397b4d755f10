"""Progress on stderr for steps that take seconds: an elapsed-time line, only on a terminal.

``with busy("refine --auto", quiet=args.quiet): ...`` redraws ``refine --auto ... 12 s`` once a
second on stderr while the block runs, and erases it at the end. Nothing is drawn when
stderr is not a terminal (pipes, files, CI logs) or with ``--quiet``, and nothing for
blocks shorter than ``after_s``. For steps with a known count of parts the grid search
has its own bar (``sysid.estimation.grid.terminal_progress``).
"""

from __future__ import annotations

import sys
import threading
import time
from contextlib import contextmanager

__all__ = ["busy"]


@contextmanager
def busy(label: str, quiet: bool = False, stream=None, after_s: float = 2.0, every_s: float = 1.0):
    stream = stream or sys.stderr
    if quiet or not stream.isatty():
        yield
        return
    done = threading.Event()
    started = time.monotonic()
    drawn = [False]

    def draw():
        # The first draw waits after_s: short steps stay silent.
        while not done.wait(after_s if not drawn[0] else every_s):
            stream.write(f"\r{label} ... {time.monotonic() - started:.0f} s")
            stream.flush()
            drawn[0] = True

    thread = threading.Thread(target=draw, daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()
        if drawn[0]:
            stream.write("\r" + " " * (len(label) + 16) + "\r")
            stream.flush()
