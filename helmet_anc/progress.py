"""Progress on stderr for steps that take seconds: a spinner on a terminal, one line per step in a pipe.

``with busy("refine --auto", quiet=args.quiet) as step: ...`` redraws ``refine --auto ... 12 s``
once a second on stderr while the block runs, and erases it at the end; ``step("step 2: adding
delay")`` names what is running now (``refine --auto: step 2: adding delay ... 12 s``). When stderr
is not a terminal (pipes, files, CI logs) nothing is redrawn: each ``step`` is one line,
``refine --auto: step 2: adding delay``, so a log shows where a long run is. Nothing at all with
``--quiet``; on a terminal nothing for blocks shorter than ``after_s``. For steps with a known
count of parts the grid search has its own bar (``sysid.estimation.grid.terminal_progress``).
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
    if quiet:
        yield lambda text: None
        return
    if not stream.isatty():
        def line(text: str) -> None:
            stream.write(f"{label}: {text}\n")
            stream.flush()

        yield line
        return
    done = threading.Event()
    started = time.monotonic()
    drawn = [0]  # characters of the last line drawn
    current = [label]
    lock = threading.Lock()

    def draw():
        with lock:
            text = f"{current[0]} ... {time.monotonic() - started:.0f} s"
            stream.write("\r" + text + " " * max(drawn[0] - len(text), 0))
            stream.flush()
            drawn[0] = len(text)

    def spin():
        # The first draw waits after_s: short steps stay silent.
        while not done.wait(after_s if not drawn[0] else every_s):
            draw()

    def step(text: str) -> None:
        current[0] = f"{label}: {text}"
        if drawn[0]:
            draw()

    thread = threading.Thread(target=spin, daemon=True)
    thread.start()
    try:
        yield step
    finally:
        done.set()
        thread.join()
        if drawn[0]:
            stream.write("\r" + " " * drawn[0] + "\r")
            stream.flush()
